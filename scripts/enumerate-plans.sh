#!/usr/bin/env bash
# Measures every subset of cached nodes of scenes/small/small_graph.xml (six cacheable nodes:
# 64 renders) and compares the fastest measured subset with --strategy auto's choice and
# end-to-end time (profile and plan included). Each render is repeated REPEATS times (median).
# Usage: scripts/enumerate-plans.sh [SPP] [RES] [REPEATS]   (defaults 32, 128, 3)
set -euo pipefail
cd "$(dirname "$0")/.."
spp=${1:-32}
res=${2:-128}
reps=${3:-3}
cargo build --release -q -p tessera
bin=$(pwd)/target/release/tessera
scene=scenes/small/small_graph.xml
out=$(mktemp -d)
nodes=(rock cells grain blend mask color)
for r in $(seq "$reps"); do
  for mask in $(seq 0 63); do
    sel=()
    for k in "${!nodes[@]}"; do
      if (( mask >> k & 1 )); then sel+=("NG_small/${nodes[$k]}"); fi
    done
    if [ ${#sel[@]} -eq 0 ]; then strat=none; else strat="nodes:$(IFS=,; echo "${sel[*]}")"; fi
    "$bin" render "$scene" --spp "$spp" -D "res=$res" --quiet --strategy "$strat" --out "$out/x.exr" --stats-json "$out/m$mask-r$r.json"
  done
  "$bin" render "$scene" --spp "$spp" -D "res=$res" --quiet --strategy auto --out "$out/auto.exr" --stats-json "$out/auto-r$r.json"
done
python3 - "$out" "$reps" <<'PY'
import json, sys, statistics
out, reps = sys.argv[1], int(sys.argv[2])
nodes = ["rock", "cells", "grain", "blend", "mask", "color"]
def t(path):
    s = json.load(open(path)); return s["phases"]["render_s"] + s["phases"].get("cache_setup_s", 0)
times = {m: statistics.median(t(f"{out}/m{m}-r{r}.json") for r in range(1, reps + 1)) for m in range(64)}
best = min(times, key=times.get)
autos = [json.load(open(f"{out}/auto-r{r}.json")) for r in range(1, reps + 1)]
auto_t = statistics.median(a["phases"]["render_s"] + a["plan"]["profile_s"] + a["plan"]["plan_s"] for a in autos)
chosen = autos[0]["plan"]["cached_nodes"]
name = lambda m: ",".join(nodes[k] for k in range(6) if m >> k & 1) or "none"
print(f"best measured subset: {name(best)} {times[best]:.3f} s; none {times[0]:.3f} s; all six {times[63]:.3f} s")
print(f"auto: caches {', '.join(chosen) or 'nothing'}; end to end {auto_t:.3f} s (ratio to best measured {auto_t / times[best]:.3f})")
ranked = sorted(times, key=times.get)
print("fastest five:", "; ".join(f"{name(m)} {times[m]:.3f}" for m in ranked[:5]))
PY
