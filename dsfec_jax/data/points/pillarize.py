"""Points -> the fixed-size masked pillar tensors of the pillar feature net (host side, numpy).

Nothing is lost silently: every point that does not reach the tensors is counted by reason
(non-finite, outside the grid, pillar slots full, point slots of its pillar full).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...core.grid import Grid
from .frame import Frame


@dataclasses.dataclass(frozen=True)
class PillarSpec:
    grid: Grid
    features: tuple[str, ...]
    max_pillars: int
    max_points: int

    @classmethod
    def of(cls, model_config) -> "PillarSpec":
        """The spec a model config expects (any config with these four fields)."""
        c = model_config
        return cls(c.grid, tuple(c.point_features), c.max_pillars, c.max_points)


def select_columns(frame: Frame, features: tuple[str, ...]) -> np.ndarray:
    missing = [f for f in features if f not in frame.point_features]
    if missing:
        raise KeyError(f"frame {frame.frame_id!r} ({frame.source}) lacks point features {missing}; "
                       f"has {frame.point_features}, the model needs {features}")
    idx = [frame.point_features.index(f) for f in features]
    return np.asarray(frame.points[:, idx], np.float32)


def cell_indices(xyz: np.ndarray, grid: Grid):
    """(ix, iy, inside) of each point; z outside the range also counts as outside."""
    ix = np.floor((xyz[:, 0] - grid.x_range[0]) / grid.cell).astype(np.int64)
    iy = np.floor((xyz[:, 1] - grid.y_range[0]) / grid.cell).astype(np.int64)
    nx, ny = grid.shape
    inside = ((ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
              & (xyz[:, 2] >= grid.z_range[0]) & (xyz[:, 2] < grid.z_range[1]))
    return ix, iy, inside


def pillarize(points: np.ndarray, spec: PillarSpec) -> tuple[dict, dict]:
    """points (N, F) with the spec's feature columns -> ({points, mask, coords}, drop counts).

    When there are more occupied cells than pillar slots, the pillars with the most points are
    kept (ties by cell index), so the dense tensor keeps the most evidence.
    """
    p, n, f = spec.max_pillars, spec.max_points, len(spec.features)
    finite = np.isfinite(points).all(axis=1)
    pts = points[finite]
    ix, iy, inside = cell_indices(pts, spec.grid)
    pts, ix, iy = pts[inside], ix[inside], iy[inside]
    ny = spec.grid.shape[1]
    cell = ix * ny + iy
    order = np.argsort(cell, kind="stable")
    cell_sorted = cell[order]
    cells, first, counts = np.unique(cell_sorted, return_index=True, return_counts=True)
    keep_cells = np.lexsort((cells, -counts))[:p]  # most points first, then cell index
    slot_of_cell = np.full(len(cells), -1)
    slot_of_cell[keep_cells] = np.arange(len(keep_cells))
    which = np.searchsorted(cells, cell_sorted)
    rank = np.arange(len(cell_sorted)) - first[which]
    slot = slot_of_cell[which]
    ok = (slot >= 0) & (rank < n)

    out_points = np.zeros((p, n, f), np.float32)
    mask = np.zeros((p, n), bool)
    coords = np.full((p, 2), -1, np.int32)
    out_points[slot[ok], rank[ok]] = pts[order][ok]
    mask[slot[ok], rank[ok]] = True
    coords[np.arange(len(keep_cells))] = np.stack([cells[keep_cells] // ny, cells[keep_cells] % ny], -1)
    stats = {
        "points": int(len(points)),
        "kept": int(ok.sum()),
        "dropped_nonfinite": int((~finite).sum()),
        "dropped_outside_grid": int((~inside).sum()),
        "dropped_pillar_limit": int((slot < 0).sum()),
        "dropped_point_limit": int(((slot >= 0) & (rank >= n)).sum()),
        "pillars": int(len(keep_cells)),
    }
    return {"points": out_points, "mask": mask, "coords": coords}, stats


PILLAR_BUDGET_STEP = 128  # budgets are multiples of this: a few compiled shapes, not one per data set


def pillar_budget(frames, max_pillars: int, step: int = PILLAR_BUDGET_STEP) -> int:
    """The fewest pillar slots (a multiple of `step`, at most `max_pillars`) that hold every occupied
    cell of any window of any of `frames`, before or after augmentation.

    A cell is occupied by at least one point, and augmentation (data.points.augment) moves and drops
    points but never adds one, so no window of a frame has more occupied cells than the frame has
    points. Training with this budget instead of `max_pillars` therefore drops no pillar that
    `max_pillars` would have kept and gives the same network inputs minus all-padding slots, which
    the pillar net masks out (masked max, masked batch norm, the scatter's spill cell). Radar frames
    have a few hundred points, so a 2048-slot budget spent most of the pillar net's time on padding.
    """
    if max_pillars < 1 or step < 1:
        raise ValueError(f"pillar_budget: max_pillars={max_pillars}, step={step}; expected integers >= 1")
    most = max((len(f.points) for f in frames), default=0)
    return min(max_pillars, max(step, -(-most // step) * step))


def pillarize_frames(frames: list[Frame], spec: PillarSpec) -> tuple[dict, list[dict]]:
    """A batch: each frame pillarized, stacked on a leading axis."""
    outs, stats = zip(*(pillarize(select_columns(fr, spec.features), spec) for fr in frames))
    return {k: np.stack([o[k] for o in outs]) for k in outs[0]}, list(stats)
