"""A predictor's path from raw input to detections as named stages: [(stage, fn(previous output) ->
output)], the first fn called with None. Each predictor runs its own list (its `stages(items)`),
and `dsfec bench` times that same list stage by stage (deploy/bench/timing.py), so the bench times
exactly what a user's call runs and cannot drift from it.

Later stages often need something an earlier one made (an image's letterbox map, a map's size), so
a stage may pass (value, context): `carrying(fn)` applies fn to the value and hands the context on.
"""

from __future__ import annotations

from typing import Callable

Stages = list[tuple[str, Callable]]


def carrying(fn: Callable) -> Callable:
    """(value, context) -> (fn(value), context)."""
    return lambda pair: (fn(pair[0]), pair[1])


def run(stages: Stages):
    """The last stage's output."""
    x = None
    for _, fn in stages:
        x = fn(x)
    return x
