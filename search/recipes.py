"""How much each trial trains and where it is measured, per family (its record's `recipes`).

`smoke` checks the whole pipeline in about a minute per trial; its numbers mean nothing. `quick`
fits a sweep into ~15 minutes on a 2-core CPU: for DSFEC a 32 m x 32 m grid in front of the
sensor (64 x 64 cells), 150 steps of batch 4 per trial (a one-shot sweep: three seeds of a
480-step supernet, `--seeds` and `--supernet-steps` to change them) and 100 validation frames,
depth sweeps starting from the base's shipped weights (search.inherit); a single seed's small mAP
differences are noise (docs/search.md, "What the quick stage-2 sweep measures"). For
RadarNeXt: the synthetic 4D (View-of-Delft-like) benchmark, RadarNeXt's schedule, 96-cell
windows of the 0.16 m VoD grid, validation on the whole grid with the VoD 3D AP. `paper` trains
on the whole grid with the paper's schedule. Sizes and latency are always profiled on the
model's own (full) grid, so the cost columns are comparable with the paper whatever the recipe.
"""

from __future__ import annotations

import dataclasses

from dsfec_jax import zoo
from dsfec_jax.core.grid import Grid
from dsfec_jax.models.family import SearchRecipe
from dsfec_jax.train.schedules import Schedule, get_schedule


@dataclasses.dataclass(frozen=True)
class Recipe:
    name: str
    schedule: Schedule
    train_frames: int
    val_frames: int
    grid: Grid | None          # None: the model's own grid
    max_pillars: int | None    # None: not a point-cloud family
    window: int | None         # training windows (cells); None: the whole (recipe) grid
    latency_repeats: int
    supernet_steps: int | None  # --strategy oneshot: steps of the one supernet, shared by all candidates
    light_profile: bool        # analytic sizes + whole-network latency only (one compile per candidate)
    warm_start: bool = False   # depth sweeps start from the base's shipped weights (search.inherit)
    oneshot_seeds: int = 1     # --strategy oneshot without --seeds: supernets (seeds) per search
    data: str = "synthetic"    # the source a search reads when --data is not given

    def model_overrides(self) -> dict:
        out = {} if self.max_pillars is None else {"max_pillars": self.max_pillars}
        if self.grid is not None:
            out["grid"] = self.grid
        return out

    def fit_options(self) -> dict:
        """The modality's own options of its fit: the point families' training windows (None:
        the whole grid); nothing for the others (max_pillars None: not a point-cloud family)."""
        return {} if self.max_pillars is None else {"window": self.window}


def build(name: str, spec: SearchRecipe, data: str) -> Recipe:
    """A family's recipe data -> the Recipe a trial runs (its schedule built from train.schedules)."""
    fields = {f.name: getattr(spec, f.name) for f in dataclasses.fields(SearchRecipe)
              if f.name not in ("schedule", "schedule_changes")}
    return Recipe(name, get_schedule(spec.schedule, **spec.schedule_changes), data=data, **fields)


# family name -> recipe name -> Recipe (tests and users may replace an entry)
RECIPES: dict[str, dict[str, Recipe]] = {
    family.name: {name: build(name, spec, family.benchmark) for name, spec in family.recipes.items()}
    for family in zoo.FAMILIES.values()}
PROFILES = sorted({name for table in RECIPES.values() for name in table})


def get_recipe(name: str, base: str) -> Recipe:
    """The recipe `name` for the family of registered model `base`."""
    table = RECIPES[zoo.family_of(base).name]
    if name not in table:
        raise ValueError(f"unknown profile {name!r} for {base!r}; valid: {sorted(table)}")
    return table[name]
