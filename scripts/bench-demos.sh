#!/usr/bin/env bash
# Renders every demo scene with each caching strategy and with free textures (the lower bound),
# side by side in one run, and prints a Markdown table of render times and cache memory.
# Usage: scripts/bench-demos.sh [SPP] [RES]   (defaults 8 and 128)
set -euo pipefail
cd "$(dirname "$0")/.."
spp=${1:-8}
res=${2:-128}
cargo build --release -q -p tessera
bin=target/release/tessera
out=$(mktemp -d)
echo "| scene | none (s) | outputs (s) | all (s) | free textures (s) | none / free | outputs / free | all / free | peak MiB outputs | peak MiB all |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for xml in scenes/*.xml; do
  name=$(basename "$xml" .xml)
  for run in none outputs all free; do
    args=(render "$xml" --spp "$spp" -D "res=$res" --quiet --out "$out/$name.exr" --stats-json "$out/$name-$run.json")
    if [ "$run" = free ]; then args+=(--free-textures); else args+=(--strategy "$run"); fi
    "$bin" "${args[@]}"
  done
  python3 - "$out" "$name" <<'PY'
import json, sys
out, name = sys.argv[1], sys.argv[2]
r = {k: json.load(open(f"{out}/{name}-{k}.json")) for k in ["none", "outputs", "all", "free"]}
t = {k: v["phases"]["render_s"] for k, v in r.items()}
peak = lambda k: (r[k].get("cache") or {}).get("peak_bytes", 0) / 2**20
print(f"| {name} | {t['none']:.2f} | {t['outputs']:.2f} | {t['all']:.2f} | {t['free']:.2f} | "
      f"{t['none']/t['free']:.2f} | {t['outputs']/t['free']:.2f} | {t['all']/t['free']:.2f} | {peak('outputs'):.1f} | {peak('all'):.1f} |")
PY
done
rm -rf "$out"
