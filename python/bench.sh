#!/usr/bin/env bash
# Speed of the Python package beside the Rust figures, in one run: builds the package
# (release) into build/py-venv and the `skinbox` command (release), then runs bench.py.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
venv="$root/build/py-venv"
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/python" -m pip install -q --disable-pip-version-check "maturin>=1.9,<2" numpy
target="${CARGO_TARGET_DIR:-$root/target}"
(cd "$root/python" && VIRTUAL_ENV="$venv" PATH="$venv/bin:$PATH" CARGO_TARGET_DIR="$target" maturin develop --release -q)
(cd "$root" && CARGO_TARGET_DIR="$target" cargo build --release --bin skinbox -q)
"$venv/bin/python" "$root/python/bench.py" --skinbox "$target/release/skinbox" "$@"
