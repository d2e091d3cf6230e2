"""Which trained weights a candidate starts from.

A recipe with `warm_start` starts every candidate of a *depth* sweep (overrides = the family's
elastic depth field only, its supernet's `field`: DSFEC's stage_blocks) from the base model's shipped weights: the candidate keeps the first k blocks of each
stage (Once-for-All's elastic depth), then trains with the recipe. Without it a 2-core `quick`
profile leaves DSFEC-L at noise-level mAP (docs/search.md, "Profiles"). The price is a bias toward the base's own depth (it starts as the exact
trained network); it is named in every record (`init`) and report. Other axes (stem filters,
activations) change what the trained weights mean, so they always train from scratch, except
where the one-shot NAS asks for leading slices (`leading:NAME@SHA`: its width subnets retrained
stand-alone start from the base's leading channels, as its supernet did; train.warm_start).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from dsfec_jax.core import checkpoint
from dsfec_jax import zoo
from dsfec_jax.train.warm_start import LeadingSlices

from .recipes import get_recipe


def source_weights(base: str, overrides: dict, recipe: str) -> Path | None:
    """The weights file a trial of this (base, overrides, recipe) starts from, or None (scratch)."""
    path, supernet = zoo.shipped_weights(base), zoo.family_of(base).supernet
    depth_only = supernet is not None and not set(overrides) - {supernet.field}
    return path if get_recipe(recipe, base).warm_start and depth_only and path.is_file() else None


LEADING = "leading:"


def describe(path: Path | None, leading: bool = False) -> str:
    """'scratch' or '[leading:]NAME.msgpack@SHA256[:12]': part of a trial's identity and of its record."""
    if path is None:
        return "scratch"
    return f"{LEADING if leading else ''}{path.name}@{hashlib.sha256(path.read_bytes()).hexdigest()[:12]}"


def initial_variables(init: str) -> dict | None:
    """The variables a record's `init` names (None for scratch); the file must still match."""
    if init == "scratch":
        return None
    leading = init.startswith(LEADING)
    name = init.removeprefix(LEADING).split("@")[0]
    path = zoo.WEIGHTS_DIR / name
    if describe(path, leading) != init:
        raise ValueError(f"{path}: the trial was planned from {init}, the file on disk is {describe(path, leading)}; "
                         "use a new --out RUN_DIR for the new weights")
    variables = checkpoint.load(path)
    return LeadingSlices(variables) if leading else variables
