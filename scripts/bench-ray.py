#!/usr/bin/env python3
"""Side by side in one run: a render in one process (tessera.render, 2 threads) and the same
render as sample passes on a local 2-worker Ray cluster (tessera.distributed.render, one CPU
and one thread per task), then merged. Prints the times, the overhead and the ratio, and checks
that the images are identical.

usage: scripts/bench-ray.py [SCENE] [--spp N] [--res R] [--passes P] [--repeats K]
(run with the Python that has tessera and ray installed, e.g. target/py-venv/bin/python)"""

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
import ray

import tessera
import tessera.distributed as td

root = Path(__file__).resolve().parents[1]
ap = argparse.ArgumentParser()
ap.add_argument("scene", nargs="?", default=str(root / "scenes" / "marble.xml"))
ap.add_argument("--spp", type=int, default=16)
ap.add_argument("--res", type=int, default=128)
ap.add_argument("--passes", type=int, default=2)
ap.add_argument("--repeats", type=int, default=3)
ap.add_argument("--strategy", default="outputs")
a = ap.parse_args()

t = time.perf_counter()
ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
init_s = time.perf_counter() - t
scene = tessera.load(a.scene, res=a.res)
single, distributed = [], []
for _ in range(a.repeats):
    t = time.perf_counter()
    img_local, _ = tessera.render(scene, spp=a.spp, strategy=a.strategy, threads=2)
    single.append(time.perf_counter() - t)
    t = time.perf_counter()
    img_ray, _ = td.render(a.scene, spp=a.spp, strategy=a.strategy, passes=a.passes, defines={"res": a.res})
    distributed.append(time.perf_counter() - t)
    assert np.array_equal(img_local.view(np.uint32), img_ray.view(np.uint32)), "images differ"
s, d = statistics.median(single), statistics.median(distributed)
print(f"scene {Path(a.scene).name} {a.res}x{a.res} at {a.spp} spp, strategy {a.strategy}, {a.passes} passes")
print(f"ray.init: {init_s:.2f} s (once per driver)")
print(f"single process, 2 threads: {s:.3f} s (median of {a.repeats}: {', '.join(f'{x:.3f}' for x in single)})")
print(f"ray, 2 workers x 1 thread: {d:.3f} s (median of {a.repeats}: {', '.join(f'{x:.3f}' for x in distributed)})")
print(f"overhead {d - s:+.3f} s, ratio {d / s:.2f}; images identical")
ray.shutdown()
