"""The farm job templates (Open Job Description, farm/*.yaml) pass `openjd check` and, run
locally with `openjd run`, make the images the command line makes in one process."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("TESSERA_BIN", str(ROOT / "target" / "release" / "tessera"))
MARBLE = ROOT / "scenes" / "marble.xml"
OPENJD = shutil.which("openjd") or str(Path(sys.executable).parent / "openjd")
pytestmark = pytest.mark.skipif(not Path(OPENJD).exists(), reason="openjd-cli is not installed")


def run(*args, cwd):
    r = subprocess.run([str(a) for a in args], cwd=cwd, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    return r


@pytest.mark.parametrize("template", ["render-passes.yaml", "render-frames.yaml"])
def test_templates_pass_openjd_check(template, tmp_path):
    run(OPENJD, "check", ROOT / "farm" / template, cwd=tmp_path)


def test_pass_split_job_equals_the_single_render(tmp_path):
    out = tmp_path / "out"
    run(OPENJD, "run", ROOT / "farm" / "render-passes.yaml", "--step", "Merge", "--run-dependencies",
        "-p", f"Scene={MARBLE}", "-p", f"OutputDir={out}", "-p", "Spp=7", "-p", "SamplesPerPass=3",
        "-p", "Seed=4", "-p", "Strategy=outputs", "-p", "Defines=-D res=32", "-p", f"Tessera={BIN}", cwd=tmp_path)
    assert sorted(p.name for p in out.glob("pass-*.exr")) == ["pass-0.exr", "pass-3.exr", "pass-6.exr"]
    run(BIN, "render", MARBLE, "-D", "res=32", "--spp", 7, "--seed", 4, "--strategy", "outputs", "--quiet",
        "--out", tmp_path / "whole.exr", cwd=tmp_path)
    assert (out / "image.exr").read_bytes() == (tmp_path / "whole.exr").read_bytes()


def test_frame_job_renders_each_frame(tmp_path):
    out = tmp_path / "out"
    run(OPENJD, "run", ROOT / "farm" / "render-frames.yaml", "--step", "Frames", "-p", f"Scene={MARBLE}",
        "-p", f"OutputDir={out}", "-p", "Frames=16,24", "-p", "FrameDefine=res", "-p", "Spp=2",
        "-p", "Strategy=none", "-p", f"Tessera={BIN}", cwd=tmp_path)
    for k in [16, 24]:
        run(BIN, "render", MARBLE, "-D", f"res={k}", "--spp", 2, "--quiet", "--out", tmp_path / f"{k}.exr",
            cwd=tmp_path)
        assert (out / f"frame_{k}.exr").read_bytes() == (tmp_path / f"{k}.exr").read_bytes()
