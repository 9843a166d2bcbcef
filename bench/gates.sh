#!/usr/bin/env bash
# The issues' quality gates as one prepared run: for a session lent a GPU, whose device time is
# short (run the sets that fit, one call), or on lavapipe in the background (hours).
#
#   bench/gates.sh OUT SET... [--scenes DIR] [--iterations N] [--jobs J] [--deadline S]
#                  [-- TRAIN_ARGS...]
#
# SETs, each run = ingest colmap -> train (test views scored every 500 iterations) -> cocog eval
# of the sharp test views (+ cocog lens against the true focus for cocog runs):
#   9-small    3dgs on sharp-dev and defocus-dev/dev-table, --downscale 4, 7000 iterations (#9)
#   9-full     the same at full size, 30000 iterations (#9)
#   12-small   3dgs and cocog on dev-table and dev-shelf, --downscale 4, 7000 iterations (#12)
#   12-full    the same at full size, 30000 iterations (#12)
#   12-full-table, 12-full-shelf  12-full's two runs of one scene: a lease too short for both
#              scenes runs one, and a later lease the other
#   12-full-cocog-table, 12-full-cocog-shelf  the cocog run of one scene alone, so it has the
#              GPU to itself (a full-size cocog run is most of a 15-minute lease)
#   12-full-3dgs  the 3dgs runs of both scenes at full size (about a minute each on an H100),
#              for a lease with room beside other work
#   12-variants cocog's lens and code variants (--coc-variant) on both dev scenes, --downscale 4,
#              7000 iterations (#12 asks for both; 12-small trains the default)
# On lavapipe (128 MiB bindings) 12-full's cocog runs fit (F takes its renders in chunks); a
# failed run gets a `failed` row and the others go on.
# --iterations N overrides every run's length (a smoke test: the schedules stay as they are);
# TRAIN_ARGS go to every `cocog train`. --jobs J trains J runs at once (a GPU that small images
# leave idle between dispatches; their train seconds then time a shared GPU, not a speed figure).
# --deadline S interrupts the trainings still running S seconds after the start (each keeps
# OUT/RUN.checkpoint and its log with the test-view scores, OUT/RUN.train-log.jsonl) and records them as
# `stopped` with the last scored iteration, so one bounded call still reports every run; the
# same command again continues the stopped runs from their checkpoints and skips finished ones. Scenes
# come from --scenes (default ../shared/bench, which holds sharp-dev/ and defocus-dev/); cocog is
# $COCOG, else target/release/cocog. Each run's own output goes to OUT/RUN.log.
#
# OUT/RUN/ keeps each trained scene (train-log.jsonl, scene.json with the learned focus
# distances, metrics.json, lens.json); OUT/summary.tsv has one line per run: run, iterations,
# train seconds, Gaussians, test PSNR, SSIM (Deblur-NeRF), SSIM (Gaussian-11), LPIPS-Alex (n/a
# without its weights: scripts/lpips/fetch-weights.sh, or COCOG_LPIPS_WEIGHTS), the iteration of
# the last training-PSNR drop, and the median relative focus error (cocog runs).
#
# On a lent GPU (../shared/notes/gpu-device.md carries the Vulkan loader): put the stripped
# binary, the three scenes without their depth/ folders and the LPIPS weights under .device/,
# then run, e.g., `COCOG=.device/cocog COCOG_LPIPS_WEIGHTS=.device/lpips bench/gates.sh /tmp/g
# 9-small 12-small --scenes .device/bench && tar czf $OUT/gates.tgz -C /tmp g` (at most 8 files
# come back from $OUT).
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
usage() { sed -n '2,44p' "${BASH_SOURCE[0]}" >&2; exit 2; }

out="" sets=() scenes="$root/../shared/bench" iterations="" train_args=() jobs=1 deadline=""
while [[ $# -gt 0 ]]; do
    case "$1" in
        --jobs) jobs="${2:?--jobs needs a number}"; shift 2 ;;
        --deadline) deadline="${2:?--deadline needs seconds}"; shift 2 ;;
        --scenes) scenes="${2:?--scenes needs a folder}"; shift 2 ;;
        --iterations) iterations="${2:?--iterations needs a number}"; shift 2 ;;
        --) shift; train_args=("$@"); break ;;
        -h|--help) usage ;;
        -*) echo "gates.sh: unknown option $1" >&2; usage ;;
        *) if [[ -z "$out" ]]; then out="$1"; else sets+=("$1"); fi; shift ;;
    esac
done
[[ -n "$out" && ${#sets[@]} -gt 0 ]] || usage
cocog="${COCOG:-$root/target/release/cocog}"
[[ -x "$cocog" ]] ||
    { echo "gates.sh: no cocog at $cocog; build it: cargo build --release -p cocog-cli" >&2; exit 1; }
for s in sharp-dev defocus-dev/dev-table defocus-dev/dev-shelf; do
    [[ -d "$scenes/$s/sparse" ]] || { echo "gates.sh: $scenes/$s: no COLMAP model (sparse/)" >&2; exit 1; }
done

# RUN = scene method downscale iterations [coc variant], e.g. "dev-table cocog 4 7000 paper".
runs=()
for set in "${sets[@]}"; do
    case "$set" in
        9-small) runs+=("sharp-dev 3dgs 4 7000" "dev-table 3dgs 4 7000") ;;
        9-full) runs+=("sharp-dev 3dgs 1 30000" "dev-table 3dgs 1 30000") ;;
        12-small) for s in dev-table dev-shelf; do runs+=("$s 3dgs 4 7000" "$s cocog 4 7000 paper"); done ;;
        12-full) for s in dev-table dev-shelf; do runs+=("$s 3dgs 1 30000" "$s cocog 1 30000 paper"); done ;;
        12-full-table | 12-full-shelf) s=dev-${set#12-full-}
            runs+=("$s 3dgs 1 30000" "$s cocog 1 30000 paper") ;;
        12-full-cocog-table | 12-full-cocog-shelf) runs+=("dev-${set#12-full-cocog-} cocog 1 30000 paper") ;;
        12-full-3dgs) runs+=("dev-table 3dgs 1 30000" "dev-shelf 3dgs 1 30000") ;;
        12-variants) for s in dev-table dev-shelf; do
            runs+=("$s cocog 4 7000 lens" "$s cocog 4 7000 code"); done ;;
        *) echo "gates.sh: unknown set $set" >&2; usage ;;
    esac
done

# Sets overlap (dev-table 3dgs is in #9's and #12's): each run once.
mapfile -t runs < <(printf '%s\n' "${runs[@]}" | awk '!seen[$0]++')

mkdir -p "$out"
summary="$out/summary.tsv"
[[ -f "$summary" ]] || printf 'run\titerations\ttrain_s\tgaussians\tpsnr\tssim_dn\tssim_g11\tlpips\tlast_drop\tfocus_err\n' >"$summary"
echo "gates: ${#runs[@]} runs with $("$cocog" --version 2>/dev/null || echo cocog) into $out" >&2

# Ingest each scene once, before runs start in parallel.
for run in "${runs[@]}"; do
    read -r scene _ <<<"$run"
    case "$scene" in sharp-dev) src="$scenes/sharp-dev" ;; *) src="$scenes/defocus-dev/$scene" ;; esac
    [[ -f "$out/.ingest-$scene/scene.json" ]] ||
        "$cocog" ingest colmap "$src" -o "$out/.ingest-$scene" -q --force >&2
done

one_run() {
    local scene method down its variant src name rc=0 limit=()
    read -r scene method down its variant <<<"$1"
    its="${iterations:-$its}"
    case "$scene" in sharp-dev) src="$scenes/sharp-dev" ;; *) src="$scenes/defocus-dev/$scene" ;; esac
    name="$scene-$method${variant:+-$variant}-d$down-$its"
    # Run again into the same OUT, a finished run is kept and a stopped one continues.
    [[ -f "$out/$name/metrics.json" ]] && return
    if [[ -n "$deadline" ]]; then
        local left=$((deadline - SECONDS))
        ((left > 0)) || { printf '%s\t%s\tnot started\n' "$name" "$its" | tee -a "$summary" >&2; return; }
        limit=(timeout --signal=INT --kill-after=60 "$left")
    fi
    local resume=()
    [[ -d "$out/$name.checkpoint" ]] && resume=(--resume "$out/$name.checkpoint")
    echo "gates: $name${resume[@]+ (continued)}" >&2
    # A run that fails (e.g. refused as too large for this adapter) gets a row and the rest go on.
    # No periodic checkpoints (a full-size run's is about 0.2 GB, read back and written every
    # 1000 iterations by default): the deadline's interrupt (SIGINT) still writes one.
    ${limit[@]+"${limit[@]}"} "$cocog" train "$out/.ingest-$scene" -o "$out/$name" --force -q \
        --method "$method" ${variant:+--coc-variant "$variant"} --downscale "$down" \
        --iterations "$its" --eval-every 500 --checkpoint-every 0 ${resume[@]+"${resume[@]}"} \
        ${train_args[@]+"${train_args[@]}"} \
        >"$out/$name.log" 2>&1 || rc=$?
    if ((rc == 124)) && [[ -f "$out/$name.train-log.jsonl" ]]; then
        python3 "$root/bench/gates_row.py" "$out/$name.train-log.jsonl" "$name" "$its" stopped \
            >>"$summary" || printf '%s\t%s\tstopped, unreadable log\n' "$name" "$its" >>"$summary"
    elif ((rc != 0)) ||
        ! "$cocog" eval "$out/$name" --downscale "$down" -q >/dev/null 2>>"$out/$name.log"; then
        printf '%s\t%s\tfailed\n' "$name" "$its" >>"$summary"
    else
        if [[ "$method" == cocog ]]; then
            "$cocog" lens "$out/$name" --truth "$src/transforms.json" --json >"$out/$name/lens.json" ||
                rm -f "$out/$name/lens.json"
        fi
        python3 "$root/bench/gates_row.py" "$out/$name" "$name" "$its" >>"$summary" ||
            printf '%s\t%s\tfinished, unscored\n' "$name" "$its" >>"$summary"
    fi
    grep -F "$name	" "$summary" | tail -1 >&2
}

for run in "${runs[@]}"; do
    while (($(jobs -rp | wc -l) >= jobs)); do wait -n || true; done
    one_run "$run" &
done
wait
# A continued run has a row per call: keep each run's last.
awk -F'\t' '{ if (!($1 in row)) order[++n] = $1; row[$1] = $0 }
    END { for (i = 1; i <= n; i++) print row[order[i]] }' "$summary" >"$summary.tmp" &&
    mv "$summary.tmp" "$summary"
column -t -s $'\t' "$summary" >&2 2>/dev/null || cat "$summary" >&2
