#!/usr/bin/env python3
"""tessera against Mitsuba 3 (llvm_ad_rgb), side by side: for each scene, one warm-up render of
each (Mitsuba compiles its kernels on the first), then interleaved rounds (each tessera variant,
then Mitsuba) at the same spp and thread count. Times are the render phase alone: tessera's
`phases.render_s` from its --stats-json, Mitsuba's `mi.render` until the image is computed. Prints
per scene the medians and the throughput ratio tessera / Mitsuba (above 1: tessera is faster).
Run by scripts/bench-mitsuba.sh.

Several tessera variants are timed in the same rounds with `--tessera` repeated, each
`LABEL=BINARY [ARGS...]` (a plain path is labelled `tessera`): a binary before and after a change,
say, or `bvh=target/release/tessera --accel bvh` beside `embree=target/release/tessera --accel embree`."""

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
ap.add_argument("--tessera", action="append", help="LABEL=BINARY [ARGS...] (repeatable; default: target/release/tessera)")
ap.add_argument("--spp", type=int, default=64)
ap.add_argument("--pairs", type=int, default=3)
ap.add_argument("--threads", type=int, default=2)
ap.add_argument("--out", help="also write the table as Markdown to this file")
a = ap.parse_args()

mi.set_variant("llvm_ad_rgb")
dr.set_thread_count(a.threads)
scenes = [Path(s) for s in a.scenes] or sorted(REFS.glob("*.xml"))


def variant(spec: str):
    label, sep, rest = spec.partition("=")
    if not sep or "/" in label or " " in label:
        label, rest = "tessera", spec
    words = rest.split()
    return label, words[0], words[1:]


variants = [variant(v) for v in (a.tessera or [str(ROOT / "target" / "release" / "tessera")])]


def tessera_render(scene: Path, tmp: Path, v) -> float:
    stats = tmp / "stats.json"
    cmd = [v[1], "render", str(scene), "--spp", str(a.spp), "--threads", str(a.threads), "--quiet",
           "--out", str(tmp / "t.exr"), "--stats-json", str(stats), *v[2]]
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
        for v in variants:
            tessera_render(path, tmp, v)  # warm-up: file cache
        ts, ms = [[] for _ in variants], []
        for _ in range(a.pairs):
            for k, v in enumerate(variants):
                ts[k].append(tessera_render(path, tmp, v))
            ms.append(mitsuba_render(scene))
        row = [path.stem, statistics.median(ms)]
        for k, v in enumerate(variants):
            ratios = [m / t for t, m in zip(ts[k], ms)]
            row.append((statistics.median(ts[k]), statistics.median(ratios), min(ratios), max(ratios)))
            print(f"{path.stem}: {v[0]} {statistics.median(ts[k]):.3f} s, Mitsuba {statistics.median(ms):.3f} s, "
                  f"ratio {statistics.median(ratios):.2f}", flush=True)
        rows.append(row)

labels = [v[0] for v in variants]
head = ("| scene | Mitsuba render s | " + " | ".join(f"{l} render s | {l} / Mitsuba (median, range)" for l in labels)
        + " |\n|---|---|" + "---|---|" * len(labels) + "\n")
body = "".join(f"| {r[0]} | {r[1]:.3f} | " + " | ".join(f"{t:.3f} | {q:.2f} ({lo:.2f}–{hi:.2f})" for t, q, lo, hi in r[2:])
               + " |\n" for r in rows)
meds = ", ".join(f"{l} {statistics.median(r[2 + k][1] for r in rows):.2f}" for k, l in enumerate(labels))
note = (f"\n{a.spp} spp, {a.threads} threads each, {a.pairs} interleaved rounds per scene after one warm-up each; "
        f"Mitsuba {mi.__version__} llvm_ad_rgb. Median throughput ratio over the scenes: {meds}. Variants: "
        + "; ".join(f"{v[0]} = `{' '.join([v[1], *v[2]])}`" for v in variants) + ".\n")
print()
print(head + body + note)
if a.out:
    Path(a.out).write_text(head + body + note)
