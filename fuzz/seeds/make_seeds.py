#!/usr/bin/env python3
"""Writes the hand-made fuzz seeds (small PLY, OBJ and PNG files of each form the readers
handle) into fuzz/seeds/<target>/. The other seeds are copies of the repository's own scenes,
documents and images and of profiles and plans `tessera` wrote (see docs/fuzzing.md)."""
import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))


def put(target, name, data):
    os.makedirs(os.path.join(HERE, target), exist_ok=True)
    with open(os.path.join(HERE, target, name), "wb") as f:
        f.write(data.encode() if isinstance(data, str) else data)


# --- PLY: a quad (positions, normals, uvs) in each encoding, and a few header forms.
QUAD = [(-1, -1, 0, 0, 0), (1, -1, 0, 1, 0), (1, 1, 0, 1, 1), (-1, 1, 0, 0, 1)]


def ply_header(fmt, extra=""):
    return (
        f"ply\nformat {fmt} 1.0\ncomment tessera fuzz seed\nelement vertex 4\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        "property float u\nproperty float v\n"
        f"element face 2\nproperty list uchar int vertex_indices\n{extra}end_header\n"
    )


def ply_binary(endian):
    fmt = "binary_little_endian" if endian == "<" else "binary_big_endian"
    out = ply_header(fmt).encode()
    for x, y, z, u, v in QUAD:
        out += struct.pack(endian + "8f", x, y, z, 0, 0, 1, u, v)
    out += struct.pack(endian + "B3i", 3, 0, 1, 2) + struct.pack(endian + "B3i", 3, 0, 2, 3)
    return out


ascii_body = "".join(f"{x} {y} {z} 0 0 1 {u} {v}\n" for x, y, z, u, v in QUAD) + "3 0 1 2\n3 0 2 3\n"
put("ply", "quad_ascii.ply", ply_header("ascii") + ascii_body)
put("ply", "quad_le.ply", ply_binary("<"))
put("ply", "quad_be.ply", ply_binary(">"))
put(
    "ply",
    "polygon_extra.ply",
    "ply\nformat ascii 1.0\nelement vertex 5\nproperty double x\nproperty double y\nproperty double z\n"
    "property uchar red\nproperty float s\nproperty float t\n"
    "element face 1\nproperty list ushort uint vertex_index\nproperty uchar flags\n"
    "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n"
    "0 0 0 255 0 0\n1 0 0 0 1 0\n1 1 0 0 1 1\n0 1 0 0 0 1\n0.5 1.5 0 9 0.5 1\n5 0 1 2 4 3 7\n0 1\n",
)
put(
    "ply",
    "short_index.ply",
    "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 1\nproperty list uchar short vertex_indices\nend_header\n".encode()
    + struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
    + struct.pack("<B3h", 3, 0, 1, 2),
)

# --- OBJ: the forms of face corners, groups, polygons, negative indices, comments.
put("obj", "quad_vtn.obj", "# quad\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
    "vn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\n")
put("obj", "tri_v.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
put("obj", "vn_only.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n")
put("obj", "negative.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf -4/-3 -3/-2 -2/-1\n"
    "f -3/-2 -1/-3 -2/-1\n")
put("obj", "groups.obj", "mtllib none.mtl\no first\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\ns 1\nf 1 2 3\n"
    "g second\nv 0 0 1\nv 1 0 1\nv 0 1 1\nv 1 1 1\nf 4 5 7 6\nl 1 2\np 3\n")
cube = ["v %d %d %d" % (x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
faces = ["f 1 3 4 2", "f 5 6 8 7", "f 1 2 6 5", "f 3 7 8 4", "f 1 5 7 3", "f 2 4 8 6"]
put("obj", "cube.obj", "\n".join(cube + faces) + "\n")

# --- PNG: 3×2 images of each colour type and bit depth the decoder handles, one interlaced.


def chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def png(color_type, depth, rows, extra=b"", interlace=0, w=3, h=2):
    ihdr = struct.pack(">IIBBBBB", w, h, depth, color_type, 0, 0, interlace)
    raw = b"".join(b"\x00" + r for r in rows)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + extra + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")


put("png", "rgb8.png", png(2, 8, [bytes(range(0, 9)), bytes(range(100, 109))]))
put("png", "rgba8.png", png(6, 8, [bytes(range(0, 12)), bytes(range(200, 212))]))
put("png", "gray8.png", png(0, 8, [b"\x00\x80\xff", b"\x10\x20\x30"]))
put("png", "gray_alpha8.png", png(4, 8, [b"\x00\xff\x80\xff\xff\x00", b"\x10\x20\x30\x40\x50\x60"]))
put("png", "rgb16.png", png(2, 16, [bytes(range(0, 18)), bytes(range(50, 68))]))
put("png", "gray1.png", png(0, 1, [b"\xa0", b"\x40"]))
put("png", "palette.png", png(3, 8, [b"\x00\x01\x02", b"\x02\x01\x00"],
                              extra=chunk(b"PLTE", b"\xff\x00\x00\x00\xff\x00\x00\x00\xff") + chunk(b"tRNS", b"\x80")))
# Adam7 of 3×2: passes 1, 4 and 6 hold one pixel of row 0 each, pass 7 all of row 1.
put("png", "interlaced.png", png(2, 8, [b"\x01\x02\x03", b"\x04\x05\x06", b"\x07\x08\x09", bytes(range(10, 19))], interlace=1))
put("png", "gamma_srgb.png", png(2, 8, [bytes(9), bytes(9)], extra=chunk(b"gAMA", struct.pack(">I", 45455))
                                 + chunk(b"sRGB", b"\x00")))

# --- Mitsuba XML: the parts the repository's scenes do not use, naming the fuzz targets' tiny
# assets (fuzz/src/lib.rs writes them beside the scene: mesh.obj, mesh.ply, texture.png,
# texture.exr, part.xml).
SENSOR = """    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 1, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="$res"/>
            <rfilter type="gaussian"/></film>
    </sensor>
"""
put("mitsuba_xml", "assets.xml", f"""<?xml version="1.0"?>
<scene version="3.0.0">
    <default name="spp" value="2"/>
    <default name="res" value="8"/>
    <integrator type="path"><integer name="max_depth" value="4"/><integer name="rr_depth" value="2"/></integrator>
{SENSOR}    <bsdf type="diffuse" id="white"><rgb name="reflectance" value="0.8, 0.8, 0.8"/></bsdf>
    <shape type="obj" id="o">
        <string name="filename" value="mesh.obj"/>
        <boolean name="face_normals" value="true"/>
        <transform name="to_world"><scale value="2"/><translate x="-0.5"/></transform>
        <ref id="white"/>
    </shape>
    <shape type="ply">
        <string name="filename" value="mesh.ply"/>
        <boolean name="flip_tex_coords" value="true"/>
        <transform name="to_world"><matrix value="1 0 0 0 0 1 0 1 0 0 1 0 0 0 0 1"/></transform>
        <bsdf type="twosided"><bsdf type="diffuse">
            <texture type="bitmap" name="reflectance">
                <string name="filename" value="texture.png"/>
                <string name="wrap_mode" value="mirror"/>
                <transform name="to_uv"><scale x="2" y="3"/></transform>
            </texture>
        </bsdf></bsdf>
    </shape>
    <shape type="sphere">
        <point name="center" x="0" y="3" z="0"/>
        <float name="radius" value="0.25"/>
        <emitter type="area"><rgb name="radiance" value="20, 20, 20"/></emitter>
    </shape>
    <shape type="disk">
        <transform name="to_world"><rotate x="1" angle="-90"/><scale value="5"/></transform>
        <bsdf type="diffuse"><texture type="checkerboard" name="reflectance">
            <rgb name="color0" value="0.1"/><rgb name="color1" value="0.9"/></texture></bsdf>
    </shape>
    <emitter type="envmap">
        <string name="filename" value="texture.exr"/>
        <float name="scale" value="0.5"/>
        <transform name="to_world"><rotate y="1" angle="90"/></transform>
    </emitter>
    <emitter type="point"><point name="position" value="1, 2, 3"/><rgb name="intensity" value="5"/></emitter>
    <emitter type="directional"><vector name="direction" x="0" y="-1" z="0"/><rgb name="irradiance" value="1"/></emitter>
    <include filename="part.xml"/>
</scene>
""")
put("mitsuba_xml", "materials.xml", f"""<scene version="3.0.0">
    <default name="spp" value="1"/>
    <default name="res" value="4"/>
{SENSOR}    <shape type="cube"><bsdf type="roughconductor"><string name="material" value="Au"/>
        <float name="alpha" value="0.2"/><string name="distribution" value="ggx"/></bsdf></shape>
    <shape type="rectangle"><bsdf type="dielectric"><float name="int_ior" value="1.5"/></bsdf></shape>
    <shape type="rectangle"><bsdf type="roughdielectric"><float name="alpha" value="0.3"/></bsdf></shape>
    <shape type="rectangle"><bsdf type="twosided"><bsdf type="conductor"/></bsdf></shape>
    <shape type="rectangle"><bsdf type="mask"><float name="opacity" value="0.5"/><bsdf type="diffuse"/></bsdf></shape>
    <shape type="sphere"><bsdf type="diffuse"><texture type="mtlx" name="reflectance">
        <string name="filename" value="checker.mtlx"/><string name="output" value="NG_checker/out"/></texture></bsdf></shape>
    <emitter type="constant"><spectrum name="radiance" value="0.5"/></emitter>
</scene>
""")

# --- EXR: 4×3 RGB images, scan lines uncompressed (float, half and uint channels), RLE, ZIPS
# and ZIP, and a tiled one. (The conformance suite's bakes, fuzz.sh adds them, are all PIZ.)
W, H = 4, 3


def exr_attr(name, ty, value):
    return name + b"\0" + ty + b"\0" + struct.pack("<i", len(value)) + value


def exr_header(channels, compression, tiles=None):
    chlist = b"".join(n + b"\0" + struct.pack("<iB3xii", t, 0, 1, 1) for n, t in channels) + b"\0"
    window = struct.pack("<4i", 0, 0, W - 1, H - 1)
    attrs = [
        exr_attr(b"channels", b"chlist", chlist),
        exr_attr(b"compression", b"compression", bytes([compression])),
        exr_attr(b"dataWindow", b"box2i", window),
        exr_attr(b"displayWindow", b"box2i", window),
        exr_attr(b"lineOrder", b"lineOrder", b"\0"),
        exr_attr(b"pixelAspectRatio", b"float", struct.pack("<f", 1)),
        exr_attr(b"screenWindowCenter", b"v2f", struct.pack("<2f", 0, 0)),
        exr_attr(b"screenWindowWidth", b"float", struct.pack("<f", 1)),
    ]
    if tiles:
        attrs.append(exr_attr(b"tiles", b"tiledesc", struct.pack("<IIB", tiles[0], tiles[1], 0)))
    version = 2 | (0x200 if tiles else 0)
    return b"v/1\x01" + struct.pack("<i", version) + b"".join(attrs) + b"\0"


def sample(t, v):
    return {0: struct.pack("<I", int(v * 100)), 1: struct.pack("<e", v), 2: struct.pack("<f", v)}[t]


def exr_rows(channels, y0, y1, x0=0, x1=W):
    """The pixel bytes of rows y0..y1: per row, per channel (in name order), the samples."""
    out = b""
    for y in range(y0, y1):
        for n, t in channels:
            out += b"".join(sample(t, (x + 2 * y + ord(n[:1])) / 16) for x in range(x0, x1))
    return out


def exr_predict(raw):
    """OpenEXR's ZIP/RLE preprocessing: bytes split into even and odd halves, then deltas."""
    half = (len(raw) + 1) // 2
    t = bytearray(len(raw))
    t[:half], t[half:] = raw[0::2], raw[1::2]
    for i in range(len(t) - 1, 0, -1):
        t[i] = (t[i] - t[i - 1] + 128) & 0xFF
    return bytes(t)


def exr_rle(data):
    out, i = bytearray(), 0
    while i < len(data):
        run = 1
        while i + run < len(data) and data[i + run] == data[i] and run < 128:
            run += 1
        if run >= 3:
            out += struct.pack("b", run - 1) + data[i:i + 1]
            i += run
        else:
            lit = data[i:i + min(127, len(data) - i)]
            out += struct.pack("b", -len(lit)) + lit
            i += len(lit)
    return bytes(out)


def exr_scanlines(channels, compression, lines_per_chunk, pack):
    header = exr_header(channels, compression)
    chunks = []
    for y in range(0, H, lines_per_chunk):
        raw = exr_rows(channels, y, min(H, y + lines_per_chunk))
        data = pack(raw)
        if len(data) >= len(raw):
            data = raw  # stored as is when compression does not pay, as OpenEXR does
        chunks.append(struct.pack("<ii", y, len(data)) + data)
    offset = len(header) + 8 * len(chunks)
    table = b""
    for c in chunks:
        table += struct.pack("<Q", offset)
        offset += len(c)
    return header + table + b"".join(chunks)


RGB_F = [(b"B", 2), (b"G", 2), (b"R", 2)]
RGBA_H = [(b"A", 1), (b"B", 1), (b"G", 1), (b"R", 1)]
put("exr", "none_float.exr", exr_scanlines(RGB_F, 0, 1, lambda raw: raw))
put("exr", "none_half_uint.exr", exr_scanlines(RGBA_H + [(b"Z", 0)], 0, 1, lambda raw: raw))
put("exr", "rle_half.exr", exr_scanlines(RGBA_H, 1, 1, lambda raw: exr_rle(exr_predict(raw))))
put("exr", "zips_float.exr", exr_scanlines(RGB_F, 2, 1, lambda raw: zlib.compress(exr_predict(raw))))
put("exr", "zip_half.exr", exr_scanlines(RGBA_H, 3, 16, lambda raw: zlib.compress(exr_predict(raw))))
# Tiled, one level, 2×2 tiles, uncompressed.
tiled_header = exr_header(RGB_F, 0, tiles=(2, 2))
tiles = []
for ty in range(0, (H + 1) // 2):
    for tx in range(0, W // 2):
        data = exr_rows(RGB_F, 2 * ty, min(H, 2 * ty + 2), 2 * tx, 2 * tx + 2)
        tiles.append(struct.pack("<iiiii", tx, ty, 0, 0, len(data)) + data)
offset, table = len(tiled_header) + 8 * len(tiles), b""
for c in tiles:
    table += struct.pack("<Q", offset)
    offset += len(c)
put("exr", "tiled_float.exr", tiled_header + table + b"".join(tiles))
