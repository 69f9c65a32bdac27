#!/usr/bin/env bash
# Selective caching on every demo scene: renders none, outputs, all and auto side by side, then
# compares the model's predictions (from auto's profile) with what each render measured.
# Prints Markdown: per scene, predicted against measured, and auto's end-to-end time (profile and
# plan included) against the best fixed strategy.
# Usage: scripts/selective-demos.sh [SPP] [RES] [BUDGET_MB]   (defaults 32, 128, 512)
set -euo pipefail
cd "$(dirname "$0")/.."
spp=${1:-32}
res=${2:-128}
budget=${3:-512}
cargo build --release -q -p tessera
bin=$(pwd)/target/release/tessera
out=$(mktemp -d)
for xml in scenes/*.xml; do
  name=$(basename "$xml" .xml)
  for run in none outputs all auto; do
    "$bin" render "$xml" --spp "$spp" -D "res=$res" --quiet --strategy "$run" --budget-mb "$budget" \
      --out "$out/$name-$run.exr" --stats-json "$out/$name-$run.json"
  done
  echo "## $name ($res², $spp spp, budget $budget MiB)"
  echo
  "$bin" analyze "$out/$name-auto.report/profile.json" --spp "$spp" --budget-mb "$budget" \
    --measured "$out/$name-none.json" --measured "$out/$name-outputs.json" \
    --measured "$out/$name-all.json" --measured "$out/$name-auto.json" | sed -n '/Predicted against measured/,$p' | tail -n +2
  python3 - "$out" "$name" <<'PY'
import json, sys
out, name = sys.argv[1], sys.argv[2]
r = {k: json.load(open(f"{out}/{name}-{k}.json")) for k in ["none", "outputs", "all", "auto"]}
t = {k: v["phases"]["render_s"] + v["phases"].get("cache_setup_s", 0) for k, v in r.items()}
p = r["auto"]["plan"]
auto_total = t["auto"] + p["profile_s"] + p["plan_s"]
best = min(("none", "outputs", "all"), key=lambda k: t[k])
print(f"auto end to end {auto_total:.2f} s (profile {p['profile_s']:.2f} s, plan {p['plan_s']:.3f} s, render {t['auto']:.2f} s; "
      f"{len(p['cached_nodes'])} nodes cached, {p['method']}); best fixed: {best} {t[best]:.2f} s; "
      f"ratio {auto_total / t[best]:.3f}")
print()
PY
done
