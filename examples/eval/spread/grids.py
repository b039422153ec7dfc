#!/usr/bin/env python3
"""Write the density grids of the spread scenes (docs/accuracy.md, "Beyond the sweep"): uint8 .raw
files with .json sidecars, deterministic, pure Python (no numpy).

  python3 examples/eval/spread/grids.py     (writes layer.raw/.json and scattered.raw/.json beside it)

layer: a stratocumulus deck 160 x 16 x 160 voxels: density 1 in the middle of the layer, a lumpy
top and base (value noise), thinning to 0 over the layer's top and bottom voxels.
scattered: five small round clouds (radius 3-6 voxels) in a 128 x 32 x 128 box, 99 % empty.
"""
import json
import math
import os
import random

HERE = os.path.dirname(os.path.abspath(__file__))


def lattice(seed, n):
    rng = random.Random(seed)
    return [rng.random() for _ in range(n * n * n)]


def value_noise(lat, n, x, y, z):
    """Trilinear value noise on an n^3 periodic lattice, in [0, 1]."""
    i, j, k = int(math.floor(x)), int(math.floor(y)), int(math.floor(z))
    fx, fy, fz = x - i, y - j, z - k
    fx, fy, fz = (f * f * (3 - 2 * f) for f in (fx, fy, fz))
    acc = 0.0
    for dk in (0, 1):
        for dj in (0, 1):
            for di in (0, 1):
                w = (fx if di else 1 - fx) * (fy if dj else 1 - fy) * (fz if dk else 1 - fz)
                acc += w * lat[((i + di) % n) + n * (((j + dj) % n) + n * ((k + dk) % n))]
    return acc


def write(name, dims, values):
    with open(os.path.join(HERE, name + ".raw"), "wb") as f:
        f.write(bytes(values))
    meta = {"resolution": list(dims), "dtype": "uint8", "endian": "little", "scale": 1.0 / 255.0}
    with open(os.path.join(HERE, name + ".json"), "w") as f:
        f.write(json.dumps(meta, indent=2) + "\n")


def layer():
    nx, ny, nz = 160, 16, 160
    lat = lattice(7, 32)
    out = []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                # Top and base heights (voxels) wander with two octaves of noise.
                n1 = value_noise(lat, 32, i / 12.0, 0.0, k / 12.0)
                n2 = value_noise(lat, 32, i / 4.0, 5.0, k / 4.0)
                top = 9.0 + 6.0 * (0.7 * n1 + 0.3 * n2)
                base = 1.0 + 3.0 * value_noise(lat, 32, i / 10.0, 11.0, k / 10.0)
                y = j + 0.5
                d = min(y - base, top - y)
                d = max(0.0, min(1.0, d / 2.0))
                puff = 0.6 + 0.4 * value_noise(lat, 32, i / 3.0, j / 3.0, k / 3.0)
                out.append(int(round(255 * d * puff)))
    write("layer", (nx, ny, nz), out)


def scattered():
    nx, ny, nz = 128, 32, 128
    rng = random.Random(3)
    blobs = [(rng.uniform(12, 116), rng.uniform(10, 22), rng.uniform(12, 116), rng.uniform(3, 6)) for _ in range(5)]
    out = []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                f = 0.0
                for cx, cy, cz, r in blobs:
                    q = ((i + 0.5 - cx) ** 2 + (j + 0.5 - cy) ** 2 + (k + 0.5 - cz) ** 2) / (r * r)
                    f = max(f, 1.0 - q)
                out.append(int(round(255 * min(1.0, 1.5 * f))) if f > 0 else 0)
    write("scattered", (nx, ny, nz), out)


if __name__ == "__main__":
    layer()
    scattered()
