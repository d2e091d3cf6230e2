"""Search spaces: axes over config fields of a registered model, expanded to candidates and
validated through the zoo before anything trains.

Axes are `FIELD=V1,V2,...` for scalar fields and `FIELD=A|B|...` for tuple fields (each value a
comma-separated tuple, e.g. `stage_blocks=3,1,6,3|3,6,6,3`). A family may define derived axes
(its record's `axes`: name -> fn(base config, overrides, value) -> overrides):
  DSFEC      stage{K}_blocks=V1,V2   blocks of stage K (1-4), the rest of stage_blocks kept from the base
             stem_filters=V1,V2      also sets the FEC's last width to V, as in the paper (FEC 32-128-12 -> stem 12)
  RadarNeXt  neck=fpn,pan,mdfen      keeps the DCNv3 positions for mdfen ((4,) when the base has
                                     none) and drops them for fpn/pan, as the paper's three variants do
"""

from __future__ import annotations

import ast
import dataclasses
import itertools
import re

from dsfec_jax import zoo


class SearchSpaceError(ValueError):
    pass


@dataclasses.dataclass(frozen=True)
class Axis:
    field: str
    values: tuple

    def label(self, value) -> str:
        shown = ",".join(map(str, value)) if isinstance(value, tuple) else str(value)
        return f"{self.field}={shown}"


def _literal(text: str):
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def parse_axis(spec: str, base: str) -> Axis:
    field, sep, raw = spec.partition("=")
    if not sep or not raw:
        raise SearchSpaceError(f"--axis {spec!r}: expected FIELD=V1,V2,... (tuple fields: FIELD=A|B)")
    derived = zoo.family_of(base).axes
    fields = {f.name for f in dataclasses.fields(zoo.config(base))}
    if field not in fields and field not in derived:
        raise SearchSpaceError(f"--axis {spec!r}: unknown field {field!r} of {base!r}; valid: {sorted(fields)} "
                               f"or the derived axes {sorted(derived)}")
    # a derived axis that is not also a field (stage2_blocks) takes scalar values
    default = getattr(zoo.config(base), field, None)
    if isinstance(default, tuple):
        values = tuple(tuple(_literal(v) for v in part.split(",")) for part in raw.split("|"))
    else:
        values = tuple(_literal(v) for v in re.split(r"[,|]", raw))
    return Axis(field, values)


def apply_axis(base_cfg, overrides: dict, field: str, value) -> dict:
    """Overrides with one axis value applied: the family's derived axis of that name, else the field."""
    derived = zoo.family_of(base_cfg).axes.get(field)
    return derived(base_cfg, dict(overrides), value) if derived else {**overrides, field: value}


def candidates(base: str, axes: list[Axis], fixed: dict | None = None) -> list[dict]:
    """Every combination of axis values: [{'label', 'overrides'}], each validated by the zoo."""
    base_cfg = zoo.config(base)
    out, errors = [], []
    for combo in itertools.product(*(a.values for a in axes)):
        overrides = dict(fixed or {})
        for axis, value in zip(axes, combo):
            overrides = apply_axis(base_cfg, overrides, axis.field, value)
        label = " ".join(a.label(v) for a, v in zip(axes, combo)) or base
        try:
            zoo.config(base, **overrides)
        except (ValueError, TypeError, KeyError) as err:
            errors.append(f"{label}: {err}")
        out.append({"label": label, "overrides": overrides})
    if errors:
        raise SearchSpaceError("invalid candidates (nothing was trained):\n  " + "\n  ".join(errors))
    return out
