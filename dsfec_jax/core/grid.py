"""The BEV grid a detector sees: metric ranges and cell size.

A leaf module (imports nothing of the project) because models, data and metrics all need the
same geometry and must not import each other.
"""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class Grid:
    """Axis-aligned pillar grid in the sensor/ego frame (metres)."""

    x_range: tuple[float, float] = (0.0, 80.0)
    y_range: tuple[float, float] = (-40.0, 40.0)
    z_range: tuple[float, float] = (-2.5, 2.5)
    cell: float = 0.5

    def __post_init__(self):
        for name in ("x_range", "y_range", "z_range"):
            lo, hi = getattr(self, name)
            if not hi > lo:
                raise ValueError(f"Grid.{name}={getattr(self, name)}: expected (low, high) with high > low")
        if self.cell <= 0:
            raise ValueError(f"Grid.cell={self.cell}: expected a positive cell size in metres")
        for name, (lo, hi) in (("x_range", self.x_range), ("y_range", self.y_range)):
            cells = (hi - lo) / self.cell
            if abs(cells - round(cells)) > 1e-6:
                raise ValueError(f"Grid.{name} spans {hi - lo} m, not a whole number of {self.cell} m cells")

    @property
    def shape(self) -> tuple[int, int]:
        """(nx, ny): cells along x (image rows) and y (image columns)."""
        nx = round((self.x_range[1] - self.x_range[0]) / self.cell)
        ny = round((self.y_range[1] - self.y_range[0]) / self.cell)
        return nx, ny

    def contains(self, x, y):
        """Whether (x, y) (scalars or arrays, metres) lies on the grid: [low, high) on each axis,
        the cells' own convention."""
        return (x >= self.x_range[0]) & (x < self.x_range[1]) & (y >= self.y_range[0]) & (y < self.y_range[1])

    @property
    def z_center(self) -> float:
        return 0.5 * (self.z_range[0] + self.z_range[1])


DSFEC_GRID = Grid()  # the paper: X [0, 80], Y [-40, 40], Z [-2.5, 2.5], 0.5 m -> 160 x 160
# RadarNeXt's 4D-radar grids (public RadarNeXt code, github Pay246-git468/RadarNeXt, commit 72676df,
# projects/RadarNeXt/configs/radarnext.py and radarnext_tj4d.py): 0.16 m pillars spanning the full height.
VOD_GRID = Grid((0.0, 51.2), (-25.6, 25.6), (-3.0, 2.0), 0.16)  # 320 x 320
TJ4D_GRID = Grid((0.0, 69.12), (-34.56, 34.56), (-4.0, 2.0), 0.16)  # 432 x 432
