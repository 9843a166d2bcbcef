#!/usr/bin/env bash
# What a short GPU lease is for, as bounded phases of one command (../shared/notes/gpu-device.md):
#
#   bench/gpu-session.sh RESULTS [PHASE...]  (default: tests peer-train step)
#
# A 15-minute lease holds the machine's start (about 40 s on 2026-11-27) and about 800 s of
# calls; a machine left idle for 30 s is gone. Measured on an H200 (2026-11-27): tests about 90 s
# (nn_compositor alone 36 s), step 45 s before its raster-block and split-list rows were added
# (about 105 s now, an estimate), peer-synthetic 85 s (65 of them gsplat's CUDA build),
# peer-train 250 s with gsplat built (plus five benches of at most 20 s after the peer now).
# gsplat's build runs in the background during an untimed phase (tests, gates) when a peer phase
# follows it, so the default order puts tests first; tests stop starting executables when the
# later phases would no longer fit (each phase's need: need_of). The default phases fit one call
# of BUDGET=540. A second call made at once fits train-split and layouts (`BUDGET=250 ...
# train-split layouts`), or `ab` where the kit carries an older build; peer-synthetic (#11's 1M-Gaussian figure, met on 2026-11-27) only where
# the lease has room left.
#
# BUDGET (seconds, default 560) bounds the whole call: a phase that would not fit what is left is
# skipped and says so in RESULTS/session.txt, and every command's timeout is cut to what is
# left. From DEV (default .device, made on the development machine by bench/device-kit.sh: the stripped `cocog` and
# `gemm-bench`, each possibly xz-compressed as NAME.xz; bench/ with sharp-dev and
# defocus-dev/dev-table and dev-shelf (no depth/ or baseline/; everything carried must stay under 64 MiB);
# lpips/, the gsplat-1.5.3 wheel, tests.tar.xz of stripped GPU test executables from `cargo
# test --no-run`):
#   step            #12's step ratio: a 5000-iteration 3dgs run on dev-table at 100×75 gives the
#                   Gaussians, then `cocog bench --resume` times a 3dgs step and a cocog step
#                   (the default variant, F on) on them, each also with its kernels compiled
#                   without naga's run-time guards (COCOG_SHADER_CHECKS=0, here and at
#                   400×300), the cocog step with F's convolutions as
#                   implicit GEMMs (COCOG_F_CONV=gemm), as tiled kernels (COCOG_F_CONV=tiled)
#                   and with its 3×3 layers by Winograd (the default), that with the first
#                   layer's forward as an implicit GEMM (COCOG_F_FIRST=gemm; a GPU's default
#                   runs it by its own kernel), and with F's maps
#                   in f32 (COCOG_NO_F16=1) as well as f16, with the per-kernel split
#                   (--kernels), and on tensor cores (COCOG_F_CONV=coop, f16 operands,
#                   experimental), and both steps compositing in 8×8 blocks on both sides
#                   (COCOG_RASTER_BLOCK=8), in 16×16 tiles on both sides (=16; by default
#                   the forward takes 8×8 blocks below 2048 tiles, the backward tiles) or with the backward's tile
#                   lists whole (COCOG_RASTER_SPLIT=1; a GPU's default splits them), or
#                   testing every tile of each Gaussian's rectangle (COCOG_TILE_SPANS=0; a
#                   GPU's default takes its wide rows as spans); then at 400×300 on the same
#                   Gaussians the 3dgs step (each of those settings, and 4 chunks) and the cocog
#                   step (what a step of #12's full-size gate costs), F on the f32 products, by
#                   Winograd with either first layer and on tensor cores in the default block
#                   layout                                  ~50 s on an H100 (2026-11-28)
#   layouts         the cocog step at 400×300 with F on tensor cores in each other block layout
#                   (COCOG_COOP_BLOCK: wider blocks, deeper slices, prefetching, skewed rows)
#                   on step's Gaussians (trained first where step has not run on the machine);
#                   then, where DEV has gemm-bench (`cargo bench --bench gemm --no-run`,
#                   stripped), F's 3×3 layer as a plain GEMM at 100×75 and 400×300 on the f32
#                   tiled product and on tensor cores in every layout
#                   (COCOG_COOPERATIVE_MATRIX=1)               ~100 s (an estimate; +15 s training)
#   peer-synthetic  #11: `cocog bench --synthetic 1000000 --size 1920x1080` (and with --zoom 3,
#                   most Gaussians culled, per kernel), then gsplat on the same Gaussians and
#                   cameras (peer_gsplat.py workload)                             ~20 s + gsplat build (65 s)
#   peer-train      #11: sharp-dev at 400×300, 30000 iterations: `cocog train --method 3dgs`
#                   (timed without evaluations or checkpoints) and `cocog eval`, then gsplat on
#                   the same views (peer_gsplat.py train), then the 3dgs step at the run's end
#                   in each compositing setting                                    ~265 s + gsplat build
#   peer-quality    #11's PSNR over seeds: SEEDS (default "1 2 3") trainings of peer-train's
#                   protocol on each side, at once (bench/peer_quality.py's table: each run,
#                   each side's mean and spread, the difference and its standard error); as
#                   many seeds as the budget fits, the rest on a later call
#                                 ~240 s for one seed, +130 per seed (estimates) + gsplat build
#   train-split     peer-train's cocog run with the backward's tile lists split
#                   (COCOG_RASTER_SPLIT, default auto), then `cocog eval`           ~80 s
#   idle-bench      `cocog bench` rows of sharp-dev at 100×75 and 1M random Gaussians at 1080p
#   ab              where DEV has another build (cocog-old, packed by device-kit.sh's
#                   OLD_COCOG; cocog-old.txt names it): the 3dgs and cocog steps at 100×75 and
#                   400×300 on step's Gaussians (and the 3dgs step on peer-train's sharp-dev
#                   model where that ran here), each build in turn, twice, every switch at its
#                   default, with the per-kernel split: an A/B of two builds on one machine
#                                                                               ~100 s (an estimate)
#   tests           the GPU test executables (f64 references, finite differences)      ~90 s
#                   (TESTS="NAME ..." runs only those; gpu_coop_gemm alone takes seconds)
#   gates SET...    bench/gates.sh's quality runs at once (--jobs 12), interrupted where they would
#                   outrun the budget; the same command again continues them (e.g. `gates
#                   12-small 12-variants`; a phase word ends the list). With GATE_ARGS="..."
#                   every training also gets those options, in runs of their own named after
#                   them (g-add-points-frame-colmap/, gates-add-points-frame-colmap.tgz)
# #12's full-size gate, one cocog run per lease, alone on the GPU: `BUDGET=580
# bench/gpu-session.sh RESULTS gates 12-full-cocog-table`, then at once the same line again
# (BUDGET=what is left) to continue the stopped run from its checkpoint on the still-warm
# machine; `gates 12-full-cocog-shelf` on another lease, and `gates 12-full-3dgs` (both scenes'
# 3dgs runs, about a minute each) beside other work. It may not fit: the cocog step at 400×300
# took 16.4 ms on an H100 at 56,739 Gaussians (2026-11-28), F 11.9 ms of it whatever the count,
# h_θ, the projections and sorts growing with it, the compositing with the tiles each Gaussian
# covers; at the 150–350k Gaussians a full-size run may reach, about 21–32 ms a step once F
# starts (6000) and 9–14 minutes for the run (BENCHMARKS.md, session 43; an estimate), against
# the about 830 s of calls a 15-minute lease leaves. A run stopped by the deadline reports its
# last scored iteration; its checkpoint (0.1–0.25 GB) cannot come back from the machine (8
# files of 16 MiB a call), so a later lease starts it again.
# gsplat's CUDA code builds once per machine (60–80 s on 16 cores; in the background where an
# untimed phase comes first); later calls on the same warm machine reuse it. A phase that finished leaves a marker in WORK, so a second call
# on the same machine goes on with the phases the first did not finish. RESULTS gets session.txt (every
# phase's output), tests.log, gates.tgz and the peers' result files.
set -uo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
results="${1:?usage: bench/gpu-session.sh RESULTS [PHASE...]}"
shift
phases=("$@")
((${#phases[@]})) || phases=(tests peer-train step)
budget="${BUDGET:-560}"
dev="${DEV:-$root/.device}"
work="${WORK:-/tmp/gpu-session}"
mkdir -p "$work"
# Executables may travel xz-compressed (DEV/NAME.xz), as everything carried shares 64 MiB.
# Unpacked on every call: a warm machine keeps WORK, and a later call may carry a rebuilt one.
for exe in cocog gemm-bench cocog-old; do
    if [[ -f "$dev/$exe.xz" ]]; then
        xz -dc "$dev/$exe.xz" >"$work/$exe.new" && chmod +x "$work/$exe.new" &&
            mv -f "$work/$exe.new" "$work/$exe"
    elif [[ -x "$dev/$exe" ]]; then
        ln -sf "$dev/$exe" "$work/$exe"
    fi
done
cocog="$work/cocog"
export COCOG="$cocog" COCOG_LPIPS_WEIGHTS="$dev/lpips"
mkdir -p "$results" "$work"
log="$results/session.txt"
left() { echo $((budget - SECONDS)); }
# `timeout` for at most $1 seconds and never past the budget (10 s kept for the rest).
bounded() {
    local most=$1
    shift
    local t=$(($(left) - 10))
    ((t > most)) && t=$most
    ((t < 1)) && t=1
    timeout "$t" "$@"
}
section() { printf '\n== %s (at %d s)\n' "$*" "$SECONDS" >>"$log"; }
# Runs phase $1 (phase_$1 with - as _) unless it finished on this machine or fewer than $2
# seconds are left.
run_phase() {
    [[ -f "$work/done-$1" ]] && return
    if (($(left) < $2)); then
        section "$1 skipped: $(left) s left, it needs about $2"
        return
    fi
    section "$1"
    # Only tests run beside gsplat's background build; what is timed waits for it (its
    # need counts what the build still has to go).
    [[ "$1" == tests ]] || wait_gsplat_build "$(need_of "$1" 0)"
    "phase_${1//-/_}" && touch "$work/done-$1"
}

for s in sharp-dev defocus-dev/dev-table; do
    n="$work/in-$(basename "$s")"
    [[ -f "$n/scene.json" ]] || "$cocog" ingest colmap "$dev/bench/$s" -o "$n" -q --force
done

gsplat_installed() {
    if [[ ! -d /tmp/site/gsplat ]]; then
        python3 -m pip install -q --no-index --no-deps --target /tmp/site \
            "$dev"/gsplat-1.5.3-py3-none-any.whl >>"$log" 2>&1 || return 1
    fi
    export PYTHONPATH=/tmp/site TORCH_CUDA_ARCH_LIST="${TORCH_CUDA_ARCH_LIST:-9.0}"
}

# gsplat compiles its CUDA code on first import (60–80 s of CPU, the GPU idle). Where the tests
# phase runs before a peer phase, the build starts in the background as tests begin, niced and
# on 12 of the 16 cores, so it overlaps them instead of adding to the lease. Every other phase
# waits for it first (run_phase): what is timed must not share the CPU with it, and gsplat
# deletes a half-built extension when a second process imports it. The call does not end with
# the build running (the EXIT trap stops it), so a later call never finds one half done.
gsplat_build_pid=
gsplat_build_started=0
start_gsplat_build() {
    [[ -z "$gsplat_build_pid" && ! -f "$work/gsplat-built" ]] && gsplat_installed || return 0
    # exec: $! is timeout's, which passes a TERM on to the compilers (its process group).
    (cd /tmp && exec env MAX_JOBS=12 nice -n 19 timeout 400 python3 -c \
        "from gsplat.cuda._backend import _C; assert _C is not None, 'no CUDA toolkit'") \
        >"$results/gsplat-build.log" 2>&1 </dev/null &
    gsplat_build_pid=$!
    gsplat_build_started=$SECONDS
    echo "-- gsplat's CUDA build started in the background" >>"$log"
}
stop_gsplat_build() {
    if [[ "$gsplat_build_pid" =~ ^[0-9]+$ ]]; then
        kill "$gsplat_build_pid" 2>/dev/null
        wait "$gsplat_build_pid" 2>/dev/null
        echo "-- gsplat's background build stopped unfinished at the call's end" >>"$log"
    fi
}
trap stop_gsplat_build EXIT
# Waits for the background build, but stops it where it would leave fewer than $1 seconds.
wait_gsplat_build() {
    if [[ "$gsplat_build_pid" =~ ^[0-9]+$ ]]; then
        local t0=$SECONDS rc=0 keep=${1:-0}
        while kill -0 "$gsplat_build_pid" 2>/dev/null && (($(left) > keep)); do
            sleep 1
        done
        kill -0 "$gsplat_build_pid" 2>/dev/null && kill "$gsplat_build_pid"
        wait "$gsplat_build_pid" || rc=$?
        echo "-- waited $((SECONDS - t0)) s for gsplat's background build (exit $rc)" >>"$log"
        ((rc == 0)) && touch "$work/gsplat-built"
        gsplat_build_pid=done
    fi
}
gsplat_ready() {
    wait_gsplat_build
    gsplat_installed && export MAX_JOBS="${MAX_JOBS:-16}"
}
# After a gsplat run: its first import built the extension where no background build had.
gsplat_ran() {
    local rc=$1
    ((rc == 0)) && touch "$work/gsplat-built"
    return "$rc"
}

# The Gaussians step and layouts bench on: a 5000-iteration 3dgs run on dev-table at 100×75,
# trained once per machine (a later call reuses it, and says so). Fails without a model.
step_model() {
    local model="$work/step-model"
    if [[ -f "$model/gaussians.ply" ]]; then
        echo "-- reusing the step model trained earlier on this machine" >>"$log"
    else
        bounded 120 "$cocog" train "$work/in-dev-table" -o "$model" --downscale 4 \
            --method 3dgs --iterations 5000 --checkpoint-every 0 -q --force >>"$log" 2>&1
    fi
    if [[ ! -f "$model/gaussians.ply" ]]; then
        echo "-- the step model did not train: no benches on it" >>"$log"
        return 1
    fi
    echo "$model"
}

# `env` without the caller's code-path switches: each bench row sets its own.
clean_env=(env -u COCOG_F_CONV -u COCOG_NO_F16 -u COCOG_COOPERATIVE_MATRIX -u COCOG_COOP_BLOCK
    -u COCOG_RASTER_BLOCK -u COCOG_RASTER_SPLIT -u COCOG_F_FIRST -u COCOG_TILE_SPANS
    -u COCOG_SHADER_CHECKS)

phase_step() {
    local model
    model=$(step_model) || return 1
    local m vars
    for m in 3dgs 3dgs-unchecked cocog-winograd cocog-unchecked cocog cocog-tiled cocog-fgemm cocog-f32 cocog-coop 3dgs-b8 cocog-b8 3dgs-b16 cocog-b16 3dgs-whole cocog-whole 3dgs-scan cocog-scan; do
        echo "-- $m step on the model's Gaussians" >>"$log"
        vars=(COCOG_F_CONV=gemm)  # the rows named cocog-winograd time the default
        [[ $m == *-tiled ]] && vars=(COCOG_F_CONV=tiled)
        [[ $m == *-winograd ]] && vars=(COCOG_F_CONV=winograd)
        # The default's first layer forward as an implicit GEMM (a GPU's default: its own kernel).
        [[ $m == *-fgemm ]] && vars=(COCOG_F_CONV=winograd COCOG_F_FIRST=gemm)
        [[ $m == *-coop ]] && vars=(COCOG_F_CONV=coop COCOG_COOPERATIVE_MATRIX=1)
        [[ $m == *-f32 ]] && vars+=(COCOG_NO_F16=1)
        # Compositing in 8×8 blocks of a tile, the backward too (the default forward's on
        # frames of few tiles), or in whole 16×16 tiles, the forward too (the default backward's).
        [[ $m == *-b8 ]] && vars+=(COCOG_RASTER_BLOCK=8)
        [[ $m == *-b16 ]] && vars+=(COCOG_RASTER_BLOCK=16)
        # The compositing backward walking each tile's list whole (a GPU's default splits them).
        [[ $m == *-whole ]] && vars+=(COCOG_RASTER_SPLIT=1)
        # Every tile of each Gaussian's rectangle tested (a GPU's default takes wide rows as
        # spans).
        [[ $m == *-scan ]] && vars+=(COCOG_TILE_SPANS=0)
        # The defaults with the kernels compiled without naga's run-time guards (loop caps,
        # index clamps, division guards): wgpu issue 7698 saw its
        # loop caps take a kernel from 0.1 to 10 ms; lavapipe showed no difference.
        [[ $m == cocog-unchecked ]] && vars=(COCOG_F_CONV=winograd)
        [[ $m == *-unchecked ]] && vars+=(COCOG_SHADER_CHECKS=0)
        bounded 60 "${clean_env[@]}" "${vars[@]}" "$cocog" bench "$work/in-dev-table" --downscale 4 \
            --resume "$model" --method "${m%%-*}" --iterations 100 --warmup 10 --kernels \
            >>"$log" 2>&1
    done
    # The same Gaussians at full size (400×300): what a step of #12's full-size gate costs,
    # against the 3dgs step there, with F on the f32 products and on tensor cores (the default
    # layout; the layouts phase times the others).
    local c
    for c in "${raster_settings[@]}"; do
        echo "-- 3dgs step at 400×300 on the model's Gaussians, $c" >>"$log"
        bounded 60 "${clean_env[@]}" $c "$cocog" bench "$work/in-dev-table" --downscale 1 \
            --resume "$model" --method 3dgs --iterations 100 --warmup 10 --kernels >>"$log" 2>&1
    done
    cocog_full_size "$model" winograd-direct:4x4 winograd-direct-unchecked:4x4 gemm:4x4 \
        winograd:4x4 coop:4x4
}

# The cocog step at 400×300 on model $1 with F as each of $2...: gemm:4x4 (the f32 products),
# winograd:4x4 (its 3×3 layers by Winograd), winograd-direct:4x4 (and the first layer's forward
# by its own kernel) or coop:LAYOUT (tensor cores in that CoopBlock layout), with the per-kernel
# split; by $COCOG_FULL_SIZE where set (another build, for an A/B
# on one machine).
cocog_full_size() {
    local model=$1 m
    shift
    for m in "$@"; do
        local conv=${m%%:*} first=gemm checks=1
        [[ $conv == *-unchecked ]] && conv=${conv%-unchecked} checks=0
        [[ $conv == *-direct ]] && conv=${conv%-direct} first=direct
        echo "-- cocog step at 400×300 on the model's Gaussians, COCOG_F_CONV=$conv COCOG_F_FIRST=$first COCOG_SHADER_CHECKS=$checks$([[ $m == coop* ]] && echo " block ${m#*:}")" >>"$log"
        bounded 60 "${clean_env[@]}" COCOG_F_CONV=$conv COCOG_F_FIRST=$first COCOG_SHADER_CHECKS=$checks COCOG_COOP_BLOCK=${m#*:} \
            COCOG_COOPERATIVE_MATRIX=$([[ $m == coop* ]] && echo 1 || echo 0) \
            "${COCOG_FULL_SIZE:-$cocog}" bench "$work/in-dev-table" --downscale 1 --resume "$model" \
            --method cocog --iterations 30 --warmup 5 --kernels >>"$log" 2>&1
    done
}

# F on tensor cores in the other block layouts (CoopBlock::NAMED), in the full-size step and,
# where DEV has gemm-bench, as a bare GEMM at 100×75 and 400×300.
phase_layouts() {
    local model
    model=$(step_model) || return 1
    cocog_full_size "$model" coop:4x8 coop:4x16 coop:4x8k4 coop:8x8 coop:4x4p coop:4x8p \
        coop:4x4s coop:4x8s coop:4x4ps coop:4x8ps
    if [[ -x "$work/gemm-bench" ]]; then
        local px
        for px in 45056 720000; do
            echo "-- F's 3×3 layer as a GEMM, $px pixels (f32 tiled vs cooperative matrices)" >>"$log"
            COCOG_COOPERATIVE_MATRIX=1 COCOG_BENCH_PIXELS=$px bounded 30 "$work/gemm-bench" \
                >>"$log" 2>&1
        done
    fi
}

phase_peer_synthetic() {
    bounded 120 "$cocog" bench --synthetic 1000000 --size 1920x1080 --iterations 20 --warmup 5 \
        --write-workload "$work/workload" >>"$log" 2>&1
    # The visible-only depth sort where most Gaussians are culled (about a third in frame).
    bounded 60 "$cocog" bench --synthetic 1000000 --size 1920x1080 --zoom 3 --iterations 20 \
        --warmup 5 --kernels >>"$log" 2>&1
    gsplat_ready && bounded 300 python3 "$root/bench/peer_gsplat.py" workload "$work/workload" \
        --out "$results/gsplat-synthetic.json" --iterations 20 --warmup 5 >>"$log" 2>&1
    gsplat_ran $?
}

# The settings the 3dgs benches compare: every default with naga's run-time guards and without
# them (COCOG_SHADER_CHECKS, the two next to each other), whole tile lists in the backward, 8×8 blocks
# on both sides, 16×16 tiles on both sides (by default the forward takes 8×8 blocks below 2048
# tiles), tile lists split (as many chunks as RasterSplit::Auto picks, a GPU's default, and 4),
# and the projection and key emission testing every tile of a rectangle (a GPU's default takes
# its wide rows as spans).
raster_settings=("COCOG_SHADER_CHECKS=1" "COCOG_SHADER_CHECKS=0" "COCOG_RASTER_SPLIT=1"
    "COCOG_RASTER_BLOCK=8" "COCOG_RASTER_BLOCK=16" "COCOG_RASTER_SPLIT=auto" "COCOG_RASTER_SPLIT=4"
    "COCOG_TILE_SPANS=0")

# cocog's side of peer-train: sharp-dev at 400×300, 30000 iterations of 3dgs, timed, then scored.
train_sharp_dev() {
    local out=$1 t0=$SECONDS
    bounded 400 "$cocog" train "$work/in-sharp-dev" -o "$out" --method 3dgs --iterations 30000 \
        --checkpoint-every 0 --force >>"$log" 2>&1
    echo "cocog train: $((SECONDS - t0)) s wall" >>"$log"
    bounded 60 "$cocog" eval "$out" >>"$log" 2>&1
}

phase_peer_train() {
    local out="$work/peer-cocog-sharp-dev"
    train_sharp_dev "$out"
    gsplat_ready && bounded 600 python3 "$root/bench/peer_gsplat.py" train "$work/in-sharp-dev" \
        --out "$results/gsplat-sharp-dev" --iterations 30000 >>"$log" 2>&1
    gsplat_ran $?
    rm -f "$results"/gsplat-sharp-dev/renders/*.png
    # After the peer, which the phase is for: the 3dgs step at the run's end in each
    # compositing setting.
    local c
    for c in "${raster_settings[@]}"; do
        echo "-- 3dgs step on the trained model, $c" >>"$log"
        bounded 20 "${clean_env[@]}" $c "$cocog" bench "$work/in-sharp-dev" --resume "$out" \
            --method 3dgs --iterations 200 --warmup 20 --kernels >>"$log" 2>&1
    done
}

# #11's "equal or better test PSNR" over seeds rather than one pair: SEEDS (default "1 2 3")
# trainings of peer-train's protocol on each side, at once on the GPU (their times share it, so
# they are no speed figures; peer-train times one pair alone), then bench/peer_quality.py's
# table: each run's PSNR, each side's mean and spread, the difference with its standard error.
# A training cut by the budget leaves nothing to score, so only the seeds that fit what is left
# start (seed_wave_s each beyond the first's seed_first_s: estimates from one H100 pair, cocog
# 57 s and gsplat 185 s alone, gsplat's Python-bound steps leaving the GPU room); a later call
# on the machine runs the rest, and the table covers every finished seed.
seed_first_s=240
seed_wave_s=130
# Whether seed $1 was scored on both sides in $2.
seed_done() {
    [[ -f "$2/cocog-$1/metrics.json" && -f "$2/gsplat-$1/result.json" ]]
}
phase_peer_quality() {
    local q="$work/quality" s todo=() fit i
    mkdir -p "$q"
    gsplat_ready || return 1
    # Concurrent imports of an unbuilt extension would each start its build (and delete one
    # another's), so it is built first where no earlier phase built it.
    if [[ ! -f "$work/gsplat-built" ]]; then
        (cd /tmp && bounded 200 python3 -c \
            "from gsplat.cuda._backend import _C; assert _C is not None, 'no CUDA toolkit'") \
            >>"$log" 2>&1 && touch "$work/gsplat-built" || return 1
    fi
    for s in ${SEEDS:-1 2 3}; do
        seed_done "$s" "$q" || todo+=("$s")
    done
    local room=$(($(left) - 10 - seed_first_s))
    fit=$((room < 0 ? 0 : room / seed_wave_s + 1))
    ((fit > ${#todo[@]})) && fit=${#todo[@]}
    if ((fit < ${#todo[@]})); then
        echo "-- peer-quality: $(left) s left, time for ${fit} of the ${#todo[@]} seeds to go; a later call runs the rest" >>"$log"
        ((fit == 0)) && return 1
    fi
    # Not "${todo[@]:0:fit}": bash before 4.4 calls an empty array unbound under set -u.
    for ((i = 0; i < fit; i++)); do
        s=${todo[i]}
        [[ -f "$q/cocog-$s/metrics.json" ]] ||
            { bounded 500 "$cocog" train "$work/in-sharp-dev" -o "$q/cocog-$s" --method 3dgs \
                --iterations 30000 --checkpoint-every 0 --seed "$s" --force -q &&
                bounded 60 "$cocog" eval "$q/cocog-$s" -q; } >"$q/cocog-$s.log" 2>&1 &
        [[ -f "$q/gsplat-$s/result.json" ]] ||
            bounded 500 python3 "$root/bench/peer_gsplat.py" train "$work/in-sharp-dev" \
                --out "$q/gsplat-$s" --iterations 30000 --seed "$s" >"$q/gsplat-$s.log" 2>&1 &
    done
    wait
    rm -rf "$q"/gsplat-*/renders
    # Into session.txt: at most 8 files come back from a call.
    tail -n 3 "$q"/*.log >>"$log" 2>&1
    python3 "$root/bench/peer_quality.py" "$q" >>"$log"
    # Done (the marker) only when every seed was scored on both sides.
    for s in ${SEEDS:-1 2 3}; do
        seed_done "$s" "$q" || return 1
    done
}

# peer-train's cocog run again with the backward's tile lists split as COCOG_RASTER_SPLIT says
# (auto unless set, which is a GPU's default now: set 1 to time whole lists); gsplat's side is
# peer-train's.
phase_train_split() {
    COCOG_RASTER_SPLIT="${COCOG_RASTER_SPLIT:-auto}" train_sharp_dev "$work/split-sharp-dev"
}

# Each build in turn, twice, on one machine: the defaults of two builds compared.
phase_ab() {
    if [[ ! -x "$work/cocog-old" ]]; then
        echo "-- no cocog-old in $dev: nothing to compare with" >>"$log"
        return 0
    fi
    local model
    model=$(step_model) || return 1
    echo "-- cocog-old is $(cat "$dev/cocog-old.txt" 2>/dev/null || echo 'an unnamed build')" >>"$log"
    local round build row method down iters warm
    for round in 1 2; do
        for build in cocog-old cocog; do
            for row in "3dgs 4 100 10" "cocog 4 100 10" "3dgs 1 100 10" "cocog 1 20 5"; do
                read -r method down iters warm <<<"$row"
                echo "-- ab round $round, $build: $method step at --downscale $down" >>"$log"
                bounded 60 "${clean_env[@]}" "$work/$build" bench "$work/in-dev-table" \
                    --downscale "$down" --resume "$model" --method "$method" \
                    --iterations "$iters" --warmup "$warm" --kernels >>"$log" 2>&1
            done
            # #11's step: sharp-dev's model where peer-train trained it on this machine.
            local sd="$work/peer-cocog-sharp-dev"
            if [[ -f "$sd/gaussians.ply" ]]; then
                echo "-- ab round $round, $build: 3dgs step on peer-train's sharp-dev model" >>"$log"
                bounded 30 "${clean_env[@]}" "$work/$build" bench "$work/in-sharp-dev" --resume "$sd" \
                    --method 3dgs --iterations 200 --warmup 20 --kernels >>"$log" 2>&1
            fi
        done
    done
}

phase_idle_bench() {
    bounded 90 "$cocog" bench "$work/in-sharp-dev" --downscale 4 --iterations 300 --warmup 30 \
        >>"$log" 2>&1
    bounded 120 "$cocog" bench --synthetic 1000000 --size 1920x1080 --iterations 20 --warmup 5 \
        >>"$log" 2>&1
}

# Executables run here (a later call on the machine runs only the others), and whether the
# phase stopped short of the rest.
phase_tests() {
    [[ -d "$work/tests" ]] || { mkdir -p "$work/tests" && tar xJf "$dev/tests.tar.xz" -C "$work"; } ||
        return 1
    local t name leave most rc cut=0
    for t in "$work"/tests/*; do
        name=$(basename "$t")
        # TESTS="gpu_coop_gemm nn_compositor" runs those alone (default: every one).
        [[ -z "${TESTS:-}" || " $TESTS " == *" $name "* ]] || continue
        [[ -f "$work/tested-$name" ]] && continue
        # The phases after this one keep what they need (less as gsplat's build gets on).
        leave=$(needs_after "$tests_next")
        most=$(($(left) - leave - 10))
        if ((most < 20)); then
            echo "== $name and the rest not run: $(left) s left, $leave kept for the later phases"
            cut=1
            break
        fi
        ((most > 150)) && most=150
        echo "== $name"
        # The cooperative-matrix product's own test enables the experimental feature; no
        # other test does, so they test what training runs.
        local coop=0
        [[ $name == gpu_coop_gemm ]] && coop=1
        CI=true COCOG_COOPERATIVE_MATRIX=$coop bounded "$most" "$t" --test-threads 2 --nocapture 2>&1 |
            grep -E "^test |test result|panicked|FAILED|assert|skipped"
        rc=${PIPESTATUS[0]}
        ((rc == 0)) || echo "== $name exited with $rc$( ((rc == 124)) && echo ' (stopped by the budget)')"
        touch "$work/tested-$name"
    done >>"$results/tests.log" 2>&1
    # Stopped short: no done marker, so a later call runs the rest.
    ((cut == 0))
}

phase_gates() {
    # GATE_ARGS (e.g. "--add-points-frame colmap") go to every training, in runs of their own
    # named after them (g-add-points-frame-colmap/, gates-add-points-frame-colmap.tgz,
    # summary-add-points-frame-colmap.tsv), so the defaults' runs and another call's options
    # stay apart: a second call with other options does not find the first's runs finished.
    local g=g extra=()
    if [[ -n "${GATE_ARGS:-}" ]]; then
        g=g-$(printf '%s' "$GATE_ARGS" | tr -cs 'A-Za-z0-9.' '-' | sed 's/^-*//; s/-*$//')
        read -ra extra <<<"$GATE_ARGS"
        extra=(-- ${extra[@]+"${extra[@]}"})
    fi
    # Trainings stop 60 s before the end, for their evaluations and the archive.
    "$root/bench/gates.sh" "$work/$g" "$@" --scenes "$dev/bench" --jobs 12 \
        --deadline $(($(left) - 60)) ${extra[@]+"${extra[@]}"} 2>"$results/gates${g#g}.err"
    tar czf "$results/gates${g#g}.tgz" -C "$work" --exclude='*.ply' --exclude='*.checkpoint' \
        --exclude='checkpoint' --exclude='.ingest-*' "$g"
    cp "$work/$g/summary.tsv" "$results/summary${g#g}.tsv" 2>/dev/null
}

# Seconds phase $1 needs to be started (what it took on an H200, with a margin), gsplat's build
# left as $2 seconds where given (0: done).
need_of() {
    case "$1" in
        train-split | idle-bench | tests | ab) echo 120 ;;
        step) echo 150 ;;
        layouts) echo 130 ;;
        # Each with gsplat's build (about 70 s) where it is not done: what a background build
        # still has to go.
        peer-synthetic) echo $((100 + ${2:-$(build_left)})) ;;
        peer-train) echo $((310 + ${2:-$(build_left)})) ;;
        # One seed's pair at least (gsplat alone took 185 s on an H100); more where there
        # is room (phase_peer_quality).
        peer-quality) echo $((seed_first_s + 10 + ${2:-$(build_left)})) ;;
        *) echo 0 ;;
    esac
}
# What the phases from index $1 on need, those this machine finished aside.
needs_after() {
    local j sum=0
    for ((j = $1; j < ${#phases[@]}; j++)); do
        [[ -f "$work/done-${phases[j]}" ]] || sum=$((sum + $(need_of "${phases[j]}")))
    done
    echo "$sum"
}
tests_next=0
# Seconds gsplat's build may still take: 0 once built, its estimate less what a background
# build has run.
build_left() {
    local est=70
    if [[ -f "$work/gsplat-built" ]]; then
        echo 0
    elif [[ "$gsplat_build_pid" =~ ^[0-9]+$ ]]; then
        local r=$((est - (SECONDS - gsplat_build_started)))
        echo $((r > 0 ? r : 0))
    else
        echo "$est"
    fi
}

# Whether a peer phase (which runs gsplat) comes after phase index $1.
peer_after() {
    local j
    for ((j = $1; j < ${#phases[@]}; j++)); do
        [[ "${phases[j]}" == peer-* && ! -f "$work/done-${phases[j]}" ]] && return 0
    done
    return 1
}

i=0
while ((i < ${#phases[@]})); do
    p="${phases[i]}"
    i=$((i + 1))
    case "$p" in
        step | layouts | peer-synthetic | peer-train | peer-quality | train-split | idle-bench | ab)
            run_phase "$p" "$(need_of "$p")" ;;
        tests)
            tests_next=$i
            # The build overlaps the tests only where they will run and a peer phase follows.
            if [[ ! -f "$work/done-tests" ]] && peer_after "$i" &&
                (($(left) >= 30 + $(needs_after "$i")))
            then
                start_gsplat_build
            fi
            run_phase tests "$((30 + $(needs_after "$i")))" ;;
        gates)
            sets=()
            while ((i < ${#phases[@]})) && [[ "${phases[i]}" == [0-9]* ]]; do
                sets+=("${phases[i]}")
                i=$((i + 1))
            done
            if ((${#sets[@]} == 0)); then
                section "gates skipped: name the sets (e.g. gates 12-small)"
            elif (($(left) > 120)); then
                # No marker: a second call continues the stopped runs.
                section "gates ${sets[*]}" && phase_gates "${sets[@]}"
            fi ;;
        *) echo "gpu-session: unknown phase $p" >&2; exit 2 ;;
    esac
done
echo "gpu-session: done at $SECONDS s" | tee -a "$log"
