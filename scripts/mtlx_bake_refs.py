#!/usr/bin/env python3
"""Bakes every output of tessera's own MaterialX reference documents with MaterialX's GLSL
TextureBaker and writes them as float EXRs with a manifest (the format of
../shared/mtlx-suite/manifest.json, so that one conformance runner reads both).

Run it through scripts/mtlx-bake-refs.sh, which supplies the venv and a virtual X display.

For each output listed in crates/graph/tests/mtlx-refs/generated.json (scripts/mtlx-gen-refs.py)
the baker's GLSL generator makes the shader of that output (target colour space lin_rec709, file
textures flipped vertically as the baker does), TextureBaker renders it over uv [0, 1]² into its
float32 RGBA framebuffer, and the captured texels are written unquantised: row 0 of the EXR is
v = 1 (the captured image is flipped, as TextureBaker flips the images it writes). Outputs whose
shader reads the normal, tangent or bitangent vertex streams (which TextureBaker does not supply)
are marked `depends_on_geometry` and baked a second time with those streams replaced by the
constants N = (0, 0, 1), T = (1, 0, 0), B = (0, 1, 0): the `flat_plane_variant`.
"""
import argparse
import json
import os
import re
import sys

import numpy as np
import OpenEXR

import MaterialX as mx
import MaterialX.PyMaterialXGenGlsl as mx_glsl
import MaterialX.PyMaterialXGenShader as mx_gen
import MaterialX.PyMaterialXRender as mx_render
import MaterialX.PyMaterialXRenderGlsl as mx_render_glsl

ROOT = os.path.normpath(os.path.join(os.path.dirname(__file__), ".."))
REFS = os.path.join(ROOT, "crates", "graph", "tests", "mtlx-refs")
IMAGES = os.path.normpath(os.path.join(ROOT, "..", "shared", "mtlx-suite", "images"))

CHANNELS = {
    "float": ["Y"],
    "integer": ["Y"],
    "boolean": ["Y"],
    "vector2": ["R", "G"],
    "vector3": ["R", "G", "B"],
    "color3": ["R", "G", "B"],
    "vector4": ["R", "G", "B", "A"],
    "color4": ["R", "G", "B", "A"],
}
GEOMETRY_STREAMS = ("normal", "tangent", "bitangent", "color", "geomprop")
FLAT = {
    "i_normal": "vec3(0.0, 0.0, 1.0)",
    "i_tangent": "vec3(1.0, 0.0, 0.0)",
    "i_bitangent": "vec3(0.0, 1.0, 0.0)",
}


def write_exr(path, names, data):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {n: np.ascontiguousarray(data[:, :, k]) for k, n in enumerate(names)}
    with OpenEXR.File(header, channels) as f:
        f.write(path)


def capture(baker, w, h, n):
    """The framebuffer as an H × W × n array, row 0 = v = 1."""
    baker.renderTextureSpace(mx.Vector2(0, 0), mx.Vector2(1, 1))
    img = baker.captureImage(None)
    out = np.zeros((h, w, n), dtype=np.float32)
    for y in range(h):
        for x in range(w):
            c = img.getTexelColor(x, y)
            for k in range(n):
                out[h - 1 - y, x, k] = c[k]
    return out


def stats(a):
    finite = np.isfinite(a)
    mins, maxs = [], []
    for k in range(a.shape[2]):
        ch = a[:, :, k][finite[:, :, k]]
        mins.append(float(ch.min()) if ch.size else None)
        maxs.append(float(ch.max()) if ch.size else None)
    return mins, maxs, int((~finite).sum())


def variant(data, rel, element, suffix, names, how):
    """Writes a variant bake of `element` beside its bake and returns its manifest record."""
    path = "%s/%s__%s.exr" % (rel, element.replace("/", "__"), suffix)
    write_exr(os.path.join(REFS, path), names, data)
    mins, maxs, nonfinite = stats(data)
    return {"bake": path, "min": mins, "max": maxs, "nonfinite_texels": nonfinite, "how": how}


def require_anisotropy_shim():
    """Exits unless scripts/gl-anisotropy-shim.c is preloaded (scripts/mtlx-bake-refs.sh does it):
    without it an `isotropic_variant` would silently be the default bake again."""
    import ctypes
    try:
        ctypes.CDLL(None).tessera_gl_anisotropy_shim
    except AttributeError:
        sys.exit("the GL anisotropy shim is not loaded: run this through scripts/mtlx-bake-refs.sh")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--res", type=int, default=24)
    ap.add_argument("--only", default=None, help="bake only documents whose name contains this")
    args = ap.parse_args()
    w = h = args.res

    index = json.load(open(os.path.join(REFS, "generated.json")))
    lib = mx.createDocument()
    search = mx.getDefaultDataSearchPath()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), search, lib)

    gen = mx_glsl.GlslShaderGenerator.create()
    ctx = mx_gen.GenContext(gen)
    ctx.registerSourceCodeSearchPath(search)
    ctx.getOptions().targetColorSpaceOverride = "lin_rec709"
    ctx.getOptions().fileTextureVerticalFlip = True
    cms = mx_gen.DefaultColorManagementSystem.create(gen.getTarget())
    cms.loadLibrary(lib)
    gen.setColorManagementSystem(cms)
    units = mx_gen.UnitSystem.create(gen.getTarget())
    units.loadLibrary(lib)
    registry = mx.UnitConverterRegistry.create()
    registry.addUnitConverter(lib.getUnitTypeDef("distance"), mx.LinearUnitConverter.create(lib.getUnitTypeDef("distance")))
    units.setUnitConverterRegistry(registry)
    gen.setUnitSystem(units)
    ctx.getOptions().targetDistanceUnit = "meter"

    baker = mx_render_glsl.TextureBaker.create(w, h, mx_render.BaseType.FLOAT)
    image_search = mx.FileSearchPath(IMAGES)
    baker.getImageHandler().setSearchPath(image_search)

    docs = {}
    bakes, failed = [], []
    for entry in index["elements"]:
        if args.only and args.only not in entry["document"]:
            continue
        path = os.path.join(REFS, entry["document"])
        if path not in docs:
            d = mx.createDocument()
            d.importLibrary(lib)
            mx.readFromXmlFile(d, path)
            ok, msg = d.validate()
            if not ok:
                print("%s: %s" % (entry["document"], msg.strip()), file=sys.stderr)
            docs[path] = d
        doc = docs[path]
        element = entry["element"]
        out = doc.getDescendant(element)
        ty = out.getType()
        names = CHANNELS[ty]
        resolved = doc.getDescendant(element.split("/")[0] + "/node").getNodeDef()
        if resolved is None or resolved.getName() != entry["nodedef"]:
            sys.exit("%s: MaterialX resolves %s, not %s" % (element, resolved and resolved.getName(), entry["nodedef"]))
        try:
            shader = gen.generate(element.replace("/", "__"), out, ctx)
            baker.createProgram(shader)
            data = capture(baker, w, h, len(names))
        except Exception as e:  # noqa: BLE001 - recorded in the manifest
            failed.append({**entry, "type": ty, "reason": "MaterialX fails: %s" % str(e).strip().splitlines()[0]})
            print("FAIL %s: %s" % (element, e), file=sys.stderr)
            continue
        vertex = shader.getSourceCode("vertex")
        pixel = shader.getSourceCode("pixel")
        streams = sorted(set(re.findall(r"\bvd\.(\w+)\s*=", vertex)))
        graph = doc.getNodeGraph(element.split("/")[0])
        files = sorted({i.getValueString() for n in graph.getNodes() for i in n.getInputs() if i.getType() == "filename" and i.getValueString()})
        rel = os.path.splitext(entry["document"])[0].replace("docs/", "bakes/", 1)
        bake = "%s/%s.exr" % (rel, element.replace("/", "__"))
        write_exr(os.path.join(REFS, bake), names, data)
        mins, maxs, nonfinite = stats(data)
        flat = data[np.isfinite(data)]
        record = {
            "document": entry["document"],
            "element": element,
            "nodedef": entry["nodedef"],
            "kind": "nodegraph_output",
            "type": ty,
            "channels": names,
            "bake": bake,
            "resolution": [w, h],
            "orientation": "row 0 = top; texel (i,j) at u=(i+0.5)/W, v=1-(j+0.5)/H",
            "min": mins,
            "max": maxs,
            "nonfinite_texels": nonfinite,
            "uniform": bool(flat.size == data.size and np.all(data == data[0:1, 0:1, :])),
            "depends_on_geometry": any(g in s.lower() for s in streams for g in GEOMETRY_STREAMS),
            "shader_streams": streams,
        }
        if files:
            record["texture_files"] = files
        # Uniforms the baker leaves at their GLSL initializers (it binds no time or frame).
        private = dict(re.findall(r"^uniform (?:float|int) (u_time|u_frame) = ([-0-9.eE+]+);", pixel, flags=re.M))
        record["shader_private_uniforms"] = {k: float(v) for k, v in private.items()}
        if any(re.search(r"\b%s\b" % a, vertex) for a in FLAT) and record["depends_on_geometry"]:
            v2 = vertex
            for a, c in FLAT.items():
                v2 = re.sub(r"^\s*in vec3 %s;" % a, "const vec3 %s = %s;" % (a, c), v2, flags=re.M)
            baker.createProgram({"vertex": v2, "pixel": pixel})
            record["flat_plane_variant"] = variant(
                capture(baker, w, h, len(names)), rel, element, "flatplane", names,
                "same shader, vertex inputs i_normal/i_tangent/i_bitangent replaced by constants N=(0,0,1), "
                "T=(1,0,0), B=(0,1,0): the flat quad with its frame, which TextureBaker itself does not supply")
        # The quad's one uv stream is i_texcoord_0; a geompropvalue of `uv` reads the attribute
        # i_geomprop_uv, which TextureBaker leaves unbound (GL's default, 0). The variant binds
        # the quad's uv stream there, expanded as GL expands a two-component attribute.
        gp = re.search(r"^in (float|vec2|vec3|vec4) i_geomprop_uv;", vertex, flags=re.M)
        if gp and re.search(r"^in vec2 i_texcoord_0;", vertex, flags=re.M):
            expr = {"float": "i_texcoord_0.x", "vec2": "i_texcoord_0", "vec3": "vec3(i_texcoord_0, 0.0)",
                    "vec4": "vec4(i_texcoord_0, 0.0, 1.0)"}[gp.group(1)]
            v2 = re.sub(r"^in \w+ i_geomprop_uv;\n", "", vertex, flags=re.M)
            v2 = re.sub(r"\bvd\.i_geomprop_uv = i_geomprop_uv;", "vd.i_geomprop_uv = %s;" % expr, v2)
            baker.createProgram({"vertex": v2, "pixel": pixel})
            record["uv_geomprop_variant"] = variant(
                capture(baker, w, h, len(names)), rel, element, "uvgeomprop", names,
                "same shader, vertex input i_geomprop_uv replaced by the quad's uv stream i_texcoord_0, "
                "expanded to the attribute's type as GL does ((u, v, 0, 1)): the quad with a geometric property `uv`, "
                "which TextureBaker itself does not bind")
        # MaterialX binds images with 16x anisotropic filtering, and llvmpipe takes the
        # anisotropic footprint from the lookup coordinate's differences inside each 2 x 2 quad,
        # not from the gradients a shader passes to textureGrad: where those coordinates jump
        # inside a quad (hex tiling), the lookup averages along a line across the image. Such
        # shaders are baked again with anisotropy 1 (scripts/gl-anisotropy-shim.c).
        if "textureGrad(" in pixel:
            require_anisotropy_shim()
            os.environ["TESSERA_GL_MAX_ANISOTROPY"] = "1"
            try:
                baker.createProgram(shader)
                idata = capture(baker, w, h, len(names))
            finally:
                del os.environ["TESSERA_GL_MAX_ANISOTROPY"]
            record["isotropic_variant"] = variant(
                idata, rel, element, "isotropic", names,
                "same shader and images, bound with GL_TEXTURE_MAX_ANISOTROPY 1 instead of MaterialX's 16: "
                "the shader passes explicit gradients to textureGrad, which llvmpipe's anisotropic filter ignores "
                "in favour of the coordinate's differences inside each 2x2 pixel quad")
        bakes.append(record)
        print("%s %s" % (element, "uniform" if record["uniform"] else "varies"))

    manifest = {
        "generator": "scripts/mtlx-bake-refs.sh (MaterialX %s TextureBaker, GLSL, Mesa llvmpipe under Xvfb)" % mx.getVersionString(),
        "resolution": [w, h],
        "uv_range": [[0.0, 0.0], [1.0, 1.0]],
        "orientation": "pixel (i,j) of the EXR (i = column, j = row, row 0 = top of file) is the value at "
        "u = (i+0.5)/W, v = 1 - (j+0.5)/H (v = 1 at the top row, as TextureBaker writes its images)",
        "pixel_format": "float32 OpenEXR (ZIP), channels Y (float/integer/boolean), R,G (vector2), R,G,B "
        "(vector3/color3), R,G,B,A (vector4/color4); values straight from the baker's RGBA32F framebuffer",
        "geometry_assumed": "the baker's texture-space quad: object/world position = (2u-1, 2v-1, 0); normal, tangent, "
        "bitangent and colour vertex streams are not supplied (see flat_plane_variant)",
        "search_path": "../shared/mtlx-suite/images",
        "bakes": bakes,
        "failed": failed,
        "skipped": index["skipped"],
    }
    if args.only:
        # Replace the re-baked documents' rows of the whole manifest, keep every other row.
        old = json.load(open(os.path.join(REFS, "manifest.json")))
        done = {b["document"] for b in bakes} | {b["document"] for b in failed}
        order = {e["document"]: k for k, e in enumerate(index["elements"])}
        for key, new in (("bakes", bakes), ("failed", failed)):
            manifest[key] = [r for r in old[key] if r["document"] not in done] + new
            manifest[key].sort(key=lambda r: order.get(r["document"], len(order)))
        bakes, failed = manifest["bakes"], manifest["failed"]
    # One line per bake: small, and a regeneration diffs by bake.
    with open(os.path.join(REFS, "manifest.json"), "w") as f:
        head = {k: v for k, v in manifest.items() if k not in ("bakes", "failed", "skipped")}
        f.write(json.dumps(head, indent=1)[:-2] + ",\n")
        for key in ("bakes", "failed", "skipped"):
            rows = ",\n".join("  " + json.dumps(r) for r in manifest[key])
            f.write(' "%s": [\n%s\n ]%s\n' % (key, rows, "," if key != "skipped" else ""))
        f.write("}\n")
    print("%d bakes, %d MaterialX failures, %d skipped" % (len(bakes), len(failed), len(index["skipped"])))


if __name__ == "__main__":
    main()
