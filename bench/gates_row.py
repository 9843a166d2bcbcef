"""One summary.tsv row of bench/gates.sh: `gates_row.py DIR NAME ITERATIONS [stopped]`.

A finished run (DIR holds gaussians.ply, metrics.json from `cocog eval`, train-log.jsonl and, for
cocog, lens.json) gets its scores; a run interrupted at the deadline (DIR is then the log it
left, RUN.train-log.jsonl) gets the iteration it reached and its last test-view PSNR.
"""

import json
import pathlib
import sys


def log_rows(path):
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]


def fmt(v, places):
    return "n/a" if v is None else f"{v:.{places}f}"


def stopped(d, name, its):
    log = log_rows(d)
    reached = max((r.get("iteration", 0) for r in log), default=0)
    evals = [r["eval"] for r in log if "eval" in r]
    last = evals[-1] if evals else {}
    psnr = f"{last['psnr']:.2f} at {last['iteration']}" if last else "-"
    return [name, its, f"stopped at {reached}", "-", psnr]


def finished(d, name, its):
    mean = json.load(open(d / "metrics.json"))["mean"]
    summary = next(r["summary"] for r in reversed(log_rows(d / "train-log.jsonl")) if "summary" in r)
    gaussians = "?"
    with open(d / "gaussians.ply", "rb") as ply:
        for line in ply:
            if line.startswith(b"element vertex "):
                gaussians = line.split()[2].decode()
            if line.strip() == b"end_header":
                break
    focus = "-"
    if (d / "lens.json").exists():
        err = json.load(open(d / "lens.json")).get("median_focus_relative_error")
        focus = "n/a" if err is None else f"{100 * abs(err):.1f}%"
    return [
        name,
        its,
        fmt(summary.get("seconds"), 1),
        gaussians,
        fmt(mean.get("psnr"), 2),
        fmt(mean.get("ssim_deblurnerf"), 4),
        fmt(mean.get("ssim_gaussian11"), 4),
        fmt(mean.get("lpips_alex"), 4),
        str(summary.get("last_psnr_drop") or "-"),
        focus,
    ]


if __name__ == "__main__":
    d, name, its = pathlib.Path(sys.argv[1]), sys.argv[2], sys.argv[3]
    row = stopped(d, name, its) if sys.argv[4:] == ["stopped"] else finished(d, name, its)
    print("\t".join(row))
