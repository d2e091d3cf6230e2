"""The check a modality's own code makes before it takes a model: that the model's family reads
this modality (a predictor, an export or a fit of one modality refuses another's model by name)."""

from __future__ import annotations

from .. import zoo


def require_modality(cfg_or_name, modality: str, what: str):
    """The family of a config or name, when it reads `modality`; else a ValueError saying which
    `what` (a command or function) handles only that modality."""
    family = zoo.family_of(cfg_or_name)
    if family.modality != modality:
        name = cfg_or_name if isinstance(cfg_or_name, str) else cfg_or_name.name
        raise ValueError(f"{what} handles {modality!r} models; {name!r} is a {family.modality!r} model "
                         f"(family {family.name!r})")
    return family
