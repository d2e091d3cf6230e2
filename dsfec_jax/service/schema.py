"""The wire format an edge device posts: one frame batch (ego pose + placed objects) per request.

Conventions (the exchange format of issue 25): time is UNIX seconds (UTC); lat/lon are WGS84
degrees, alt metres; heading_deg is the compass heading (clockwise from north); a placed object's
box is [x1, y1, x2, y2] in pixels of the frame, depth_m is along the optical axis and x_m lateral
(right of the optical axis positive). An empty `objects` list is a valid batch: the ego position
still extends the device's track.

Validation is strict so that nothing is stored by accident: numbers must be JSON numbers (not
strings or booleans) and finite, strings must be strings with a non-blank character, unknown keys
are refused (a misspelt field would otherwise vanish silently), and a batch holds at most
MAX_OBJECTS objects. `field_errors` turns pydantic's errors into "objects.2.lat: ..." lines, the
form the service answers with.
"""

from __future__ import annotations

import hashlib
import json
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, field_validator

MAX_OBJECTS = 1000  # far above any detector's per-frame output; bounds one request's work and size
NonBlank = Annotated[str, Field(min_length=1, max_length=256, pattern=r"\S")]
Latitude = Annotated[float, Field(ge=-90.0, le=90.0)]
Longitude = Annotated[float, Field(ge=-180.0, le=180.0)]


class _Strict(BaseModel):
    model_config = ConfigDict(strict=True, allow_inf_nan=False, extra="forbid", populate_by_name=True)


class Ego(_Strict):
    lat: Latitude
    lon: Longitude
    alt: float
    heading_deg: Annotated[float, Field(ge=-360.0, le=360.0)]


class PlacedObject(_Strict):
    cls: NonBlank = Field(alias="class")
    score: Annotated[float, Field(ge=0.0, le=1.0)]
    box: Annotated[list[float], Field(min_length=4, max_length=4)]
    depth_m: Annotated[float, Field(gt=0.0)]
    x_m: float
    lat: Latitude
    lon: Longitude
    alt: float

    @field_validator("box")
    @classmethod
    def _ordered_box(cls, box):
        x1, y1, x2, y2 = box
        if x1 > x2 or y1 > y2:
            raise ValueError(f"box must be [x1, y1, x2, y2] with x1 <= x2 and y1 <= y2, got {box}")
        return box


class FrameBatch(_Strict):
    batch_id: NonBlank
    device: NonBlank
    frame: Annotated[str, Field(max_length=256)]
    time: Annotated[float, Field(ge=0.0)]
    ego: Ego
    objects: Annotated[list[PlacedObject], Field(max_length=MAX_OBJECTS)]

    def wire(self) -> dict:
        """The batch as JSON values with the wire names ("class", not "cls")."""
        return self.model_dump(mode="json", by_alias=True)

    def content_hash(self) -> str:
        """SHA-256 of the canonical JSON of the validated batch: a re-post of the same batch hashes
        the same even if its keys come in another order or a score is written 1 instead of 1.0."""
        canonical = json.dumps(self.wire(), sort_keys=True, separators=(",", ":"), allow_nan=False)
        return hashlib.sha256(canonical.encode()).hexdigest()


def field_errors(errors, drop_prefix=("body",)) -> list[str]:
    """pydantic / FastAPI error dicts -> ["objects.2.lat: Input should be less than or equal to 90", ...].
    FastAPI puts the body's fields under "body", which says nothing to the sender: dropped."""
    lines = []
    for err in errors:
        if err.get("type") == "json_invalid":  # loc is ("body", character offset): say so
            offset = err.get("loc", ("body", "?"))[-1]
            lines.append(f"body: not valid JSON at character {offset} ({(err.get('ctx') or {}).get('error', 'decode error')})")
            continue
        loc = [str(part) for part in err.get("loc", ())]
        if loc[: len(drop_prefix)] == list(drop_prefix):
            loc = loc[len(drop_prefix):]
        msg = str(err.get("msg", "invalid")).removeprefix("Value error, ")
        lines.append(f"{'.'.join(loc) or 'body'}: {msg}")
    return lines
