"""The ``creature`` task's terrain: seeded Perlin noise for the arenas' heightfields."""
from __future__ import annotations

import numpy as np

NOISE_CELL = 4.0  # m, the period of the coarsest noise octave
NOISE_OCTAVES = 3


def perlin(shape: tuple[int, int], cells: float, rng: np.random.Generator, octaves: int = NOISE_OCTAVES) -> np.ndarray:
    """Seeded 2-D gradient (Perlin) noise on a ``shape`` grid, rescaled to [0, 1].

    Octave k has a lattice of period ``cells / 2**k`` grid samples, unit gradients at uniform random
    angles on the lattice points, Perlin's fade 6t^5 - 15t^4 + 10t^3 and amplitude 2**-k. The sum
    is rescaled to [0, 1] by its minimum and maximum (all zeros if it is constant)."""
    rows, cols = shape
    total = np.zeros(shape)
    for k in range(octaves):
        period = cells / 2**k
        y, x = np.meshgrid(np.arange(rows) / period, np.arange(cols) / period, indexing="ij")
        angles = rng.uniform(0.0, 2 * np.pi, (int(y.max()) + 2, int(x.max()) + 2))
        gx, gy = np.cos(angles), np.sin(angles)
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        fx, fy = x - x0, y - y0

        def corner(dx: int, dy: int) -> np.ndarray:
            return gx[y0 + dy, x0 + dx] * (fx - dx) + gy[y0 + dy, x0 + dx] * (fy - dy)

        u = fx**3 * (fx * (6 * fx - 15) + 10)
        v = fy**3 * (fy * (6 * fy - 15) + 10)
        bottom = corner(0, 0) + u * (corner(1, 0) - corner(0, 0))
        top = corner(0, 1) + u * (corner(1, 1) - corner(0, 1))
        total += (bottom + v * (top - bottom)) / 2**k
    span = total.max() - total.min()
    return (total - total.min()) / span if span > 0 else np.zeros(shape)
