"""The Python package against the command line: the same renders bit for bit, images reaching
NumPy without a copy, and bad input as TesseraError with tessera's message.

Run by scripts/test-python.sh (which builds and installs the package), with TESSERA_BIN naming
the command-line binary built from the same tree."""

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import tessera

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("TESSERA_BIN", str(ROOT / "target" / "release" / "tessera"))
SCENES = ROOT / "scenes"


def cli(*args, cwd):
    r = subprocess.run([BIN, *map(str, args)], cwd=cwd, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return r


@pytest.fixture(scope="module")
def marble():
    return tessera.load(SCENES / "marble.xml", res=40)


def test_scene_properties(marble):
    assert (marble.width, marble.height) == (40, 40)
    assert marble.spp == 16
    assert marble.path.name == "marble.xml"
    assert ("res", "40") in marble.defines
    assert "40x40" in repr(marble)


def test_render_equals_the_command_line_bit_for_bit(marble, tmp_path):
    for strategy in ["none", "outputs"]:
        cli("render", SCENES / "marble.xml", "-D", "res=40", "--spp", 3, "--seed", 5, "--strategy", strategy,
            "--out", f"cli-{strategy}.exr", "--quiet", cwd=tmp_path)
        image, stats = tessera.render(marble, spp=3, seed=5, strategy=strategy, out=tmp_path / f"py-{strategy}.exr")
        assert (tmp_path / f"py-{strategy}.exr").read_bytes() == (tmp_path / f"cli-{strategy}.exr").read_bytes()
        # Nothing written: the same pixels.
        again, _ = tessera.render(marble, spp=3, seed=5, strategy=strategy)
        assert np.array_equal(image.view(np.uint32), again.view(np.uint32))
        assert stats["schema"] == "tessera.stats/1"
        assert stats["counts"]["samples"] == 40 * 40 * 3
        assert (stats["cache"] is None) == (strategy == "none")


def test_images_reach_numpy_without_a_copy(marble):
    image, _ = tessera.render(marble, spp=1)
    assert image.shape == (40, 40, 3) and image.dtype == np.float32
    assert image.flags["C_CONTIGUOUS"] and image.flags["WRITEABLE"]
    # NumPy did not allocate the pixels: they are the renderer's buffer, kept alive by the array.
    assert not image.flags["OWNDATA"]
    assert type(image.base).__name__ == "PySliceContainer"
    assert np.isfinite(image).all() and image.mean() > 0.01


def test_threads_and_progress_do_not_change_the_image(marble):
    one, _ = tessera.render(marble, spp=2, threads=1)
    two, _ = tessera.render(marble, spp=2, threads=2)
    assert np.array_equal(one.view(np.uint32), two.view(np.uint32))


def test_passes_rendered_from_python_merge_into_the_whole_render(marble, tmp_path):
    whole, _ = tessera.render(marble, spp=5, seed=2, out=tmp_path / "whole.exr")
    parts = []
    for i, (a, b) in enumerate([(0, 2), (2, 5)]):
        part, stats = tessera.render(marble, spp=5, seed=2, samples=(a, b), out=tmp_path / f"p{i}.exr")
        assert stats["counts"]["samples"] == 40 * 40 * (b - a)
        parts.append(f"p{i}.exr")
    window, _ = tessera.render(marble, spp=5, seed=2, crop=(0, 10, 40, 30), out=tmp_path / "w.exr")
    assert window.shape == (20, 40, 3)
    assert np.array_equal(window.view(np.uint32), whole[10:30].view(np.uint32))
    cli("merge", *parts, "--out", "merged.exr", "--quiet", cwd=tmp_path)
    assert (tmp_path / "merged.exr").read_bytes() == (tmp_path / "whole.exr").read_bytes()


def test_footprint_equals_the_command_line(marble, tmp_path):
    r = cli("footprint", SCENES / "marble.xml", "-D", "res=40", "--pixel", 20, 25, "--seed", 3, "--json", cwd=tmp_path)
    mine = tessera.footprint(marble, (20, 25), seed=3)
    theirs = json.loads(r.stdout)
    assert mine["vertices"] == theirs["vertices"] and mine["radiance"] == theirs["radiance"]
    assert mine["schema"] == "tessera.footprint/1" and mine["seed"] == 3


def test_bake_returns_texel_values(tmp_path):
    # u at texel centres, an independent expectation for a point-sampled bake.
    doc = tmp_path / "u.mtlx"
    doc.write_text(
        '<?xml version="1.0"?>\n<materialx version="1.39">\n'
        '  <nodegraph name="NG">\n'
        '    <texcoord name="uv" type="vector2"/>\n'
        '    <extract name="u" type="float"><input name="in" type="vector2" nodename="uv"/>'
        '<input name="index" type="integer" value="0"/></extract>\n'
        '    <output name="out" type="float" nodename="u"/>\n'
        "  </nodegraph>\n</materialx>\n"
    )
    texels, names = tessera.bake(doc, "NG/out", 8, res_y=2)
    assert texels.shape == (2, 8, 1) and list(names) == ["Y"]
    expected = (np.arange(8) + 0.5) / 8
    assert np.allclose(texels[0, :, 0], expected, atol=1e-6) and np.allclose(texels[1, :, 0], expected, atol=1e-6)
    with pytest.raises(tessera.TesseraError, match="NG/nothing"):
        tessera.bake(doc, "NG/nothing", 8)


def test_bad_input_raises_tessera_errors(marble, tmp_path):
    with pytest.raises(tessera.TesseraError, match="scene file not found"):
        tessera.load(tmp_path / "missing.xml")
    bad = tmp_path / "bad.xml"
    bad.write_text('<scene version="3.0.0">\n  <shape type="sphere">\n</scene>\n')
    with pytest.raises(tessera.TesseraError, match=r"bad\.xml:\d"):
        tessera.load(bad)
    with pytest.raises(tessera.TesseraError, match="unknown strategy"):
        tessera.render(marble, strategy="sometimes")
    with pytest.raises(tessera.TesseraError, match="--spp must be between"):
        tessera.render(marble, spp=0)
    with pytest.raises(tessera.TesseraError, match="beyond the render's 4 samples"):
        tessera.render(marble, spp=4, samples=(2, 6), out=tmp_path / "p.exr")
    with pytest.raises(tessera.TesseraError, match="outside the 40"):
        tessera.footprint(marble, (99, 0))
    with pytest.raises(TypeError):
        tessera.render(marble, spp="many")
    assert not (tmp_path / "p.exr").exists()
