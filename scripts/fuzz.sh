#!/usr/bin/env bash
# Coverage-guided fuzzing of tessera's readers on the stable toolchain (docs/fuzzing.md).
#
#   scripts/fuzz.sh [SECONDS] [TARGET...]
#
# Installs cargo-fuzz if it is missing, builds every fuzz target with `--sanitizer none`
# (sanitizers need nightly; without one, libFuzzer's coverage guidance and Rust's own checks,
# overflow checks and debug assertions included, still find panics), then runs each TARGET (all
# by default) for SECONDS (default 60), one at a time. Each target's corpus is
# fuzz/corpus/TARGET, seeded from fuzz/seeds/TARGET and from the repository's scenes,
# documents and images (and ../shared when it is there); crashes land in fuzz/artifacts/TARGET
# and are replayed at the end so that their panic messages show. A summary table (seconds,
# executions, exec/s, corpus files and bytes, crashes) is printed and written to
# fuzz/logs/summary.md. Exits 1 if any target crashed.
#
# Environment: CARGO_TARGET_DIR is honoured; FUZZ_ARGS adds libFuzzer flags (e.g. -jobs=2).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
seconds=${1:-60}
shift || true
case $seconds in '' | *[!0-9]*) echo "usage: scripts/fuzz.sh [SECONDS] [TARGET...]" >&2; exit 2 ;; esac

if ! cargo fuzz --version > /dev/null 2>&1; then
    echo "== installing cargo-fuzz" >&2
    cargo install cargo-fuzz --locked
fi

cd fuzz
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    mapfile -t targets < <(cargo fuzz list)
fi
echo "== building ${targets[*]} (cargo fuzz build --sanitizer none)" >&2
cargo fuzz build --sanitizer none

shared=$root/../shared
# Copies the repository's (and shared/'s) files of the kind TARGET reads into $2.
gather() {
    local target=$1 dir=$2
    mkdir -p "$dir"
    cp -n "seeds/$target"/* "$dir"/ 2> /dev/null || true
    local from=()
    case $target in
        mitsuba_xml) from=("$root/scenes" "$shared/refs/scenes"); pat='*.xml' ;;
        mtlx) from=("$root/scenes" "$root/crates" "$shared/mtlx-suite"); pat='*.mtlx' ;;
        obj) from=("$shared/refs/scenes"); pat='*.obj' ;;
        png) from=("$shared/refs/scenes"); pat='*.png' ;;
        exr) from=("$shared/mtlx-suite/bakes/channel"); pat='*.exr' ;;
        *) return 0 ;;
    esac
    local d f
    for d in "${from[@]}"; do
        [ -d "$d" ] || continue
        while IFS= read -r -d '' f; do
            # Keep seeds small: libFuzzer caps new inputs at the largest seed's size.
            [ "$(stat -c %s "$f")" -le 65536 ] || continue
            cp -n "$f" "$dir/$(echo "${f#"$root"/}" | tr '/' '_')"
        done < <(find "$d" -name "$pat" -type f -print0)
    done
}

mkdir -p logs
summary=logs/summary.md
{
    echo "| target | seconds | executions | exec/s | corpus files | corpus bytes | crashes |"
    echo "|---|---:|---:|---:|---:|---:|---:|"
} > "$summary"
status=0
for t in "${targets[@]}"; do
    corpus=corpus/$t
    gather "$t" "$corpus"
    mkdir -p "artifacts/$t"
    before=$(find "artifacts/$t" -type f | sort)
    echo "== fuzzing $t for ${seconds}s (corpus $corpus: $(find "$corpus" -type f | wc -l) files)" >&2
    start=$(date +%s)
    # -close_fd_mask=2: the loaders' warnings on stderr would flood the log (libFuzzer's own
    # report still shows; crashes are replayed below with stderr open).
    # shellcheck disable=SC2086
    cargo fuzz run --sanitizer none "$t" "$corpus" -- -max_total_time="$seconds" -timeout=30 \
        -print_final_stats=1 -close_fd_mask=2 ${FUZZ_ARGS:-} > "logs/$t.log" 2>&1 || true
    elapsed=$(($(date +%s) - start))
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "logs/$t.log" | grep -o '[0-9]*$' | tail -1)
    rate=$(grep -o 'stat::average_exec_per_sec: *[0-9]*' "logs/$t.log" | grep -o '[0-9]*$' | tail -1)
    files=$(find "$corpus" -type f | wc -l)
    bytes=$(find "$corpus" -type f -printf '%s\n' | awk '{s += $1} END {print s + 0}')
    new=$(comm -13 <(echo "$before") <(find "artifacts/$t" -type f | sort) | sed '/^$/d')
    crashes=$(echo -n "$new" | grep -c . || true)
    echo "| $t | $elapsed | ${execs:-?} | ${rate:-?} | $files | $bytes | $crashes |" >> "$summary"
    if [ "$crashes" -gt 0 ]; then
        status=1
        echo "$new" | head -5 | while IFS= read -r a; do
            echo "== $t: replaying $a (minimise with: cargo fuzz tmin --sanitizer none $t $a)" >&2
            cargo fuzz run --sanitizer none "$t" "$a" 2>&1 | grep -v '^INFO\|^WARNING' | tail -15 >&2 || true
        done
    fi
done
cat "$summary"
exit $status
