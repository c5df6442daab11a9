# Shared by scripts/run and scripts/test: checks the toolchain and installs what is missing.
# Debian packages are installed with apt-get when running as root; otherwise the exact
# command is printed and the script stops. Python tools go into a venv under build/.

set -euo pipefail

SKINBOX_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
SKINBOX_BUILD="$SKINBOX_ROOT/build"

die() {
    echo "skinbox setup: $*" >&2
    exit 1
}

# require_rust: cargo with rustfmt and clippy.
require_rust() {
    command -v cargo >/dev/null || die "cargo not found: install Rust (https://rustup.rs) and run again"
    if [ "${1:-}" = "--lint" ]; then
        cargo fmt --version >/dev/null 2>&1 || die "rustfmt missing: run 'rustup component add rustfmt'"
        cargo clippy --version >/dev/null 2>&1 || die "clippy missing: run 'rustup component add clippy'"
    fi
}

# require_debian_packages COMMAND:PACKAGE...: installs PACKAGE when COMMAND is not on PATH.
require_debian_packages() {
    local missing=()
    for pair in "$@"; do
        command -v "${pair%%:*}" >/dev/null || missing+=("${pair#*:}")
    done
    [ ${#missing[@]} -eq 0 ] && return 0
    if [ "$(id -u)" -ne 0 ]; then
        die "missing ${missing[*]}: run 'sudo apt-get update && sudo apt-get install -y ${missing[*]}' and run again"
    fi
    echo "skinbox setup: installing ${missing[*]} with apt-get" >&2
    if ! DEBIAN_FRONTEND=noninteractive apt-get install -y -q "${missing[@]}" >&2; then
        apt-get update -q >&2
        DEBIAN_FRONTEND=noninteractive apt-get install -y -q "${missing[@]}" >&2
    fi
}
