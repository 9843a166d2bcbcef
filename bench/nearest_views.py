#!/usr/bin/env python3
"""Build the do-nothing baseline of a Deblur-NeRF-layout dataset: for every test view, the blurred
train view nearest in pose, copied under the test view's name.

Usage: nearest_views.py DATASET OUT_DIR

- Views are the files of DATASET/images sorted by name (the LLFF convention), one row each in
  DATASET/poses_bounds.npy (N x 17: a 3x5 [R|t|hwf] camera-to-world, then near/far).
- Test views: index % hold == 0, hold read from the `hold=N` marker file (default 8).
- Nearest: smallest distance between camera centres; ties broken by the smaller angle between
  viewing directions.
Prints one line per test view: "<test> <train> <centre distance> <angle in degrees>".
"""
import os
import re
import shutil
import sys

import numpy as np

IMAGE_EXT = (".png", ".jpg", ".jpeg")


def fail(msg):
    print(f"nearest_views.py: {msg}", file=sys.stderr)
    sys.exit(1)


def main():
    if len(sys.argv) != 3:
        fail("usage: nearest_views.py DATASET OUT_DIR")
    data, out = sys.argv[1:]
    img_dir = os.path.join(data, "images")
    if not os.path.isdir(img_dir):
        fail(f"{img_dir}: not a folder (expected the Deblur-NeRF layout: images/, poses_bounds.npy)")
    names = sorted(n for n in os.listdir(img_dir) if n.lower().endswith(IMAGE_EXT))
    pb_path = os.path.join(data, "poses_bounds.npy")
    try:
        pb = np.load(pb_path)
    except OSError as e:
        fail(f"{pb_path}: {e}")
    if pb.ndim != 2 or pb.shape[1] != 17:
        fail(f"{pb_path}: shape {pb.shape}, expected (N, 17)")
    if pb.shape[0] != len(names):
        fail(f"{pb_path}: {pb.shape[0]} poses but {len(names)} images in {img_dir}")
    holds = [m.group(1) for n in os.listdir(data) if (m := re.fullmatch(r"hold=(\d+)", n))]
    hold = int(holds[0]) if holds else 8
    if hold < 2:
        fail(f"{data}: hold={hold} leaves no train views")

    poses = pb[:, :15].reshape(-1, 3, 5)
    centres = poses[:, :, 3]
    # LLFF columns are [down, right, back]: the camera looks along -back.
    forward = -poses[:, :, 2] / np.linalg.norm(poses[:, :, 2], axis=1, keepdims=True)
    test = [i for i in range(len(names)) if i % hold == 0]
    train = [i for i in range(len(names)) if i % hold != 0]

    os.makedirs(out, exist_ok=True)
    for t in test:
        dist = np.linalg.norm(centres[train] - centres[t], axis=1)
        angle = np.degrees(np.arccos(np.clip(forward[train] @ forward[t], -1.0, 1.0)))
        best = min(range(len(train)), key=lambda k: (round(dist[k], 9), angle[k]))
        src = names[train[best]]
        ext = os.path.splitext(src)[1]
        shutil.copyfile(os.path.join(img_dir, src),
                        os.path.join(out, os.path.splitext(names[t])[0] + ext))
        print(f"{names[t]} {src} {dist[best]:.4f} {angle[best]:.2f}")


if __name__ == "__main__":
    main()
