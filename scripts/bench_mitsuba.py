#!/usr/bin/env python3
"""tessera against Mitsuba 3 (llvm_ad_rgb), side by side: for each scene, one warm-up render of
each (Mitsuba compiles its kernels on the first), then interleaved pairs (tessera, Mitsuba) at the
same spp and thread count. Times are the render phase alone: tessera's `phases.render_s` from its
--stats-json, Mitsuba's `mi.render` until the image is computed. Prints per scene the medians and
the throughput ratio tessera / Mitsuba (above 1: tessera is faster). Run by scripts/bench-mitsuba.sh."""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import drjit as dr
import mitsuba as mi

ROOT = Path(__file__).resolve().parents[1]
REFS = ROOT.parent / "shared" / "refs" / "scenes"

ap = argparse.ArgumentParser()
ap.add_argument("scenes", nargs="*", help="scene files (default: every scene of ../shared/refs/scenes)")
ap.add_argument("--tessera", default=str(ROOT / "target" / "release" / "tessera"))
ap.add_argument("--spp", type=int, default=64)
ap.add_argument("--pairs", type=int, default=3)
ap.add_argument("--threads", type=int, default=2)
ap.add_argument("--out", help="also write the table as Markdown to this file")
a = ap.parse_args()

mi.set_variant("llvm_ad_rgb")
dr.set_thread_count(a.threads)
scenes = [Path(s) for s in a.scenes] or sorted(REFS.glob("*.xml"))


def tessera_render(scene: Path, tmp: Path) -> float:
    stats = tmp / "stats.json"
    cmd = [a.tessera, "render", str(scene), "--spp", str(a.spp), "--threads", str(a.threads), "--quiet",
           "--out", str(tmp / "t.exr"), "--stats-json", str(stats)]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"tessera failed on {scene}: {r.stderr}")
    return json.loads(stats.read_text())["phases"]["render_s"]


def mitsuba_render(scene) -> float:
    t = time.perf_counter()
    image = mi.render(scene, spp=a.spp)
    dr.eval(image)
    dr.sync_thread()
    return time.perf_counter() - t


rows = []
with tempfile.TemporaryDirectory() as d:
    tmp = Path(d)
    for path in scenes:
        scene = mi.load_file(str(path))
        mitsuba_render(scene)  # warm-up: kernel compilation
        tessera_render(path, tmp)  # warm-up: file cache
        ts, ms = [], []
        for _ in range(a.pairs):
            ts.append(tessera_render(path, tmp))
            ms.append(mitsuba_render(scene))
        ratios = [m / t for t, m in zip(ts, ms)]
        rows.append((path.stem, statistics.median(ts), statistics.median(ms), statistics.median(ratios),
                     min(ratios), max(ratios)))
        print(f"{path.stem}: tessera {statistics.median(ts):.3f} s, Mitsuba {statistics.median(ms):.3f} s, "
              f"ratio {statistics.median(ratios):.2f}", flush=True)

head = (f"| scene | tessera render s | Mitsuba render s | throughput tessera / Mitsuba (median, range) |\n"
        f"|---|---|---|---|\n")
body = "".join(f"| {n} | {t:.3f} | {m:.3f} | {r:.2f} ({lo:.2f}–{hi:.2f}) |\n" for n, t, m, r, lo, hi in rows)
med = statistics.median(r[3] for r in rows)
note = (f"\n{a.spp} spp, {a.threads} threads each, {a.pairs} interleaved pairs per scene after one warm-up each; "
        f"Mitsuba {mi.__version__} llvm_ad_rgb. Median ratio over the scenes: {med:.2f}.\n")
print()
print(head + body + note)
if a.out:
    Path(a.out).write_text(head + body + note)
