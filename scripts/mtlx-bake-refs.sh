#!/usr/bin/env bash
# Regenerates tessera's own MaterialX references: writes one document per node category covering
# every nodedef of the standard library (scripts/mtlx-gen-refs.py), then bakes every output with
# MaterialX 1.39.5's GLSL TextureBaker under Xvfb with Mesa's software OpenGL
# (scripts/mtlx_bake_refs.py) into crates/graph/tests/mtlx-refs/{docs,bakes,manifest.json}.
# Compare them with `cargo test --release -p graph --test verify suite::`.
#
# usage: scripts/mtlx-bake-refs.sh [--res N] [--only NAME]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
python=$(scripts/mtlx-venv.sh | tail -1)
"$python" scripts/mtlx-gen-refs.py
rm -rf crates/graph/tests/mtlx-refs/bakes
# llvmpipe, whatever GPU the machine has: the references must not depend on a driver.
LIBGL_ALWAYS_SOFTWARE=1 GALLIUM_DRIVER=llvmpipe \
  xvfb-run -a -s "-screen 0 1024x768x24" "$python" scripts/mtlx_bake_refs.py "$@"
