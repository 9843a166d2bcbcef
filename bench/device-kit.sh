#!/usr/bin/env bash
# Builds what bench/gpu-session.sh carries to a lent GPU machine (../shared/notes/gpu-device.md),
# in the git-ignored .gl/ and .device/ of the project root:
#   .gl/                 the Vulkan loader and GL dispatch packages the machine lacks (amd64 .debs)
#   .device/cocog.xz     the release `cocog`, stripped
#   .device/gemm-bench.xz  `cargo bench --bench gemm --no-run`, stripped; or, with
#                        OLD_COCOG=PATH [OLD_NAME=NAME], that other build as cocog-old.xz (and
#                        its name in cocog-old.txt) for gpu-session.sh's `ab` phase
#   .device/tests.tar.xz the GPU test executables of the engine and the trainer, stripped
#   .device/bench/       sharp-dev, defocus-dev/dev-table and dev-shelf from ../shared/bench,
#                        without depth/ and baseline/
#   .device/lpips/       the LPIPS-Alex weights (scripts/lpips/fetch-weights.sh; VGG left out)
#   .device/gsplat-1.5.3-py3-none-any.whl  the peer, for bench/peer_gsplat.py
#
#   [OLD_COCOG=PATH OLD_NAME=NAME] bench/device-kit.sh [SHARED]   (SHARED defaults to ../shared)
#
# The run tool carries at most 64 MiB with the working tree; this prints the total and fails
# past it. Takes about 10 minutes on 2 cores from a clean target/.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
shared="$(cd "${1:-$root/../shared}" && pwd)"
cd "$root"
[[ -d "$shared/bench/sharp-dev" ]] || { echo "device-kit: no $shared/bench/sharp-dev" >&2; exit 1; }
# The LPIPS conversion below needs numpy, which a fresh machine lacks: installed before the
# 20-minute build rather than found missing after it (2026-11-28).
python3 -c 'import numpy' 2>/dev/null || python3 -m pip install -q numpy
exclude="$(git rev-parse --git-path info/exclude)"
mkdir -p "$(dirname "$exclude")"
for p in /.gl/ /.device/; do
    grep -qxF "$p" "$exclude" 2>/dev/null || echo "$p" >>"$exclude"
done

debs=(libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
missing=0
for d in "${debs[@]}"; do
    compgen -G ".gl/${d}_*.deb" >/dev/null || missing=1
done
if ((missing)); then
    mkdir -p .gl /tmp/device-kit-apt/partial
    o=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/device-kit-apt)
    apt-get "${o[@]}" update -qq
    (cd .gl && apt-get "${o[@]}" download "${debs[@]}")
fi

mkdir -p .device
cargo build --release -p cocog-cli
strip -o /tmp/device-kit-cocog target/release/cocog
xz -T0 -6 -c /tmp/device-kit-cocog >.device/cocog.xz

# "NAME PATH" of every test or bench executable the cargo command built, as cargo reports
# them (target/*/deps holds older builds of the same targets too).
executables() {
    "$@" --no-run --message-format=json | python3 -c '
import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["profile"]["test"]:
        print(m["target"]["name"], m["executable"])'
}
# OLD_COCOG=PATH (a release `cocog` of another commit; OLD_NAME says which) travels as
# cocog-old for the session script's `ab` phase, in gemm-bench's place: both do not fit the
# 64 MiB. Without it, no stale old build stays behind to be compared under a wrong name.
rm -f .device/cocog-old.xz .device/cocog-old.txt
if [[ -n "${OLD_COCOG:-}" ]]; then
    rm -f .device/gemm-bench.xz
    strip -o /tmp/device-kit-cocog-old "$OLD_COCOG"
    xz -T0 -6 -c /tmp/device-kit-cocog-old >.device/cocog-old.xz
    echo "${OLD_NAME:-$OLD_COCOG}" >.device/cocog-old.txt
else
    gemm=$(executables cargo bench -p cocog-engine --bench gemm | awk '$1 == "gemm" { print $2 }')
    [[ -n "$gemm" ]] || { echo "device-kit: cargo built no gemm bench" >&2; exit 1; }
    strip -o /tmp/device-kit-gemm "$gemm"
    xz -T0 -c /tmp/device-kit-gemm >.device/gemm-bench.xz
fi

rm -rf /tmp/device-kit-tests && mkdir -p /tmp/device-kit-tests/tests
executables cargo test -p cocog-engine -p cocog-train >/tmp/device-kit-tests/list
for f in cocog-engine/tests/*.rs plugins/train/tests/*.rs; do
    n=$(basename "$f" .rs)
    [[ $n == gpu_* || $n == nn_* ]] || continue
    exe=$(awk -v n="$n" '$1 == n { print $2 }' /tmp/device-kit-tests/list)
    [[ -n "$exe" ]] || { echo "device-kit: cargo built no test executable $n" >&2; exit 1; }
    strip -o "/tmp/device-kit-tests/tests/$n" "$exe"
done
# -9e: about 2 MB less than tar's default xz level, which an old build beside needs.
tar cf - -C /tmp/device-kit-tests tests | xz -T0 -9e >.device/tests.tar.xz

rm -rf .device/bench && mkdir -p .device/bench/defocus-dev
cp -r "$shared/bench/sharp-dev" .device/bench/
for s in dev-table dev-shelf; do
    cp -r "$shared/bench/defocus-dev/$s" .device/bench/defocus-dev/
done
rm -rf .device/bench/*/depth .device/bench/*/*/depth .device/bench/*/*/baseline

if [[ ! -f .device/lpips/alex.safetensors ]]; then
    scripts/lpips/fetch-weights.sh .device/lpips
    rm -f .device/lpips/vgg.safetensors
fi
[[ -f .device/gsplat-1.5.3-py3-none-any.whl ]] ||
    python3 -m pip download -q --no-deps --only-binary=:all: -d .device gsplat==1.5.3

# What the run tool carries besides: tracked files and untracked ones git does not ignore.
tree=$(git ls-files -z --cached --others --exclude-standard |
    du -cb --files0-from=- 2>/dev/null | tail -1 | cut -f1 || true)
kit=$(du -sb .gl .device | awk '{s += $1} END {print s}')
mib=$(( (tree + kit + 1048575) / 1048576 ))
echo "device-kit: $(git rev-parse --short HEAD), about $mib MiB with the tracked tree (limit 64)"
((mib < 64)) || { echo "device-kit: over the 64 MiB the run tool carries" >&2; exit 1; }
