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

# require_python_venv: python3 with its venv module (for the synthesis tools, which
# `skinbox synth` installs from PyPI into build/synth-venv).
require_python_venv() {
    if command -v python3 >/dev/null && python3 -c 'import venv, ensurepip' 2>/dev/null; then
        return 0
    fi
    if [ "$(id -u)" -ne 0 ]; then
        die "python3 with venv missing: run 'sudo apt-get update && sudo apt-get install -y python3 python3-venv' and run again"
    fi
    echo "skinbox setup: installing python3 python3-venv with apt-get" >&2
    if ! DEBIAN_FRONTEND=noninteractive apt-get install -y -q python3 python3-venv >&2; then
        apt-get update -q >&2
        DEBIAN_FRONTEND=noninteractive apt-get install -y -q python3 python3-venv >&2
    fi
}
