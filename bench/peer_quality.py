#!/usr/bin/env python3
"""Test PSNR of cocog's and gsplat's runs over several seeds: `peer_quality.py DIR`.

DIR holds `cocog-SEED/metrics.json` (`cocog eval` of `cocog train --seed SEED`) and
`gsplat-SEED/result.json` (`peer_gsplat.py train --seed SEED`), as bench/gpu-session.sh's
peer-quality phase leaves them. Prints one row per seed, each side's mean and sample standard
deviation, and the difference of the means with its standard error: whether cocog's PSNR is
"equal or better" than gsplat's (#11) is decided over seeds, not by one pair.
"""

import json
import math
import pathlib
import statistics
import sys


def scores(d, side):
    out = {}
    for run in sorted(p for p in d.glob(f"{side}-*") if p.is_dir()):
        seed = run.name.split("-", 1)[1]
        try:
            if side == "cocog":
                out[seed] = json.load(open(run / "metrics.json"))["mean"]["psnr"]
            else:
                out[seed] = json.load(open(run / "result.json"))["test_psnr"]
        except (OSError, KeyError, ValueError):
            out[seed] = None
    return out


def spread(values):
    mean = statistics.fmean(values)
    sd = statistics.stdev(values) if len(values) > 1 else float("nan")
    return mean, sd


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    d = pathlib.Path(sys.argv[1])
    cocog, gsplat = scores(d, "cocog"), scores(d, "gsplat")
    def fmt(side, seed):
        if seed not in side:
            return "-"
        return "failed" if side[seed] is None else f"{side[seed]:.2f}"

    print("seed\tcocog PSNR\tgsplat PSNR")
    for seed in sorted(set(cocog) | set(gsplat), key=lambda s: (len(s), s)):
        print(f"{seed}\t{fmt(cocog, seed)}\t{fmt(gsplat, seed)}")
    a = [v for v in cocog.values() if v is not None]
    b = [v for v in gsplat.values() if v is not None]
    if not a or not b:
        print("not enough finished runs to compare")
        return
    (ma, sa), (mb, sb) = spread(a), spread(b)
    print(f"cocog  mean {ma:.2f} dB, sd {sa:.2f} over {len(a)} runs")
    print(f"gsplat mean {mb:.2f} dB, sd {sb:.2f} over {len(b)} runs")
    if len(a) > 1 and len(b) > 1:
        se = math.sqrt(sa * sa / len(a) + sb * sb / len(b))
        print(f"cocog - gsplat: {ma - mb:+.2f} dB (standard error {se:.2f})")
    else:
        print(f"cocog - gsplat: {ma - mb:+.2f} dB (one run a side: no standard error)")


if __name__ == "__main__":
    main()
