#!/usr/bin/env bash
# Renders every demo and reference scene with each caching strategy at a small size and writes
# the images and the timing-free part of each stats file (and of each profile) under OUT. Two
# such folders, made by two builds, must be byte-identical for a change that claims not to alter
# behaviour: `scripts/identity-check.sh OUT_A; ...; diff -r OUT_A OUT_B`.
#
# One thread: the cache's hit and miss counts depend on which thread fills a tile first (the
# images do not).
#
# usage: scripts/identity-check.sh OUT [TESSERA_BINARY]
set -euo pipefail
out=${1:?usage: identity-check.sh OUT [TESSERA_BINARY]}
bin=${2:-target/release/tessera}
root=$(cd "$(dirname "$0")/.." && pwd)
shared="$root/../shared"
mkdir -p "$out"
# Keys that hold timings (or things derived from them) or output paths, dropped before comparing.
normalise() {
  python3 - "$1" "$2" <<'PY'
import json, sys
TIMING = {"phases", "throughput", "threads", "estimated_s", "images", "aovs", "wall_s", "outside_thread_s",
          "texture_thread_s", "tap_thread_s", "machine", "cost", "report"}
def strip(x):
    if isinstance(x, dict):
        return {k: strip(v) for k, v in x.items() if k not in TIMING}
    if isinstance(x, list):
        return [strip(v) for v in x]
    return x
json.dump(strip(json.load(open(sys.argv[1]))), open(sys.argv[2], "w"), indent=1, sort_keys=True)
PY
}
scenes=("$root"/scenes/*.xml "$root"/scenes/small/*.xml "$root"/scenes/library/*.xml "$shared"/refs/scenes/*.xml)
for scene in "${scenes[@]}"; do
  name=$(basename "$scene" .xml)
  for strategy in none outputs all; do
    tag="$name.$strategy"
    # The footprint AOV once per scene (it traces footprints even where no texture reads them).
    aov=()
    [ "$strategy" = none ] && aov=(--aov footprint)
    "$bin" render "$scene" --spp 2 -D res=48 --quiet --threads 1 --strategy "$strategy" "${aov[@]}" \
      --out "$out/$tag.exr" --stats-json "$out/$tag.raw.json"
    normalise "$out/$tag.raw.json" "$out/$tag.stats.json"
    rm "$out/$tag.raw.json"
  done
  # Scenes without procedural graphs have nothing to profile: the error message is compared.
  if "$bin" profile "$scene" -D res=48 --quiet --threads 1 --out "$out/$name.profile.raw.json" \
      2>"$out/$name.profile.err"; then
    normalise "$out/$name.profile.raw.json" "$out/$name.profile.json"
    rm "$out/$name.profile.raw.json" "$out/$name.profile.err"
  fi
done
echo "wrote $(ls "$out" | wc -l) files to $out"
