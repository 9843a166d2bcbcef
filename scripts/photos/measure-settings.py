#!/usr/bin/env python3
"""Compares `cocog ingest photos` settings on the bench scenes: photos registered, worst camera
rotation and centre error after a similarity alignment to transforms.json, 3D points, time.

    scripts/photos/measure-settings.py COCOG_BIN ../shared/bench [name=ARGS ...]

Each setting is `name="--flag value ..."`; with none given, a built-in matrix runs. REPEAT=N
runs each N times (COLMAP's multi-threaded matching makes runs differ); SCENES=a,b picks
scenes. Results are printed as a Markdown table (BENCHMARKS.md, "ingest photos").
"""
import json, os, shlex, subprocess, sys, tempfile, time
from pathlib import Path

import numpy as np

SCENES = os.environ.get("SCENES", "defocus-dev/dev-table,defocus-dev/dev-shelf,sharp-dev").split(",")
REPEAT = int(os.environ.get("REPEAT", "1"))
MATRIX = {
    "COLMAP defaults": "--no-dsp",
    "cocog defaults (DSP, focal length held while mapping)": "",
    "DSP, COLMAP's free intrinsics": "--free-intrinsics",
    "DSP, 16k features, ratio 0.9, guided": "--max-features 16384 --max-ratio 0.9 --guided-matching",
    "no DSP, ratio 0.9, guided": "--no-dsp --max-ratio 0.9 --guided-matching",
    "DSP, SIMPLE_PINHOLE": "--camera-model SIMPLE_PINHOLE",
}


def truth(dataset):
    t = json.loads((dataset / "transforms.json").read_text())
    out = {}
    for f in t["frames"]:
        m = np.array(f["transform_matrix"], float)
        r = m[:3, :3] @ np.diag([1.0, -1.0, -1.0])  # OpenGL -> OpenCV camera axes
        out[Path(f["file_path"]).name] = (m[:3, 3], r)
    return out


def recovered(scene):
    s = json.loads((scene / "scene.json").read_text())
    out = {}
    for v in s["views"]:
        m = np.array(v["world_from_camera"], float)
        out[v["name"]] = (m[:3, 3], m[:3, :3])
    return out


def align(est_c, est_r, tru_c, tru_r):
    """Similarity true = s*R*est + t. R from the camera orientations (chordal mean of
    R_true R_est^T): centres alone leave the rotation about a narrow, forward-facing rig's long
    axis almost free. s and t are then least squares over the centres."""
    u, _, vt = np.linalg.svd(sum(a @ b.T for a, b in zip(tru_r, est_r)))
    r = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    me, mt = est_c.mean(0), tru_c.mean(0)
    a = (est_c - me) @ r.T
    s = (a * (tru_c - mt)).sum() / (a * a).sum()
    return s, r, mt - s * r @ me


def measure(cocog, dataset, args):
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "s"
        t0 = time.time()
        p = subprocess.run([cocog, "ingest", "photos", str(dataset), "-o", str(out), "--json",
                            "--min-registered", "3"] + shlex.split(args),
                           capture_output=True, text=True)
        secs = time.time() - t0
        if p.returncode != 0:
            return dict(error=p.stderr.strip().splitlines()[-1], secs=secs)
        summary = json.loads(p.stdout)
        est, tru = recovered(out), truth(dataset)
        names = sorted(set(est) & set(tru))
        ce = np.array([est[n][0] for n in names]); ct = np.array([tru[n][0] for n in names])
        s, r, t = align(ce, [est[n][1] for n in names], ct, [tru[n][1] for n in names])
        spread = np.sqrt(((ct - ct.mean(0)) ** 2).sum(1).mean())
        rot = max(np.degrees(np.arccos(np.clip((np.trace(tru[n][1].T @ r @ est[n][1]) - 1) / 2, -1, 1)))
                  for n in names)
        pos = max(np.linalg.norm(s * r @ est[n][0] + t - tru[n][0]) / spread for n in names)
        c = summary["colmap"]
        return dict(registered=f'{c["registered"]}/{c["photos"]}', rot=rot, pos=pos,
                    points=summary["points"], focal=c["focal_px"], undistorted=c["undistorted"], secs=secs)


def main():
    cocog, bench = sys.argv[1], Path(sys.argv[2])
    matrix = dict(a.split("=", 1) for a in sys.argv[3:]) or MATRIX
    print("| setting | scene | registered | max rotation error (°) | max centre error (× spread) | points | focal (px) | undistorted | seconds |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, args in matrix.items():
        for scene in [s for s in SCENES for _ in range(REPEAT)]:
            m = measure(cocog, bench / scene, args)
            if "error" in m:
                print(f"| {name} | {scene} | failed: {m['error']} | | | | | | {m['secs']:.0f} |", flush=True)
                continue
            print(f"| {name} | {scene} | {m['registered']} | {m['rot']:.4f} | {m['pos']:.4f} | {m['points']} | "
                  f"{m['focal']:.1f} | {m['undistorted']} | {m['secs']:.0f} |", flush=True)


if __name__ == "__main__":
    main()
