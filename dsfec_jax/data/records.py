"""Typed fields of records read from JSON data files (dataset tables, cache manifests).

JSON gives any type anywhere: a reader that indexes `record["size"][2]` on a mistyped file dies with
a KeyError or TypeError that names neither the file nor the field. `check_fields` checks the fields
a reader uses, once, and raises ValueError naming the file, the record and the field.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Mapping

from .paths import path_problem


def _finite(v: Any) -> bool:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return math.isfinite(float(v))  # a huge JSON integer overflows a float
    except OverflowError:
        return False


def _numbers(n: int, positive: bool = False, nonzero: bool = False) -> Callable[[Any], bool]:
    def ok(v):
        if not (isinstance(v, list) and len(v) == n and all(map(_finite, v))):
            return False
        return (not positive or min(v) > 0) and (not nonzero or any(v))
    return ok


# kind -> (test, what is expected)
KINDS: dict[str, tuple[Callable[[Any], bool], str]] = {
    "str": (lambda v: isinstance(v, str), "a string"),
    "token": (lambda v: isinstance(v, str), "a token string ('' for none)"),
    "bool": (lambda v: isinstance(v, bool), "true or false"),
    "number": (_finite, "a finite number"),
    # bounded so that counts, and the sum of two (nuScenes num_pts), fit an int64 array
    "count": (lambda v: isinstance(v, int) and not isinstance(v, bool) and 0 <= v < 2**62,
              "a non-negative integer below 2**62"),
    "vec3": (_numbers(3), "a list of 3 finite numbers"),
    "size": (_numbers(3, positive=True), "a list of 3 positive finite numbers (w, l, h)"),
    "quat": (_numbers(4, nonzero=True), "a non-zero (w, x, y, z) quaternion of 4 finite numbers"),
    "str_list": (lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v), "a list of strings"),
    "relpath": (lambda v: path_problem(v) is None, "a non-empty relative path without '..'"),
    "object": (lambda v: isinstance(v, dict), "a JSON object"),
}

Fields = Mapping[str, tuple[str, bool]]  # field -> (kind, required)


def short(value: Any, n: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= n else text[: n - 3] + "..."


def check_fields(record: Any, fields: Fields, where: str) -> None:
    """Raises ValueError "{where}: field 'x' ..." for a missing required field or a mistyped one.

    `where` names the file (and record); fields not listed are not looked at."""
    if not isinstance(record, dict):
        raise ValueError(f"{where}: expected a JSON object; got {short(record)}")
    for name, (kind, required) in fields.items():
        test, expected = KINDS[kind]
        if name not in record:
            if required:
                raise ValueError(f"{where}: field {name!r} is missing; expected {expected}")
            continue
        if not test(record[name]):
            raise ValueError(f"{where}: field {name!r} = {short(record[name])}; expected {expected}")
