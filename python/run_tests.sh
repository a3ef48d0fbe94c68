#!/usr/bin/env bash
# The Python tests: builds the `slamd` package into a venv under target/
# and runs pytest on python/tests (a daemon test starts target/debug/slamd).
set -euo pipefail
cd "$(dirname "$0")/.."
venv=target/python-venv
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
# The dev profile reuses what `cargo test` built; `pip install ./python`
# without it builds the release a user wants.
MATURIN_PEP517_ARGS="--profile dev" "$venv/bin/pip" install -q "./python[test]"
cargo build -q --bin slamd
"$venv/bin/python" -m pytest -q -p no:cacheprovider python/tests "$@"
