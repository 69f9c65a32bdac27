#!/usr/bin/env bash
# Side-by-side `tessera bench` of an earlier commit and the working tree.
#
#   scripts/bench-before-after.sh REV OUT [tessera bench options...]
#
# Builds REV in a worktree of its own (`$OUT/before-src`, target `$OUT/before-target`), builds the
# working tree, then runs the same `tessera bench` with each binary, one after the other, into
# `$OUT/before` and `$OUT/after`, and writes `$OUT/compare.md`: per scene and strategy, the time
# over the free-texture lower bound (each measured within its own run, so machine drift between
# the two runs cancels) and the image error against each binary's own supersampled reference.
# Example: scripts/bench-before-after.sh fbe6b0c /tmp/ba --res 128 --spp 16 --repeats 2
# BEFORE_BIN=PATH uses an already built binary of REV instead of building it.
set -euo pipefail
rev=${1:?usage: bench-before-after.sh REV OUT [bench options]}
out=${2:?usage: bench-before-after.sh REV OUT [bench options]}
shift 2
repo=$(cd "$(dirname "$0")/.." && pwd)
mkdir -p "$out"
out=$(cd "$out" && pwd)
before_bin=${BEFORE_BIN:-}
if [ -z "$before_bin" ]; then
    if [ ! -d "$out/before-src" ]; then
        git -C "$repo" worktree add --detach "$out/before-src" "$rev" >/dev/null
    fi
    (cd "$out/before-src" && CARGO_TARGET_DIR="$out/before-target" cargo build --release -p tessera)
    before_bin="$out/before-target/release/tessera"
fi
(cd "$repo" && cargo build --release -p tessera)
"$before_bin" bench "$repo/scenes" --out "$out/before" --ref-cache "$out/refs-before" "$@"
"$repo/target/release/tessera" bench "$repo/scenes" --out "$out/after" --ref-cache "$out/refs-after" "$@"
python3 - "$out" "$rev" <<'EOF'
import json, sys
out, rev = sys.argv[1], sys.argv[2]
load = lambda side: {s["name"]: s for s in json.load(open(f"{out}/{side}/results.json"))["scenes"]}
before, after = load("before"), load("after")
lines = [f"# `tessera bench` before ({rev}) and after (working tree)", "",
         "Time over the free-texture lower bound (median of the repeats, each run against its own bound), and "
         "image error (relative MSE, LDR-FLIP) against each binary's own supersampled reference. The speed-up "
         "compares absolute times of the two runs, minutes apart on one host: read it with the host's drift in mind; "
         "the ratios are each measured within one run.", "",
         "| scene | strategy | × bound before | × bound after | speed-up | rel. MSE before | after | FLIP before | after |",
         "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
def run(scene, strategy):
    for r in scene["runs"]:
        if r["strategy"] == strategy and r.get("summary"):
            return r["summary"]
    return None
for name, a in after.items():
    b = before.get(name)
    for r in a["runs"]:
        if r["lower_bound"] or not r.get("summary"):
            continue
        sa, sb = r["summary"], run(b, r["strategy"]) if b else None
        ra = sa["ratio_to_lower_bound"]["median"]
        ea = sa.get("image_error") or {}
        if sb:
            rb = sb["ratio_to_lower_bound"]["median"]
            eb = sb.get("image_error") or {}
            speed = sb["time_s"]["median"] / sa["time_s"]["median"]
            lines.append(f"| {name} | {r['strategy']} | {rb:.2f} | {ra:.2f} | {speed:.2f}× | {eb.get('rel_mse', float('nan')):.3e} | "
                         f"{ea.get('rel_mse', float('nan')):.3e} | {eb.get('flip', float('nan')):.4f} | {ea.get('flip', float('nan')):.4f} |")
        else:
            lines.append(f"| {name} | {r['strategy']} | – | {ra:.2f} | – | – | {ea.get('rel_mse', float('nan')):.3e} | – | {ea.get('flip', float('nan')):.4f} |")
open(f"{out}/compare.md", "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
EOF
