"""Makes the procedural albedo textures in scenes/textures/ (stone tiles,
bricks, plaster), deterministic from a seed: python tools/make_textures.py.

Each is a 256 x 256 8-bit sRGB PNG that repeats seamlessly (every pattern
and its noise wrap around the image's edges)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio

N = 256
OUT = Path(__file__).resolve().parents[1] / "scenes" / "textures"


def noise(rng, octaves=5):
    """Periodic value noise in [0, 1]: the sum of upsampled random grids."""
    out = np.zeros((N, N))
    for o in range(octaves):
        cells = 4 * 2**o
        grid = rng.random((cells, cells))
        x = np.arange(N) * cells / N
        i0 = np.floor(x).astype(int)
        f = x - i0
        f = f * f * (3 - 2 * f)
        i1 = (i0 + 1) % cells
        rows = grid[i0][:, i0] * (1 - f)[None, :] + grid[i0][:, i1] * f[None, :]
        rows1 = grid[i1][:, i0] * (1 - f)[None, :] + grid[i1][:, i1] * f[None, :]
        out += (rows * (1 - f)[:, None] + rows1 * f[:, None]) * 0.5**o
    return (out - out.min()) / (out.max() - out.min())


def tiles(rng):
    n = noise(rng)
    y, x = np.mgrid[0:N, 0:N]
    joint = ((x % 64) < 3) | ((y % 64) < 3)
    base = np.array([0.62, 0.57, 0.50]) * (0.8 + 0.3 * n[..., None])
    return np.where(joint[..., None], [0.30, 0.28, 0.26], base)


def bricks(rng):
    n = noise(rng)
    y, x = np.mgrid[0:N, 0:N]
    row = y // 32
    shifted = (x + (row % 2) * 32) % 64
    joint = (shifted < 3) | ((y % 32) < 3)
    tone = rng.random((N // 32, N // 64 + 1))[row, ((x + (row % 2) * 32) % N) // 64]
    base = np.array([0.55, 0.30, 0.22]) * (0.75 + 0.25 * tone[..., None] + 0.15 * n[..., None])
    return np.where(joint[..., None], [0.58, 0.56, 0.52], base)


def plaster(rng):
    n = noise(rng, 6)
    return np.array([0.78, 0.74, 0.66]) * (0.85 + 0.2 * n[..., None])


def save(name, rgb_linear):
    c = np.clip(rgb_linear, 0, 1)
    srgb = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    pixels = np.ascontiguousarray(np.round(srgb * 255).astype(np.uint8))
    path = OUT / name
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(N, N, 3, oiio.UINT8))
    out.write_image(pixels)
    out.close()
    print("wrote", path)


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    for seed, (name, make) in enumerate((("tiles.png", tiles), ("bricks.png", bricks), ("plaster.png", plaster))):
        save(name, make(np.random.default_rng(2009 + seed)))


if __name__ == "__main__":
    main()
