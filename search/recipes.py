"""How much each trial trains and where it is measured.

`smoke` checks the whole pipeline in about a minute per trial (8 m x 8 m grid, 2 steps); its
numbers mean nothing. `quick` fits a sweep into ~15 minutes on a 2-core CPU: a 32 m x 32 m grid
in front of the sensor (64 x 64 cells), 150 steps of batch 4 per trial (240 for a whole one-shot
supernet) and 100 validation frames; depth sweeps start from the base's shipped weights
(search.inherit). Its mAP differences below ~1.5 points are noise (README, "What the quick
stage-2 sweep measures"). `paper` trains on the whole grid with the paper's schedule. Sizes and latency are always profiled on the model's own (full) grid, so the
cost columns are comparable with the paper whatever the recipe.

RadarNeXt-family bases have recipes of their own (`RADARNEXT_RECIPES`, same names): the
synthetic 4D (View-of-Delft-like) benchmark, RadarNeXt's schedule, training on 96-cell windows
of the 0.16 m VoD grid and validating on the whole grid with the VoD 3D AP.
"""

from __future__ import annotations

import dataclasses

from dsfec_jax import zoo
from dsfec_jax.grid import DSFEC_GRID, VOD_GRID, Grid
from dsfec_jax.train.schedules import Schedule, get_schedule


@dataclasses.dataclass(frozen=True)
class Recipe:
    name: str
    schedule: Schedule
    train_frames: int
    val_frames: int
    grid: Grid | None          # None: the model's own grid
    max_pillars: int
    window: int | None         # training windows (cells); None: the whole (recipe) grid
    latency_repeats: int
    supernet_steps: int | None  # --strategy oneshot: steps of the one supernet, shared by all candidates
    light_profile: bool        # analytic sizes + whole-network latency only (one compile per candidate)
    warm_start: bool = False   # depth sweeps start from the base's shipped weights (search.inherit)
    data: str = "synthetic"    # the source a search reads when --data is not given

    def model_overrides(self) -> dict:
        out = {"max_pillars": self.max_pillars}
        if self.grid is not None:
            out["grid"] = self.grid
        return out


NEAR_GRID = Grid((0.0, 32.0), (-16.0, 16.0), DSFEC_GRID.z_range, DSFEC_GRID.cell)
SMOKE_GRID = Grid((0.0, 8.0), (-4.0, 4.0), DSFEC_GRID.z_range, DSFEC_GRID.cell)

RECIPES = {
    "smoke": Recipe("smoke", get_schedule("quick", steps=2, batch_size=2, warmup_steps=1), 4, 2, SMOKE_GRID, 64, None, 1,
                    supernet_steps=4, light_profile=True),
    "quick": Recipe("quick", get_schedule("quick", steps=150, batch_size=4, warmup_steps=15), 400, 100,
                    NEAR_GRID, 512, None, 20, supernet_steps=240, light_profile=True, warm_start=True),
    "paper": Recipe("paper", get_schedule("paper"), 4800, 500, None, 2048, None, 20,
                    supernet_steps=None, light_profile=False),
}


# a synthetic-4D frame holds ~1,100 points, so 2,048 pillar slots never drop one (the config's
# 16,000 is the public code's bound for real 5-scan VoD); fewer slots make each step cheaper
RADARNEXT_SMOKE_GRID = Grid((0.0, 12.8), (-6.4, 6.4), VOD_GRID.z_range, VOD_GRID.cell)
RADARNEXT_RECIPES = {
    "smoke": Recipe("smoke", get_schedule("radarnext", steps=2, batch_size=2, warmup_steps=1), 4, 2,
                    RADARNEXT_SMOKE_GRID, 256, None, 1, supernet_steps=None, light_profile=True, data="synthetic4d"),
    # the paper's decay points (35/80, 45/80) would spend half of a short run at 1 % of the rate
    "quick": Recipe("quick", get_schedule("radarnext", steps=300, batch_size=4, warmup_steps=30, decay_at=(0.7, 0.9)),
                    400, 40, None, 2048, 96, 10, supernet_steps=None, light_profile=True, data="synthetic4d"),
    "paper": Recipe("paper", get_schedule("radarnext"), 4800, 500, None, 16000, None, 20,
                    supernet_steps=None, light_profile=False, data="synthetic4d"),
}


def get_recipe(name: str, base: str | None = None) -> Recipe:
    """The recipe `name` for the family of `base` (DSFEC's when no base is given)."""
    table = RADARNEXT_RECIPES if base is not None and zoo.config(base).family == "radarnext" else RECIPES
    if name not in table:
        raise ValueError(f"unknown profile {name!r}; valid: {sorted(table)}")
    return table[name]
