#!/usr/bin/env bash
# Side by side against Mitsuba 3 (the vectorised CPU variant llvm_ad_rgb): installs Mitsuba 3.9.1
# from PyPI into target/mitsuba-venv (and LLVM 19, which drjit's JIT needs, from Debian's packages
# when it is missing), builds tessera, then times interleaved pairs on each reference scene of
# ../shared/refs/scenes and prints the throughput ratio per scene (scripts/bench_mitsuba.py).
# A benchmark, never a test: it reports, it does not fail on a slow machine.
#
# usage: scripts/bench-mitsuba.sh [--spp N] [--pairs K] [--threads T] [--out FILE.md]
#          [--tessera "LABEL=BINARY [ARGS...]"]... [SCENE...]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
llvm=/usr/lib/x86_64-linux-gnu/libLLVM-19.so
if [ ! -e "$llvm" ]; then
  sudo=""
  [ "$(id -u)" -ne 0 ] && sudo=sudo
  $sudo apt-get install -y -q libllvm19 >/dev/null
fi
venv=target/mitsuba-venv
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check "mitsuba==3.9.1" "numpy>=1.21"
cargo build --release --quiet -p tessera
DRJIT_LIBLLVM_PATH="$llvm" "$venv/bin/python" scripts/bench_mitsuba.py "$@"
