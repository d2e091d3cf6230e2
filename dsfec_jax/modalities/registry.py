"""The registry of modalities: a new modality is its folder under modalities/ plus one entry here."""

from __future__ import annotations

from .. import zoo
from .base import Modality
from .image.record import MODALITY as IMAGE
from .points.record import MODALITY as POINTS
from .rd.record import MODALITY as RD

MODALITIES: dict[str, Modality] = {m.name: m for m in (POINTS, RD, IMAGE)}


def modality_named(name: str) -> Modality:
    """The record of a modality's name, or a KeyError listing the known ones."""
    if name not in MODALITIES:
        raise KeyError(f"unknown modality {name!r}; modalities: {sorted(MODALITIES)}")
    return MODALITIES[name]


def modality_of(cfg_or_name) -> Modality:
    """The Modality record of a config (or of a registered variant's name): its family's."""
    return modality_named(zoo.family_of(cfg_or_name).modality)


def protocol(name: str):
    """The scoring Protocol a family's MetricProtocol names, from whichever modality supplies it."""
    for modality in MODALITIES.values():
        if name in modality.protocols:
            return modality.protocols[name]
    known = sorted(p for m in MODALITIES.values() for p in m.protocols)
    raise KeyError(f"unknown metric protocol {name!r}; known: {known}")
