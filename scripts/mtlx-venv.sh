#!/usr/bin/env bash
# Installs MaterialX 1.39.5 from PyPI into target/mtlx-venv (with numpy and OpenEXR, which the
# reference scripts use to write float EXRs), and, for GLSL baking, Xvfb and Mesa's software
# OpenGL from Debian's packages when xvfb-run is missing. Prints the venv's python.
#
# usage: scripts/mtlx-venv.sh
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
if ! command -v xvfb-run >/dev/null; then
  sudo=""
  [ "$(id -u)" -ne 0 ] && sudo=sudo
  $sudo apt-get install -y -q xvfb xauth libgl1-mesa-dri libglx-mesa0 mesa-utils libegl1 >/dev/null
fi
venv=target/mtlx-venv
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check "materialx==1.39.5" "OpenEXR==3.3.5" "numpy>=1.21"
echo "$root/$venv/bin/python"
