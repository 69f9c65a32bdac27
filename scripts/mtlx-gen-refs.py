#!/usr/bin/env python3
"""Writes tessera's own MaterialX reference documents: one node graph per nodedef of the standard
library, one document per node category.

Reads the signature table crates/graph/tests/data/stdlib_nodedefs.json (scripts/mtlx-nodedefs.py)
and writes crates/graph/tests/mtlx-refs/docs/<category>.mtlx. Each graph holds one node of its
nodedef (every input given with its type, which selects the nodedef) and an output per output of the nodedef. Every input
that carries a number is driven by the texture coordinate: one of u and v per channel (the choice
alternating over channels and inputs), scaled and offset into a range of its own, so that two
inputs never see the same values and the result varies over the bake. The ranges follow what the
node does (RANGES below: positive for sqrt and ln, away from integers for floor, a few cells of
noise, a magnified patch of an image); integers are the floor of such a ramp and booleans a
threshold of one, where they are operands; settings (uniform inputs, strings, octaves, ...) keep
their defaults or the constants of CONSTANTS.

The first nodedef of each category is also written once for every other value of each of its
enumerated settings (`space`, address modes, `filtertype`, noise `type` and `style`, `ramp`'s
kind and interpolation, ...), as graphs named <nodedef>_<input>_<value>.

Not generated (listed in the bake manifest's `skipped`): nodedefs whose outputs are shaders,
materials, matrices, strings or filenames, which a texture bake cannot show.

usage: python3 scripts/mtlx-gen-refs.py
"""
import json
import os
import re
import shutil

ROOT = os.path.normpath(os.path.join(os.path.dirname(__file__), ".."))
TABLE = os.path.join(ROOT, "crates", "graph", "tests", "data", "stdlib_nodedefs.json")
OUT = os.path.join(ROOT, "crates", "graph", "tests", "mtlx-refs", "docs")

BAKEABLE = {"float", "integer", "boolean", "vector2", "vector3", "vector4", "color3", "color4"}
CHANNELS = {"float": 1, "vector2": 2, "vector3": 3, "vector4": 4, "color3": 3, "color4": 4}
COMBINE = {"vector2": "combine2", "vector3": "combine3", "color3": "combine3", "vector4": "combine4", "color4": "combine4"}

IMAGE = "resources/Images/cloth.png"
NORMAL_IMAGE = "resources/Images/mesh_wire_norm.png"
# A patch of about 30 image texels across the bake: magnified, so that a GPU's mip level is 0.
IMAGE_UV = (0.30, 0.35)

# (lo, hi) per category and input; "*" for every driven input of the category.
RANGES = {
    "sqrt": {"*": (0.02, 4.0)},
    "ln": {"*": (0.05, 5.0)},
    "exp": {"*": (-2.0, 2.0)},
    "asin": {"*": (-0.97, 0.97)},
    "acos": {"*": (-0.97, 0.97)},
    "atan2": {"iny": (-1.0, 0.9), "inx": (-0.8, 1.1)},
    "sin": {"*": (-4.0, 4.0)},
    "cos": {"*": (-4.0, 4.0)},
    "tan": {"*": (-1.2, 1.2)},
    "power": {"in1": (0.05, 3.0), "in2": (-1.5, 2.5)},
    "safepower": {"in1": (-2.0, 2.0), "in2": (0.3, 2.7)},
    "divide": {"in1": (-2.0, 2.0), "in2": (0.3, 2.0)},
    "modulo": {"in1": (-3.03, 3.07), "in2": (0.45, 1.35)},
    "fract": {"*": (-3.03, 2.97)},
    "floor": {"*": (-3.03, 2.97)},
    "ceil": {"*": (-3.03, 2.97)},
    "round": {"*": (-3.03, 2.97)},
    "sign": {"*": (-1.03, 0.97)},
    "absval": {"*": (-1.03, 0.97)},
    "invert": {"in": (-0.5, 1.5), "amount": (0.5, 1.5)},
    "clamp": {"in": (-0.5, 1.5), "low": (0.0, 0.3), "high": (0.7, 1.0)},
    "min": {"in1": (-1.0, 1.0), "in2": (-0.8, 0.9)},
    "max": {"in1": (-1.0, 1.0), "in2": (-0.8, 0.9)},
    "add": {"in1": (-1.0, 1.0), "in2": (-0.8, 1.3)},
    "subtract": {"in1": (-1.0, 1.0), "in2": (-0.8, 1.3)},
    "multiply": {"in1": (-1.0, 1.0), "in2": (-1.3, 0.8)},
    "normalize": {"*": (-1.0, 0.9)},
    "magnitude": {"*": (-1.0, 0.9)},
    "distance": {"in1": (-1.0, 1.0), "in2": (-0.7, 0.9)},
    "dotproduct": {"in1": (-1.0, 1.0), "in2": (-0.7, 0.9)},
    "crossproduct": {"in1": (-1.0, 1.0), "in2": (-0.7, 0.9)},
    "reflect": {"in": (-1.0, 1.0), "normal": (-0.7, 0.9)},
    "refract": {"in": (-1.0, 1.0), "normal": (-0.7, 0.9), "ior": (1.1, 1.7)},
    "smoothstep": {"in": (-0.2, 1.2), "low": (0.0, 0.3), "high": (0.7, 1.0)},
    "remap": {"in": (-0.2, 1.2), "inlow": (0.01, 0.23), "inhigh": (0.8, 1.0), "outlow": (-1.0, -0.5), "outhigh": (1.0, 2.0)},
    "range": {"in": (-0.2, 1.2), "inlow": (0.01, 0.23), "inhigh": (0.8, 1.0), "gamma": (0.5, 2.0), "outlow": (-1.0, -0.5), "outhigh": (1.0, 2.0)},
    "trianglewave": {"*": (-2.03, 2.97)},
    "contrast": {"in": (0.0, 1.0), "amount": (0.5, 2.0), "pivot": (0.3, 0.7)},
    "hsvadjust": {"in": (0.05, 0.95), "amount": (0.2, 1.2)},
    "saturate": {"in": (0.05, 0.95), "amount": (0.2, 1.8)},
    "rgbtohsv": {"*": (0.02, 0.98)},
    "hsvtorgb": {"*": (0.02, 0.98)},
    "rotate2d": {"in": (-1.0, 1.0), "amount": (-180.0, 180.0)},
    "rotate3d": {"in": (-1.0, 1.0), "amount": (-180.0, 180.0), "axis": (0.2, 1.0)},
    "place2d": {"texcoord": (-0.5, 1.5), "pivot": (0.2, 0.8), "scale": (0.5, 2.0), "rotate": (-90.0, 90.0), "offset": (-0.3, 0.3)},
    "switch": {"which": (0.2, 10.6)},
    "noise2d": {"texcoord": (-1.0, 4.0), "amplitude": (0.5, 1.5), "pivot": (-0.3, 0.3)},
    "noise3d": {"position": (-1.0, 4.0), "amplitude": (0.5, 1.5), "pivot": (-0.3, 0.3)},
    # MaterialX's vector fractals evaluate their other channels at p + (19, 193) and the like,
    # scaled by lacunarity^octave: with lacunarity up to 2.4 the last of the 3 octaves ran at
    # coordinates of about 1100, where an f32's last bit (1.2e-4) times the noise's slope exceeds
    # the conformance tolerance, so the bakes measured single-precision rounding, not the node.
    # Up to 1.6 they stay below 512 (a last bit of 3e-5); lacunarity still varies over the bake.
    "fractal2d": {"texcoord": (-1.0, 4.0), "amplitude": (0.5, 1.5), "lacunarity": (1.3, 1.6), "diminish": (0.3, 0.7)},
    "fractal3d": {"position": (-1.0, 4.0), "amplitude": (0.5, 1.5), "lacunarity": (1.3, 1.6), "diminish": (0.3, 0.7)},
    "cellnoise2d": {"texcoord": (-2.03, 5.07)},
    "cellnoise3d": {"position": (-2.03, 5.07)},
    "worleynoise2d": {"texcoord": (-1.0, 4.0), "jitter": (0.5, 1.0)},
    "worleynoise3d": {"position": (-1.0, 4.0), "jitter": (0.5, 1.0)},
    "unifiednoise2d": {"texcoord": (-0.5, 2.0), "freq": (1.0, 3.0), "offset": (-0.5, 0.5), "jitter": (0.5, 1.0), "outmin": (0.0, 0.2), "outmax": (0.8, 1.0), "lacunarity": (1.8, 2.4), "diminish": (0.3, 0.7)},
    "unifiednoise3d": {"position": (-0.5, 2.0), "freq": (1.0, 3.0), "offset": (-0.5, 0.5), "jitter": (0.5, 1.0), "outmin": (0.0, 0.2), "outmax": (0.8, 1.0), "lacunarity": (1.8, 2.4), "diminish": (0.3, 0.7)},
    # randomfloat scales a float `in` by 4096 before taking its cell: a range whose texel
    # centres stay 0.37 or more from a cell edge there (the GPU's interpolated uv is 1e-7 off).
    "randomfloat": {"in": (0.0137, 19.71), "min": (-0.5, 0.0), "max": (1.0, 1.5), "seed": (0.0, 5.0)},
    "randomcolor": {"in": (0.0137, 19.71), "huelow": (0.0, 0.2), "huehigh": (0.7, 1.0), "saturationlow": (0.0, 0.3), "saturationhigh": (0.6, 1.0), "brightnesslow": (0.0, 0.3), "brightnesshigh": (0.6, 1.0), "seed": (0.0, 5.0)},
    "checkerboard": {"texcoord": (0.0, 1.0), "uvtiling": (3.0, 9.0), "uvoffset": (-0.2, 0.2)},
    "circle": {"texcoord": (0.0, 1.0), "center": (0.3, 0.7), "radius": (0.15, 0.45)},
    "cloverleaf": {"texcoord": (0.0, 1.0), "center": (0.3, 0.7), "radius": (0.15, 0.45)},
    "hexagon": {"texcoord": (0.0, 1.0), "center": (0.3, 0.7), "radius": (0.15, 0.45)},
    # line: the segment point1–point2 is relative to center.
    "line": {"texcoord": (0.0, 1.0), "center": (0.45, 0.55), "radius": (0.02, 0.12), "point1": (-0.4, -0.1), "point2": (0.1, 0.4)},
    # ifequal: whole numbers (QUANTIZED), so that the operands are sometimes equal.
    "ifequal": {"value1": (0.2, 3.8), "value2": (0.3, 3.7)},
    "grid": {"texcoord": (0.0, 1.0), "uvtiling": (2.0, 6.0), "uvoffset": (-0.2, 0.2), "thickness": (0.02, 0.15)},
    "crosshatch": {"texcoord": (0.0, 1.0), "uvtiling": (2.0, 6.0), "uvoffset": (-0.2, 0.2), "thickness": (0.02, 0.15)},
    "tiledcircles": {"texcoord": (0.0, 1.0), "uvtiling": (2.0, 6.0), "uvoffset": (-0.2, 0.2), "size": (0.3, 0.9)},
    "tiledcloverleafs": {"texcoord": (0.0, 1.0), "uvtiling": (2.0, 6.0), "uvoffset": (-0.2, 0.2), "size": (0.3, 0.9)},
    "tiledhexagons": {"texcoord": (0.0, 1.0), "uvtiling": (2.0, 6.0), "uvoffset": (-0.2, 0.2), "size": (0.3, 0.9)},
    "ramplr": {"texcoord": (0.0, 1.0)},
    "ramptb": {"texcoord": (0.0, 1.0)},
    "ramp4": {"texcoord": (0.0, 1.0)},
    "splitlr": {"texcoord": (0.0, 1.0), "center": (0.3, 0.7)},
    "splittb": {"texcoord": (0.0, 1.0), "center": (0.3, 0.7)},
    "image": {"texcoord": IMAGE_UV},
    "tiledimage": {"texcoord": IMAGE_UV, "uvtiling": (1.0, 1.2), "uvoffset": (0.0, 0.05)},
    "hextiledimage": {"texcoord": (0.2, 0.45), "rotation": (0.0, 1.0), "scale": (0.5, 1.0), "offset": (0.0, 1.0)},
    "hextilednormalmap": {"texcoord": (0.0, 2.0), "rotation": (0.0, 1.0), "scale": (0.5, 1.0), "offset": (0.0, 1.0)},
    "triplanarprojection": {"position": IMAGE_UV, "normal": (-1.0, 1.0)},
    "normalmap": {"in": (0.1, 0.9), "scale": (0.5, 1.5), "normal": (-0.5, 1.0), "tangent": (-0.5, 1.0), "bitangent": (-0.5, 1.0)},
    "heighttonormal": {"in": (0.0, 1.0), "scale": (0.5, 2.0)},
    "transformpoint": {"*": (-1.0, 1.0)},
    "transformvector": {"*": (-1.0, 1.0)},
    "transformnormal": {"*": (-1.0, 1.0)},
    "transformmatrix": {"*": (-1.0, 1.0)},
    "bump": {"height": (0.0, 1.0), "scale": (0.5, 1.5)},
    "blur": {"size": (0.0, 1.0)},
    "time": {"fps": (12.0, 60.0)},
    "colorcorrect": {"in": (0.05, 0.95), "hue": (-0.2, 0.2), "saturation": (0.5, 1.5), "gamma": (0.5, 2.0), "lift": (0.0, 0.2), "gain": (0.5, 1.5), "contrast": (0.5, 1.5), "contrastpivot": (0.3, 0.7), "exposure": (-1.0, 1.0)},
    "flake2d": {"texcoord": (0.0, 1.0), "size": (0.05, 0.2), "roughness": (0.2, 0.8), "coverage": (0.3, 0.9)},
    "flake3d": {"position": (-1.0, 1.0), "size": (0.05, 0.2), "roughness": (0.2, 0.8), "coverage": (0.3, 0.9)},
    "ramp": {"texcoord": (0.0, 1.0)},
    "ramp_gradient": {"x": (0.0, 1.0)},
}

# Constant values of inputs that are not driven (settings), per category and input.
MAT33 = "0.8, 0.6, 0.0, -0.6, 0.8, 0.0, 0.1, 0.2, 1.0"
MAT44 = "0.8, 0.6, 0.0, 0.0, -0.6, 0.8, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.1, 0.2, 0.3, 1.0"
CONSTANTS = {
    "extract": {"index": "1"},
    "geompropvalue": {"geomprop": "uv"},
    "hextilednormalmap": {"file": NORMAL_IMAGE},
    # Real-world sizes at their defaults keep the image magnified (see IMAGE_UV).
    "tiledimage": {"realworldimagesize": "1.0, 1.0", "realworldtilesize": "1.0, 1.0"},
    # Per-tile ranges and luma weights at their defaults (None: the nodedef's default).
    "hextiledimage": {"tiling": None, "rotationrange": None, "scalerange": None, "offsetrange": None, "lumacoeffs": None},
    # jitter < 1 rotates the lattice by (jitter - 1) * 90000 degrees (3D: moves it as far along
    # z), where single-precision sin/cos and floor differ between any two implementations.
    "unifiednoise2d": {"jitter": "1.0"},
    "unifiednoise3d": {"jitter": "1.0"},
}

# Enumerated settings with no variants: frameendaction acts only on image sequences.
NO_VARIANTS = {"frameendaction"}
# Ranges for variants of a setting (a tuple per channel): an address mode's variants straddle
# the image's edge at 0 in their own axis (with `default` held, texcoord is the first driven
# input: channel 0 follows u, channel 1 v).
VARIANT_RANGES = {
    "uaddressmode": {"texcoord": ((-0.02, 0.02), (0.30, 0.34))},
    "vaddressmode": {"texcoord": ((0.30, 0.34), (-0.02, 0.02))},
}
# Inputs held at 0.25 in variants of a setting: MaterialX's GLSL renders the `constant` address
# mode with the sampler's border colour, set from `default`'s value, so a connected `default`
# reads as 0 beyond the edge (tessera returns the connected value, as the specification says).
VARIANT_HELD = {"uaddressmode": ("default",), "vaddressmode": ("default",)}

# Integer and boolean inputs that are operands (driven), not settings.
OPERANDS = {"in", "in1", "in2", "value1", "value2", "which", "fg", "bg", "value"}
# Float inputs driven by the floor of their ramp, per category.
QUANTIZED = {"ifequal": {"value1", "value2"}}


def typed_default(ty):
    return {
        "float": "0.5",
        "integer": "1",
        "boolean": "false",
        "vector2": "0.5, 0.5",
        "vector3": "0.5, 0.5, 0.5",
        "color3": "0.5, 0.5, 0.5",
        "vector4": "0.5, 0.5, 0.5, 0.5",
        "color4": "0.5, 0.5, 0.5, 0.5",
        "matrix33": MAT33,
        "matrix44": MAT44,
    }.get(ty, "")


def fmt(x):
    s = "%.6g" % x
    return s


class Graph:
    def __init__(self, name):
        self.name = name
        self.lines = [
            '  <nodegraph name="%s">' % name,
            '    <texcoord name="uv" type="vector2"/>',
            '    <separate2 name="uv_split" type="multioutput">',
            '      <input name="in" type="vector2" nodename="uv"/>',
            "    </separate2>",
        ]

    def node(self, category, name, ty, inputs, nodedef=None):
        nd = ' nodedef="%s"' % nodedef if nodedef else ""
        self.lines.append('    <%s name="%s" type="%s"%s>' % (category, name, ty, nd))
        for iname, ity, kind, v, out in inputs:
            if kind == "value":
                self.lines.append('      <input name="%s" type="%s" value="%s"/>' % (iname, ity, v))
            else:
                o = ' output="%s"' % out if out else ""
                self.lines.append('      <input name="%s" type="%s" nodename="%s"%s/>' % (iname, ity, v, o))
        self.lines.append("    </%s>" % category)

    def coord(self, k):
        return ("uv_split", "outx" if k % 2 == 0 else "outy")

    def ramp(self, prefix, ty, lo, hi, k, per_channel=None):
        """A value of type ty over [lo, hi] per channel, channel c following u or v by (k + c)
        (per_channel: explicit (lo, hi) of each channel instead)."""
        n = CHANNELS[ty]
        span = hi - lo
        los = [lo + 0.1 * span * c for c in range(n)]
        his = [hi - 0.05 * span * c for c in range(n)]
        if per_channel:
            los, his = [a for a, _ in per_channel], [b for _, b in per_channel]
        if n == 1:
            src, out = self.coord(k)
            inp = ("in", "float", "node", src, out)
        else:
            ins = []
            for c in range(n):
                src, out = self.coord(k + c)
                ins.append(("in%d" % (c + 1), "float", "node", src, out))
            self.node(COMBINE[ty], prefix + "_uv", ty, ins)
            inp = ("in", ty, "node", prefix + "_uv", None)
        # remap from [0, 1]: lo + t · (hi − lo).
        self.node(
            "remap",
            prefix + "_ramp",
            ty,
            [
                inp,
                ("outlow", ty, "value", ", ".join(fmt(l) for l in los), None),
                ("outhigh", ty, "value", ", ".join(fmt(h) for h in his), None),
            ],
        )
        return prefix + "_ramp"

    def text(self):
        return "\n".join(self.lines + ["  </nodegraph>"])


def input_range(nd, inp, k):
    r = RANGES.get(nd["node"], {})
    if inp["name"] in r:
        return r[inp["name"]]
    if "*" in r:
        return r["*"]
    return (0.1 + 0.04 * k, 0.9 - 0.03 * k)


def constant(nd, inp):
    c = CONSTANTS.get(nd["node"], {})
    if c.get(inp["name"]) is not None:
        return c[inp["name"]]
    if inp["type"] == "filename":
        return IMAGE
    v = inp.get("value", "")
    if v:
        return v
    if inp.get("enum"):
        return inp["enum"][0].strip()
    return typed_default(inp["type"])


def enum_variants(nd):
    """(name suffix, {input: value}) for every other value of each enumerated setting of nd."""
    out = []
    for inp in nd["inputs"]:
        names = [e.strip() for e in inp.get("enum", [])]
        # Enumerated integers and strings (a colour's enum, as luminance's lumacoeffs, names presets).
        if inp["type"] not in ("integer", "string"):
            continue
        if not names or inp["name"] in CONSTANTS.get(nd["node"], {}) or inp["name"] in NO_VARIANTS:
            continue
        values = [v.strip() for v in inp["enumvalues"].split(",")] if inp.get("enumvalues") else names
        default = constant(nd, inp)
        for name, value in zip(names, values):
            if value != default:
                ranges = VARIANT_RANGES.get(inp["name"], {})
                settings = {inp["name"]: value}
                for held in VARIANT_HELD.get(inp["name"], ()):
                    i = next(i for i in nd["inputs"] if i["name"] == held)
                    settings[held] = ", ".join(["0.25"] * CHANNELS.get(i["type"], 1))
                out.append(("%s_%s" % (inp["name"], re.sub(r"\W", "", name).lower()), settings, ranges))
    return out


def graph_for(nd, suffix="", settings=None, ranges=None):
    settings = settings or {}
    ranges = ranges or {}
    g = Graph((nd["name"][3:] if nd["name"].startswith("ND_") else nd["name"]) + suffix)
    ins = []
    k = 0
    for inp in nd["inputs"]:
        ty = inp["type"]
        fixed = inp["name"] in CONSTANTS.get(nd["node"], {})
        driven = not fixed and not inp.get("uniform") and (
            ty in CHANNELS or (ty in ("integer", "boolean") and inp["name"] in OPERANDS)
        )
        if inp["name"] in settings:
            ins.append((inp["name"], ty, "value", settings[inp["name"]], None))
            continue
        if not driven:
            ins.append((inp["name"], ty, "value", constant(nd, inp), None))
            continue
        per_channel = None
        r = ranges.get(inp["name"])
        if r and isinstance(r[0], tuple):
            per_channel, (lo, hi) = r, r[0]
        else:
            lo, hi = r or input_range(nd, inp, k)
        prefix = "drive_" + inp["name"]
        if ty == "integer":
            if nd["node"] not in RANGES or inp["name"] not in RANGES[nd["node"]]:
                lo, hi = {"which": (0.2, 10.6), "value1": (0.2, 4.8), "value2": (0.4, 4.6)}.get(inp["name"], (-5.3, 7.7))
            f = g.ramp(prefix, "float", lo, hi, k)
            g.node("floor", prefix + "_int", "integer", [("in", "float", "node", f, None)])
            src = prefix + "_int"
        elif ty == "boolean":
            f = g.ramp(prefix, "float", 0.0, 1.0, k)
            g.node(
                "ifgreater",
                prefix + "_bool",
                "boolean",
                [
                    ("value1", "float", "node", f, None),
                    ("value2", "float", "value", fmt(0.37 + 0.21 * (k % 3)), None),
                ],
            )
            src = prefix + "_bool"
        else:
            src = g.ramp(prefix, ty, lo, hi, k, per_channel)
            if inp["name"] in QUANTIZED.get(nd["node"], ()):
                g.node("floor", prefix + "_whole", ty, [("in", ty, "node", src, None)])
                src = prefix + "_whole"
        ins.append((inp["name"], ty, "node", src, None))
        k += 1
    multi = len(nd["outputs"]) > 1
    # No `nodedef` attribute: every input is given with its type, which names the nodedef as
    # surely (the bake script checks that MaterialX resolves the one intended).
    g.node(nd["node"], "node", "multioutput" if multi else nd["outputs"][0]["type"], ins)
    elements = []
    for o in nd["outputs"]:
        sel = ' output="%s"' % o["name"] if multi else ""
        g.lines.append('    <output name="%s" type="%s" nodename="node"%s/>' % (o["name"], o["type"], sel))
        elements.append("%s/%s" % (g.name, o["name"]))
    return g, elements


def main():
    table = json.load(open(TABLE))["nodedefs"]
    by_cat = {}
    skipped = []
    for nd in table:
        types = [o["type"] for o in nd["outputs"]]
        bad = [t for t in types if t not in BAKEABLE]
        if bad:
            skipped.append({"nodedef": nd["name"], "node": nd["node"], "type": bad[0], "reason": "output type %s is not an image a texture bake can show" % bad[0]})
            continue
        by_cat.setdefault(nd["node"], []).append(nd)
    if os.path.isdir(OUT):
        shutil.rmtree(OUT)
    os.makedirs(OUT)
    index = []
    for cat, nds in by_cat.items():
        parts = ['<?xml version="1.0"?>', "<!-- Generated by scripts/mtlx-gen-refs.py from MaterialX 1.39.5's nodedefs: one graph per nodedef of `%s`. -->" % cat, '<materialx version="1.39">']
        for i, nd in enumerate(nds):
            # Every type variant at the default settings; the first also at every other value of
            # each enumerated setting (spaces, address modes, noise types, ramp kinds, ...).
            variants = [("", {}, {})] + (enum_variants(nd) if i == 0 else [])
            for suffix, settings, ranges in variants:
                g, elements = graph_for(nd, "_" + suffix if suffix else "", settings, ranges)
                parts.append(g.text())
                for e in elements:
                    index.append({"document": "docs/%s.mtlx" % cat, "element": e, "nodedef": nd["name"], "node": cat})
        parts.append("</materialx>\n")
        with open(os.path.join(OUT, cat + ".mtlx"), "w") as f:
            f.write("\n".join(parts))
    with open(os.path.join(OUT, "..", "generated.json"), "w") as f:
        json.dump({"elements": index, "skipped": skipped}, f, indent=1)
        f.write("\n")
    print("%d documents, %d outputs, %d nodedefs skipped -> %s" % (len(by_cat), len(index), len(skipped), OUT))


if __name__ == "__main__":
    main()
