#!/usr/bin/env bash
# Builds and installs the Python package (`pip install .`, maturin) into a venv of its own,
# target/py-venv, and runs its tests (tests/python) against the command-line binary built from
# the same tree, Ray's tests on a local two-CPU cluster. Needs python3 (3.9 or later) with venv
# and pip, and PyPI for maturin, numpy, pytest, ray and openjd-cli (the farm templates are run by
# `openjd run` in tests/python/test_farm.py).
#
# usage: scripts/test-python.sh [PYTEST_ARGS...]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
venv=target/py-venv
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check "numpy>=1.21" "pytest>=7" "ray>=2.40,<3" "openjd-cli>=0.8"
cargo build --release --quiet -p tessera
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps .
TESSERA_BIN="$root/target/release/tessera" "$venv/bin/python" -m pytest -q tests/python "$@"
