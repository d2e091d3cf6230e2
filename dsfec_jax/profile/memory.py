"""Memory figures.

`paper_memory_mb` is the family's own published convention, where it has one (DSFEC's Table 2:
the stem's input and output maps plus its weights, models/dsfec/stem_memory.py; Shuffle-YOLOv3's
Sec. 3.4: every layer's parameters and output map at 416 x 416, models/camera/footprint.py), named
by the family's `memory_convention`. `xla_peak_mb` is
what XLA reserves for temporaries plus arguments and outputs of the compiled network: a fuller,
less comparable figure.
"""

from __future__ import annotations

from .. import zoo

MIB = 2**20


def paper_memory_mb(detector, variables) -> float | None:
    """The family's published memory figure; None for families without one (use xla_peak_mb)."""
    measure = zoo.family_of(detector.config).stem_memory
    return None if measure is None else measure(detector.config, variables)


def convention(detector) -> str:
    """What `memory_mb` of `detector`'s record measures."""
    family = zoo.family_of(detector.config)
    if family.stem_memory is None:
        return "none: the family publishes no memory figure (see xla_peak_mb)"
    return family.memory_convention


def xla_peak_mb(compiled) -> float:
    mem = compiled.memory_analysis()
    if mem is None:
        return float("nan")
    total = mem.temp_size_in_bytes + mem.argument_size_in_bytes + mem.output_size_in_bytes
    return total / MIB
