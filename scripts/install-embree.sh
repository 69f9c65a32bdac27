#!/usr/bin/env bash
# Installs Intel Embree 3, which tessera loads at run time to trace rays (`--accel auto`, the
# default, uses it where it is installed; the built-in BVH otherwise): Debian's libembree3-3
# package, with apt-get (through sudo when not root). Nothing happens when the library is
# already there. The test suite compares Embree with the built-in BVH when it can load it.
#
# usage: scripts/install-embree.sh
set -euo pipefail
if ldconfig -p 2>/dev/null | grep -q 'libembree3\.so\.3 '; then
  exit 0
fi
sudo=""
[ "$(id -u)" -ne 0 ] && sudo=sudo
if ! $sudo apt-get install -y -q libembree3-3 >/dev/null 2>&1; then
  # A fresh machine may have no package lists yet.
  $sudo apt-get update -q >/dev/null
  $sudo apt-get install -y -q libembree3-3 >/dev/null
fi
ldconfig -p | grep -q 'libembree3\.so\.3 ' || { echo "install-embree.sh: libembree3.so.3 is still not found" >&2; exit 1; }
