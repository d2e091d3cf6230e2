"""Rules of the YOLO-on-RD layout that config.py and the net's modules both read: how a width is
scaled, and the Exchangers' modes and fusion options. A leaf: config.py imports the net (to build
it), so the net never imports config.py."""

from __future__ import annotations

import math

MODES = (1, 2)  # an Exchanger's primary features: 1 the backbone's, 2 the auxiliary branch's
FUSIONS = (1, 2, 3)
SEARCHABLE = 0  # the fusion 'option' of a one-shot supernet's Exchanger: all three, chosen per step (adapter.py)


def make_divisible(x: float, divisor: int = 8) -> int:
    return int(math.ceil(x / divisor) * divisor)


def scaled_width(full: int, ratio: float) -> int:
    """A width scaled by an elastic ratio: make_divisible(full x ratio, 8); the full width at 1."""
    return int(full) if ratio == 1 else make_divisible(full * ratio, 8)
