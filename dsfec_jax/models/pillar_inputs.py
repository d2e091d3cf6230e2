"""Random but valid pillar inputs for any pillar-based config (init, profiling, tests).

`cfg` needs `grid`, `max_pillars`, `max_points` and `point_features` (x, y, z first).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np


def random_pillar_inputs(cfg, batch_size: int, seed: int, occupancy: float) -> dict:
    """A valid input pytree: `occupancy` of the pillar slots used (distinct cells), each with a
    random number of points inside its cell. occupancy=0 is an empty frame, 1 a full one."""
    rng = np.random.default_rng(seed)
    nx, ny = cfg.grid.shape
    p, n, f = cfg.max_pillars, cfg.max_points, len(cfg.point_features)
    used = int(round(occupancy * p))
    points = np.zeros((batch_size, p, n, f), np.float32)
    mask = np.zeros((batch_size, p, n), bool)
    coords = np.full((batch_size, p, 2), -1, np.int32)
    for b in range(batch_size):
        cells = rng.choice(nx * ny, size=used, replace=False)
        coords[b, :used] = np.stack([cells // ny, cells % ny], -1)
        counts = rng.integers(1, n + 1, size=used) if occupancy < 1 else np.full(used, n)
        mask[b, :used] = np.arange(n)[None, :] < counts[:, None]
        lo = np.array([cfg.grid.x_range[0], cfg.grid.y_range[0], cfg.grid.z_range[0]])
        cell_lo = lo[:2] + coords[b, :used] * cfg.grid.cell
        xy = cell_lo[:, None, :] + rng.uniform(0, cfg.grid.cell, (used, n, 2))
        z = rng.uniform(*cfg.grid.z_range, (used, n, 1))
        rest = rng.normal(size=(used, n, f - 3))
        points[b, :used] = np.concatenate([xy, z, rest], -1) * mask[b, :used, :, None]
    return {"points": jnp.asarray(points), "mask": jnp.asarray(mask), "coords": jnp.asarray(coords)}
