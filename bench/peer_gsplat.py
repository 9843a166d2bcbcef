#!/usr/bin/env python3
"""Time and score gsplat on cocog's own inputs, for side-by-side figures in BENCHMARKS.md.

Three modes:
  train SCENE --out DIR [--downscale N --iterations I --prune-scale3d X --no-opacity-reset
        --seed S]
      plain 3DGS with gsplat's rasterizer and DefaultStrategy on a cocog scene directory (the
      output of `cocog ingest`): the same views, split, initial points and downscale as
      `cocog train SCENE --method 3dgs`; writes DIR/result.json and the test renders as PNG
      (score them with `cocog eval --pred DIR/renders --gt ...`).
  workload DIR --out FILE [--iterations I --warmup W]
      the fixed-count workload `cocog bench --synthetic N --size WxH --write-workload DIR`
      wrote: the same random Gaussians and cameras, no density control, all SH bands, targets
      as cocog's bench makes them; prints and writes ms/iteration and peak GPU memory.
  check SCENE | check --workload DIR
      loads the inputs only (numpy, Pillow; no torch) and prints what it found.

The training recipe is INRIA's as gsplat drives it: Adam per group (means 1.6e-4 x scene scale
decayed 100x over the run, scales 5e-3, quats 1e-3, opacities 5e-2, SH DC 2.5e-3, SH rest
2.5e-3/20), loss 0.8 L1 + 0.2 (1 - SSIM, 11x11 Gaussian window), one SH band per 1000
iterations, black background, densification every 100 from 500 to 15000, opacity reset every
3000 (gsplat 1.5.3's own reset never fires, so it is done here unless --no-opacity-reset).
Timing covers the training loop after its first step (gsplat's CUDA build and warm-up), with the
GPU synchronised at both ends; train's it/s counts the timed steps.
Needs a CUDA GPU with torch and gsplat==1.5.3 (see ../shared/anchors/gsplat/README.md for
installing it where nothing can be downloaded).
"""
import argparse
import json
import math
import os
import sys
import time

import numpy as np

SH_C0 = 0.28209479177387814


# ---- inputs (numpy only) --------------------------------------------------------------------

def downscaled_size(w, h, n):
    """cocog's --downscale size: w / n rounded half away from zero (not Python's round())."""
    return max(1, int(w / n + 0.5)), max(1, int(h / n + 0.5))


def load_rgb(path, downscale):
    """An image in [0, 1], alpha composited over black (cocog's background), area-averaged to
    cocog's downscaled size."""
    from PIL import Image
    if not os.path.exists(path):
        sys.exit(f"{path}: no such image (scene.json holds the paths `cocog ingest` saw: ingest "
                 f"the dataset on this machine)")
    img = Image.open(path).convert("RGBA")
    if downscale > 1:
        img = img.resize(downscaled_size(*img.size, downscale), Image.BOX)
    rgba = np.asarray(img, dtype=np.float32) / 255.0
    return rgba[..., :3] * rgba[..., 3:]


_PLY_TYPES = {"float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8",
              "uchar": "u1", "uint8": "u1", "char": "i1", "int8": "i1", "ushort": "<u2",
              "uint16": "<u2", "short": "<i2", "int16": "<i2", "uint": "<u4", "uint32": "<u4",
              "int": "<i4", "int32": "<i4"}


def read_ply_vertices(path):
    """The vertex element of a binary little-endian PLY (what cocog writes) as a record array:
    numpy alone, since the GPU image has no plyfile."""
    with open(path, "rb") as f:
        if f.readline().strip() != b"ply":
            sys.exit(f"{path}: not a PLY file")
        fields, count, in_vertex = [], None, False
        while True:
            words = f.readline().decode("ascii").split()
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "format" and words[1] != "binary_little_endian":
                sys.exit(f"{path}: format {words[1]}, expected binary_little_endian")
            if words[0] == "element":
                in_vertex = words[1] == "vertex"
                if in_vertex:
                    count = int(words[2])
                elif count is None:
                    sys.exit(f"{path}: the vertex element must come first")
            elif words[0] == "property" and in_vertex:
                if words[1] == "list":
                    sys.exit(f"{path}: list property in the vertex element")
                fields.append((words[-1], _PLY_TYPES[words[1]]))
            elif words[0] == "end_header":
                break
        return np.fromfile(f, dtype=np.dtype(fields), count=count)


def load_scene(scene_dir, downscale):
    """Views (camera, world_from_camera, image, split) and initial points of a cocog scene."""
    with open(os.path.join(scene_dir, "scene.json")) as f:
        scene = json.load(f)
    cameras = {c["id"]: c for c in scene["cameras"]}
    views = []
    for v in scene["views"]:
        c = cameras[v["camera"]]
        path = v["image"] if os.path.isabs(v["image"]) else os.path.join(scene_dir, v["image"])
        image = load_rgb(path, downscale)
        # Intrinsics scaled by the size ratio, as cocog scales them.
        sx, sy = image.shape[1] / c["width"], image.shape[0] / c["height"]
        views.append(dict(
            name=v["name"], split=v["split"], image=image,
            K=np.array([[c["fx"] * sx, 0, c["cx"] * sx],
                        [0, c["fy"] * sy, c["cy"] * sy], [0, 0, 1]], np.float32),
            world_from_camera=np.array(v["world_from_camera"], np.float64)))
    points = scene.get("points")
    if points is None:
        sys.exit(f"{scene_dir}/scene.json: no `points` (ingest a dataset with a point cloud)")
    vx = read_ply_vertices(points if os.path.isabs(points) else os.path.join(scene_dir, points))
    xyz = np.stack([vx["x"], vx["y"], vx["z"]], 1).astype(np.float32)
    rgb = np.stack([vx["red"], vx["green"], vx["blue"]], 1).astype(np.float32) / 255.0
    return views, xyz, rgb


def load_workload(work_dir):
    """The random Gaussians (INRIA PLY) and cameras `cocog bench --write-workload` wrote."""
    vx = read_ply_vertices(os.path.join(work_dir, "gaussians.ply"))
    names = vx.dtype.names
    rest = sorted((n for n in names if n.startswith("f_rest_")), key=lambda n: int(n[7:]))
    k = len(rest) // 3 + 1
    g = dict(
        means=np.stack([vx["x"], vx["y"], vx["z"]], 1),
        log_scales=np.stack([vx[f"scale_{i}"] for i in range(3)], 1),
        quats=np.stack([vx[f"rot_{i}"] for i in range(4)], 1),
        opacity_logits=np.asarray(vx["opacity"]),
        sh0=np.stack([vx[f"f_dc_{c}"] for c in range(3)], 1)[:, None, :],
        # INRIA stores f_rest channel-major: f_rest_{c*(K-1) + j}.
        shN=np.ascontiguousarray(
            np.stack([vx[n] for n in rest], 1).reshape(-1, 3, k - 1).transpose(0, 2, 1))
        if rest else np.zeros((len(vx), 0, 3), np.float32),
        sh_degree=int(round(math.sqrt(k))) - 1)
    with open(os.path.join(work_dir, "cameras.json")) as f:
        cams = json.load(f)["cameras"]
    views = []
    for i, c in enumerate(cams):
        w, h = c["width"], c["height"]
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        # The targets cocog's bench trains towards: smooth and distinct per view.
        image = np.stack([xx / w, yy / h, np.full_like(xx, 0.5 + 0.4 * math.sin(i))], -1)
        views.append(dict(name=f"{i:03}", split="train", image=image,
                          K=np.array([[c["fx"], 0, c["cx"]], [0, c["fy"], c["cy"]], [0, 0, 1]],
                                     np.float32),
                          world_from_camera=np.array(c["world_from_camera"], np.float64)))
    return views, g


def scene_scale(views):
    """INRIA's camera extent: 1.1 x the largest distance of a training camera from their mean."""
    centres = np.stack([v["world_from_camera"][:3, 3] for v in views if v["split"] == "train"])
    return 1.1 * float(np.linalg.norm(centres - centres.mean(0), axis=1).max())


def check(args):
    if args.workload:
        views, g = load_workload(args.workload)
        n = len(g["means"])
        print(f"workload: {n} Gaussians, SH degree {g['sh_degree']}, {len(views)} cameras of "
              f"{views[0]['image'].shape[1]}x{views[0]['image'].shape[0]}")
        xyz = g["means"]
    else:
        views, xyz, _ = load_scene(args.scene, args.downscale)
        train = sum(v["split"] == "train" for v in views)
        print(f"scene: {len(views)} views ({train} train, {len(views) - train} test) of "
              f"{views[0]['image'].shape[1]}x{views[0]['image'].shape[0]}, {len(xyz)} points, "
              f"scene scale {scene_scale(views):.6f}")
    # Every view sees some of the points: a wrong pose convention sees none.
    for v in views:
        m = np.linalg.inv(v["world_from_camera"])
        p = xyz @ m[:3, :3].T + m[:3, 3]
        z = np.maximum(p[:, 2], 1e-9)
        u = v["K"][0, 0] * p[:, 0] / z + v["K"][0, 2]
        w = v["K"][1, 1] * p[:, 1] / z + v["K"][1, 2]
        h, wd = v["image"].shape[:2]
        seen = (p[:, 2] > 0) & (u >= 0) & (u < wd) & (w >= 0) & (w < h)
        print(f"  {v['name']}: {seen.mean():.3f} of the points in its frame")


# ---- gsplat (torch, CUDA) ---------------------------------------------------------------------

def ssim_window(channels, dev):
    """The 11x11 Gaussian window (sigma 1.5), one per channel."""
    import torch
    x = torch.arange(11, dtype=torch.float32, device=dev) - 5
    g = torch.exp(-x ** 2 / (2 * 1.5 ** 2))
    g = g / g.sum()
    return (g[:, None] * g[None, :]).expand(channels, 1, 11, 11).contiguous()


def ssim(a, b, win):
    """Mean SSIM of two NCHW images with `win` (ssim_window), zero padding."""
    import torch.nn.functional as F
    blur = lambda t: F.conv2d(t, win, padding=5, groups=a.shape[1])
    mu_a, mu_b = blur(a), blur(b)
    va, vb = blur(a * a) - mu_a ** 2, blur(b * b) - mu_b ** 2
    cov = blur(a * b) - mu_a * mu_b
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    s = (2 * mu_a * mu_b + c1) * (2 * cov + c2) / ((mu_a ** 2 + mu_b ** 2 + c1) * (va + vb + c2))
    return s.mean()


def fit(views, params, steps, extent, strategy=None, reset_every=0, sh_every=1000,
        max_degree=3, warmup=1, seed=0):
    """Trains `params` on the training views for `steps` steps; returns the seconds of steps
    `warmup`.. (the first ones pay gsplat's CUDA build) and how many steps that timed."""
    import torch
    from gsplat import rasterization
    from gsplat.strategy.ops import reset_opa
    dev = params["means"].device
    train = [v for v in views if v["split"] == "train"]
    targets = [torch.from_numpy(v["image"]).to(dev) for v in train]
    Ks = [torch.from_numpy(v["K"]).to(dev) for v in train]
    viewmats = [torch.from_numpy(np.linalg.inv(v["world_from_camera"]).astype(np.float32)).to(dev)
                for v in train]
    lrs = dict(means=1.6e-4 * extent, scales=5e-3, quats=1e-3, opacities=5e-2, sh0=2.5e-3,
               shN=2.5e-3 / 20)
    opt = {k: torch.optim.Adam([params[k]], lr=lr, eps=1e-15) for k, lr in lrs.items()}
    decay = torch.optim.lr_scheduler.ExponentialLR(opt["means"], 0.01 ** (1.0 / steps))
    state = strategy.initialize_state(scene_scale=extent) if strategy else None
    win = ssim_window(3, dev)
    order = np.random.default_rng(seed)
    perm, clock = [], None
    if steps <= warmup:
        sys.exit(f"{steps} steps leave none to time after {warmup} warm-up step(s)")
    for it in range(steps):
        if it == warmup:
            torch.cuda.synchronize()
            clock = time.perf_counter()
        if not perm:
            perm = list(order.permutation(len(train)))
        i = perm.pop()
        h, w = targets[i].shape[:2]
        degree = min(it // sh_every, max_degree) if sh_every else max_degree
        colors = torch.cat([params["sh0"], params["shN"]], 1)
        # gsplat normalises the quaternions itself.
        img, _, info = rasterization(
            params["means"], params["quats"], torch.exp(params["scales"]), torch.sigmoid(params["opacities"]), colors,
            viewmats[i][None], Ks[i][None], w, h, sh_degree=degree, packed=False)
        if strategy:
            strategy.step_pre_backward(params, opt, state, it, info)
        pred = img[0].permute(2, 0, 1)[None]
        gt = targets[i].permute(2, 0, 1)[None]
        loss = 0.8 * (pred - gt).abs().mean() + 0.2 * (1 - ssim(pred, gt, win))
        loss.backward()
        for o in opt.values():
            o.step()
            o.zero_grad(set_to_none=True)
        decay.step()
        if strategy:
            strategy.step_post_backward(params, opt, state, it, info, packed=False)
            if reset_every and it > 0 and it % reset_every == 0 and it < strategy.refine_stop_iter:
                # As INRIA and gsplat's own reset: opacities to at most 0.01, Adam's moments of
                # the opacities cleared.
                reset_opa(params=params, optimizers=opt, state=state, value=0.01)
    torch.cuda.synchronize()
    return time.perf_counter() - clock, steps - warmup


def as_params(arrays, dev):
    import torch
    return torch.nn.ParameterDict({k: torch.nn.Parameter(torch.as_tensor(v, dtype=torch.float32,
                                                                         device=dev))
                                   for k, v in arrays.items()})


def train(args):
    import torch
    from gsplat import DefaultStrategy
    from PIL import Image
    from scipy.spatial import cKDTree
    views, xyz, rgb = load_scene(args.scene, args.downscale)
    extent = scene_scale(views)
    d, _ = cKDTree(xyz).query(xyz, k=4)
    dist = np.sqrt(np.maximum((d[:, 1:] ** 2).mean(1), 1e-7))
    n = len(xyz)
    params = as_params(dict(
        means=xyz, scales=np.log(dist)[:, None].repeat(3, 1),
        quats=np.tile([1.0, 0, 0, 0], (n, 1)), opacities=np.full(n, math.log(0.1 / 0.9)),
        sh0=((rgb - 0.5) / SH_C0)[:, None, :], shN=np.zeros((n, 15, 3))), "cuda")
    strategy = DefaultStrategy(prune_scale3d=args.prune_scale3d, refine_start_iter=500,
                               refine_stop_iter=15000, refine_every=100, reset_every=3000)
    torch.cuda.reset_peak_memory_stats()
    # The seed picks the view order and the splits' samples (torch's generator), as `cocog
    # train --seed` picks cocog's: runs of either side with several seeds show their spread.
    torch.manual_seed(args.seed)
    seconds, timed = fit(views, params, args.iterations, extent, strategy,
                         reset_every=0 if args.no_opacity_reset else 3000, seed=args.seed)
    from gsplat import rasterization
    os.makedirs(os.path.join(args.out, "renders"), exist_ok=True)
    psnrs = []
    with torch.no_grad():
        for v in views:
            if v["split"] != "test":
                continue
            h, w = v["image"].shape[:2]
            img, _, _ = rasterization(
                params["means"], torch.nn.functional.normalize(params["quats"], dim=-1),
                torch.exp(params["scales"]), torch.sigmoid(params["opacities"]),
                torch.cat([params["sh0"], params["shN"]], 1),
                torch.from_numpy(np.linalg.inv(v["world_from_camera"]).astype(np.float32))
                .cuda()[None], torch.from_numpy(v["K"]).cuda()[None], w, h, sh_degree=3)
            png = (img[0].clamp(0, 1).cpu().numpy() * 255 + 0.5).astype(np.uint8)
            # As `cocog eval` scores a saved render: 8-bit against the ground truth.
            mse = float(((png.astype(np.float64) / 255 - v["image"]) ** 2).mean())
            psnrs.append(10 * math.log10(1 / max(mse, 1e-20)))
            Image.fromarray(png).save(os.path.join(args.out, "renders",
                                                   os.path.splitext(v["name"])[0] + ".png"))
    result = dict(peer="gsplat", gsplat=__import__("gsplat").__version__,
                  device=torch.cuda.get_device_name(), scene=os.path.abspath(args.scene),
                  downscale=args.downscale, iterations=args.iterations,
                  timed_iterations=timed, seconds=seconds, it_per_s=timed / seconds,
                  gaussians=len(params["means"]), initial_gaussians=n,
                  scene_scale=extent, train_views=sum(v["split"] == "train" for v in views),
                  test_psnr=float(np.mean(psnrs)) if psnrs else None,
                  peak_gpu_bytes=torch.cuda.max_memory_allocated(),
                  prune_scale3d=args.prune_scale3d, opacity_reset=not args.no_opacity_reset,
                  seed=args.seed)
    with open(os.path.join(args.out, "result.json"), "w") as f:
        json.dump(result, f, indent=2)
    print(json.dumps(result, indent=2))


def workload(args):
    import torch
    views, g = load_workload(args.workload)
    params = as_params({k: g[k] for k in ("means", "quats", "sh0", "shN")} |
                       dict(scales=g["log_scales"], opacities=g["opacity_logits"]), "cuda")
    torch.cuda.reset_peak_memory_stats()
    seconds, _ = fit(views, params, args.iterations + args.warmup, scene_scale(views),
                     sh_every=0, max_degree=g["sh_degree"], warmup=args.warmup)
    result = dict(peer="gsplat", gsplat=__import__("gsplat").__version__,
                  device=torch.cuda.get_device_name(), workload=os.path.abspath(args.workload),
                  gaussians=len(g["means"]), views=len(views),
                  size=list(views[0]["image"].shape[1::-1]), iterations=args.iterations,
                  ms_per_iteration=1e3 * seconds / args.iterations,
                  it_per_s=args.iterations / seconds,
                  peak_gpu_bytes=torch.cuda.max_memory_allocated())
    with open(args.out, "w") as f:
        json.dump(result, f, indent=2)
    print(json.dumps(result, indent=2))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="mode", required=True)
    t = sub.add_parser("train", help="train and score plain 3DGS on a cocog scene")
    t.add_argument("scene")
    t.add_argument("--out", required=True)
    t.add_argument("--downscale", type=int, default=1)
    t.add_argument("--iterations", type=int, default=30000)
    t.add_argument("--prune-scale3d", type=float, default=1e9,
                   help="world-space prune x scene scale (INRIA 0.1; default off, as cocog's "
                        "auto schedule for forward-facing captures)")
    t.add_argument("--no-opacity-reset", action="store_true")
    t.add_argument("--seed", type=int, default=0,
                   help="view order and the strategy's random draws (default 0)")
    w = sub.add_parser("workload", help="time the random Gaussians of cocog bench --synthetic")
    w.add_argument("workload")
    w.add_argument("--out", required=True)
    w.add_argument("--iterations", type=int, default=100)
    w.add_argument("--warmup", type=int, default=10)
    c = sub.add_parser("check", help="load the inputs and print them (no GPU)")
    c.add_argument("scene", nargs="?")
    c.add_argument("--workload")
    c.add_argument("--downscale", type=int, default=1)
    args = ap.parse_args()
    if args.mode == "check" and not (args.scene or args.workload):
        ap.error("check needs a SCENE or --workload DIR")
    {"train": train, "workload": workload, "check": check}[args.mode](args)


if __name__ == "__main__":
    main()
