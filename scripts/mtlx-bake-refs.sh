#!/usr/bin/env bash
# Regenerates tessera's own MaterialX references: writes one document per node category covering
# every nodedef of the standard library (scripts/mtlx-gen-refs.py), then bakes every output with
# MaterialX 1.39.5's GLSL TextureBaker under Xvfb with Mesa's software OpenGL
# (scripts/mtlx_bake_refs.py) into crates/graph/tests/mtlx-refs/{docs,bakes,manifest.json}.
# Compare them with `cargo test --release -p graph --test verify suite::`.
#
# usage: scripts/mtlx-bake-refs.sh [--res N] [--only NAME]
# (needs a C compiler for the GL shim; --only NAME re-bakes the documents whose name contains NAME)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
python=$(scripts/mtlx-venv.sh | tail -1)
"$python" scripts/mtlx-gen-refs.py
# A whole regeneration starts from nothing; `--only` replaces its documents' bakes and manifest
# rows and keeps the rest.
case " $* " in
  *" --only"*) ;;
  *) rm -rf crates/graph/tests/mtlx-refs/bakes ;;
esac
# The shim that lets shaders passing explicit gradients be baked a second time without
# MaterialX's 16x anisotropic filtering (scripts/gl-anisotropy-shim.c says why).
shim=target/gl-anisotropy-shim.so
mkdir -p target
cc -shared -fPIC -O2 -o "$shim" scripts/gl-anisotropy-shim.c -ldl
# llvmpipe, whatever GPU the machine has: the references must not depend on a driver.
LIBGL_ALWAYS_SOFTWARE=1 GALLIUM_DRIVER=llvmpipe \
  xvfb-run -a -s "-screen 0 1024x768x24" env LD_PRELOAD="$root/$shim" "$python" scripts/mtlx_bake_refs.py "$@"
