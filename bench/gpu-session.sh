#!/usr/bin/env bash
# Everything a short GPU lease is for, as one bounded command (../shared/notes/gpu-device.md):
#
#   bench/gpu-session.sh RESULTS [SECONDS [RESERVE]]      (defaults 560 and 120)
#
# From DEV (default .device, made on the development machine: the stripped `cocog`, bench/ with
# sharp-dev and defocus-dev's scenes, lpips/alex.safetensors, and tests.tar.xz holding stripped
# GPU test executables from `cargo test --no-run`):
#  1. speed on an otherwise idle GPU: `cocog bench` of sharp-dev at 100×75 and of one million
#     random Gaussians at 1920×1080 (#11);
#  2. the GPU tests on this adapter (f64 references and finite differences), beside
#  3. bench/gates.sh's quality runs, all at once, interrupted where they would outrun the
#     lease (#9, #12; run the same command again on the same machine to continue them);
#  4. a 3dgs step against a cocog step at the same Gaussians and size (#12's ≤ 2.5×), from the
#     dev-table cocog run's model, again on an idle GPU.
# RESULTS gets bench.txt, tests.log and gates.tgz (logs, scores, learned focus; no models).
set -uo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
results="${1:?usage: bench/gpu-session.sh RESULTS [SECONDS [RESERVE]]}"
budget="${2:-560}"
reserve="${3:-120}"
dev="${DEV:-$root/.device}"
work="${WORK:-/tmp/gpu-session}"
cocog="$dev/cocog"
export COCOG="$cocog" COCOG_LPIPS_WEIGHTS="$dev/lpips"
mkdir -p "$results" "$work"
bench="$results/bench.txt"
left() { echo $((budget - SECONDS)); }

section() { printf '\n== %s (at %d s)\n' "$*" "$SECONDS" >>"$bench"; }
for s in sharp-dev defocus-dev/dev-table; do
    n="$work/in-$(basename "$s")"
    [[ -f "$n/scene.json" ]] || "$cocog" ingest colmap "$dev/bench/$s" -o "$n" -q --force
done

# 1. Idle-GPU speed, skipped when this is a continuation (the figures exist).
if [[ ! -f "$work/bench-done" ]]; then
    section "sharp-dev, 100×75, 3dgs"
    timeout 90 "$cocog" bench "$work/in-sharp-dev" --downscale 4 --iterations 300 --warmup 30 \
        >>"$bench" 2>&1
    section "synthetic 1,000,000 Gaussians, 1920×1080, 3dgs"
    timeout 120 "$cocog" bench --synthetic 1000000 --size 1920x1080 --iterations 20 --warmup 5 \
        >>"$bench" 2>&1
    touch "$work/bench-done"
fi

# 2. and 3.
if [[ -f "$dev/tests.tar.xz" && ! -d "$work/tests" ]]; then
    mkdir -p "$work/tests" && tar xJf "$dev/tests.tar.xz" -C "$work"
    (
        for t in "$work"/tests/*; do
            echo "== $(basename "$t")"
            CI=true timeout 150 "$t" --test-threads 2 2>&1 | grep -E "^test |test result|panicked|FAILED|assert"
        done
    ) >"$results/tests.log" 2>&1 &
    tests=$!
fi
# Trainings stop RESERVE seconds before the end: for their evaluations, the step comparison and
# the archive.
"$root/bench/gates.sh" "$work/g" 9-small 12-small 12-variants 9-full --scenes "$dev/bench" \
    --jobs 12 --deadline $(($(left) - reserve)) 2>"$results/gates.err"
if [[ -n "${tests:-}" ]]; then
    while kill -0 "$tests" 2>/dev/null && (($(left) > 75)); do sleep 2; done
    if kill -0 "$tests" 2>/dev/null; then
        kids=$(pgrep -P "$tests")
        kill "$tests" 2>/dev/null
        [[ -n "$kids" ]] && kill $kids 2>/dev/null
        echo "(tests stopped at $SECONDS s, still running)" >>"$results/tests.log"
    fi
fi

# 4. The same Gaussians through both steps.
model="$work/g/dev-table-cocog-d4-7000"
[[ -f "$model/gaussians.ply" ]] || model="$work/g/dev-table-cocog-d4-7000.checkpoint"
if [[ -e "$model" && ! -f "$work/compare-done" ]] && (($(left) > 30)); then
    touch "$work/compare-done"
    for m in 3dgs cocog; do
        section "dev-table, 100×75, --resume $(basename "$model"), $m"
        timeout 30 "$cocog" bench "$work/in-dev-table" --downscale 4 --resume "$model" --method "$m" \
            --iterations 100 --warmup 10 >>"$bench" 2>&1
    done
fi

tar czf "$results/gates.tgz" -C "$work" --exclude='*.ply' --exclude='*.checkpoint' \
    --exclude='checkpoint' --exclude='.ingest-*' g
cp "$work/g/summary.tsv" "$results/" 2>/dev/null
column -t -s $'\t' "$work/g/summary.tsv" 2>/dev/null || cat "$work/g/summary.tsv"
echo "gpu-session: done at $SECONDS s"
