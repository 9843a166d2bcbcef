#!/usr/bin/env bash
# Benchmarks cocog on one defocus dataset in the Deblur-NeRF layout (images/, poses_bounds.npy,
# optional hold=N marker) and appends a row per method to BENCHMARKS.md.
#
#   bench/defocus.sh DATASET [--label TEXT] [--work DIR] [--no-append] [-- TRAIN_ARGS...]
#
# - When this cocog has the ingest-llff, train and render stages: ingest → train → render the test
#   views → eval against the sharp test images. TRAIN_ARGS go to `cocog train`.
# - Otherwise (and always, as the reference to beat): the do-nothing baseline, each test view
#   scored against the blurred train view nearest in pose (bench/nearest_views.py).
# - If DATASET/baseline/ exists (the synthetic bench scenes), it is scored too: each test pose
#   rendered with the scene lens at the median train focus.
#
# cocog is $COCOG, else target/release/cocog, else target/debug/cocog. Needs python3 + numpy.
# Scores come from `cocog eval` (PSNR, SSIM in both conventions, LPIPS-Alex when its weights are
# installed: scripts/lpips/fetch-weights.sh). Work files go to --work (default: a temp folder,
# removed at exit).
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
usage() { sed -n '2,16p' "${BASH_SOURCE[0]}" >&2; exit 2; }

dataset="" label="" work="" append=1 train_args=()
while [[ $# -gt 0 ]]; do
    case "$1" in
        --label) label="${2:?--label needs a value}"; shift 2 ;;
        --work) work="${2:?--work needs a folder}"; shift 2 ;;
        --no-append) append=0; shift ;;
        --) shift; train_args=("$@"); break ;;
        -h|--help) usage ;;
        -*) echo "defocus.sh: unknown option $1" >&2; usage ;;
        *) [[ -z "$dataset" ]] || usage; dataset="$1"; shift ;;
    esac
done
[[ -n "$dataset" ]] || usage
[[ -d "$dataset/images" ]] || { echo "defocus.sh: $dataset/images: not a folder" >&2; exit 1; }
dataset="$(cd "$dataset" && pwd)"

cocog="${COCOG:-}"
if [[ -z "$cocog" ]]; then
    for c in "$root/target/release/cocog" "$root/target/debug/cocog"; do
        [[ -x "$c" ]] && { cocog="$c"; break; }
    done
fi
[[ -n "$cocog" && -x "$cocog" ]] ||
    { echo "defocus.sh: no cocog binary; build it: cargo build --release -p cocog-cli" >&2; exit 1; }

if [[ -z "$work" ]]; then
    work="$(mktemp -d)"
    trap 'rm -rf "$work"' EXIT
fi
mkdir -p "$work"

stages="$("$cocog" plugins --json |
    python3 -c 'import json,sys; print(" ".join(s["stage"] for s in json.load(sys.stdin)["stages"]))')"
has() { [[ " $stages " == *" $1 "* ]]; }
has eval || { echo "defocus.sh: $cocog has no eval stage" >&2; exit 1; }

commit="$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)"
machine="$(nproc) cores ($(basename "$(dirname "$cocog")") build)"
now() { date +%s%N; }
# secs T0: seconds since the nanosecond timestamp T0, two decimals.
secs() { local ms=$((($(now) - $1) / 1000000)); printf '%d.%02d' $((ms / 1000)) $((ms % 1000 / 10)); }

# score METHOD PRED_DIR PIPELINE_SECONDS: runs cocog eval, prints the row, appends it.
score() {
    local method="$1" pred="$2" pipeline_s="$3" out="$work/metrics-$RANDOM.json" t0 eval_s row
    t0="$(now)"
    "$cocog" eval --pred "$pred" --gt "$dataset/images" -o "$out" >/dev/null
    eval_s="$(secs "$t0")"
    row="$(python3 - "$out" "$method" "$pipeline_s" "$eval_s" \
        "$(basename "$dataset")" "$commit" "$machine" "$label" <<'EOF'
import datetime, json, sys
out, method, pipe_s, eval_s, dataset, commit, machine, label = sys.argv[1:]
r = json.load(open(out))
m = r["mean"]
fmt = lambda k, p: "n/a" if m.get(k) is None else f"{m[k]:.{p}f}"
print(json.dumps([
    datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d"), commit, dataset, method,
    str(r["count"]), fmt("psnr", 2), fmt("ssim_deblurnerf", 4), fmt("ssim_gaussian11", 4),
    fmt("lpips_alex", 4), pipe_s, eval_s, machine, label or "-",
]))
EOF
    )"
    echo "$row"
    if [[ $append -eq 1 ]]; then
        python3 "$root/bench/append_row.py" "$root/BENCHMARKS.md" \
            "Defocus deblurring (bench/defocus.sh)" \
            '["date","commit","dataset","method","test views","PSNR","SSIM (Deblur-NeRF)","SSIM (Gaussian-11)","LPIPS-Alex","pipeline s","eval s","machine","notes"]' \
            "$row"
    fi
}

if has ingest-llff && has train && has render; then
    t0="$(now)"
    "$cocog" ingest llff "$dataset" -o "$work/scene" >/dev/null
    "$cocog" train "$work/scene" -o "$work/trained" "${train_args[@]}" >/dev/null
    "$cocog" render "$work/trained" -o "$work/renders" --split test >/dev/null
    pipeline_s="$(secs "$t0")"
    score "cocog train ${train_args[*]:-(defaults: cocog, paper)}" "$work/renders" "$pipeline_s"
else
    echo "defocus.sh: no ingest-llff/train/render stages yet: scoring baselines only" >&2
fi

python3 "$root/bench/nearest_views.py" "$dataset" "$work/nearest" >&2
score "do-nothing: nearest blurred train view" "$work/nearest" "-"

if [[ -d "$dataset/baseline" ]]; then
    score "do-nothing: baseline/ (median-focus render)" "$dataset/baseline" "-"
fi
