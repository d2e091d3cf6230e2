"""The wire format an edge device posts: one frame batch (ego pose + placed objects) per request.

Conventions (the exchange format of issue 25): time is UNIX seconds (UTC); lat/lon are WGS84
degrees, alt metres; heading_deg is the compass heading (clockwise from north); a placed object's
box is [x1, y1, x2, y2] in pixels of the frame, depth_m is along the optical axis and x_m lateral
(right of the optical axis positive). An empty `objects` list is a valid batch: the ego position
still extends the device's track.

Validation is strict so that nothing is stored by accident: numbers must be JSON numbers (not
strings or booleans) and finite, strings must be strings with a non-blank character, unknown keys
are refused (a misspelt field would otherwise vanish silently), and a batch holds at most
MAX_OBJECTS objects. Every number is bounded to what a camera on a vehicle can report: one stored
absurd value (a time in milliseconds, 1e13) would otherwise sit at the top of every "latest" query
and break readers that convert it. The bounds are the module constants below; `time` must lie
between 2000-01-01 and MAX_CLOCK_SKEW_S past the server's clock. `field_errors` turns pydantic's errors into "objects.2.lat: ..." lines, the
form the service answers with.
"""

from __future__ import annotations

import hashlib
import json
import math
import time as _time
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator

MAX_OBJECTS = 1000  # far above any detector's per-frame output; bounds one request's work and size
EARLIEST_TIME_S = 946_684_800.0  # 2000-01-01T00:00:00Z: older than any device that posts here
MAX_CLOCK_SKEW_S = 600.0         # how far a device's clock may run ahead of the server's
ALTITUDE_M = (-500.0, 10_000.0)  # the Dead Sea shore to above any road or airfield
MAX_DEPTH_M = 5_000.0            # a monocular camera resolves nothing this far; bounds the placement
MAX_PIXEL = 100_000.0            # box corners: beyond any sensor's width, with room for unclipped boxes
MAX_OBJECT_RANGE_M = 5_000.0     # an object placed farther than this from its ego is a placement bug
R_EARTH_M = 6_371_008.8
NonBlank = Annotated[str, Field(min_length=1, max_length=256, pattern=r"\S")]
Latitude = Annotated[float, Field(ge=-90.0, le=90.0)]
Longitude = Annotated[float, Field(ge=-180.0, le=180.0)]
Altitude = Annotated[float, Field(ge=ALTITUDE_M[0], le=ALTITUDE_M[1])]
Pixel = Annotated[float, Field(ge=-MAX_PIXEL, le=MAX_PIXEL)]


class _Strict(BaseModel):
    model_config = ConfigDict(strict=True, allow_inf_nan=False, extra="forbid", populate_by_name=True)


class Ego(_Strict):
    lat: Latitude
    lon: Longitude
    alt: Altitude
    heading_deg: Annotated[float, Field(ge=-360.0, le=360.0)]


class PlacedObject(_Strict):
    cls: NonBlank = Field(alias="class")
    score: Annotated[float, Field(ge=0.0, le=1.0)]
    box: Annotated[list[Pixel], Field(min_length=4, max_length=4)]
    depth_m: Annotated[float, Field(gt=0.0, le=MAX_DEPTH_M)]
    x_m: Annotated[float, Field(ge=-MAX_DEPTH_M, le=MAX_DEPTH_M)]
    lat: Latitude
    lon: Longitude
    alt: Altitude

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
    time: Annotated[float, Field(ge=EARLIEST_TIME_S)]
    ego: Ego
    objects: Annotated[list[PlacedObject], Field(max_length=MAX_OBJECTS)]

    @field_validator("time")
    @classmethod
    def _not_in_the_future(cls, t):
        latest = _time.time() + MAX_CLOCK_SKEW_S
        if t > latest:
            hint = (" (it looks like milliseconds: time is UNIX seconds)"
                    if EARLIEST_TIME_S <= t / 1000 <= latest else "")
            raise ValueError(f"{t} is more than {MAX_CLOCK_SKEW_S:.0f} s ahead of the server's clock "
                             f"({_time.time():.0f} UNIX s){hint}")
        return t

    @field_validator("objects")
    @classmethod
    def _objects_near_their_ego(cls, objects, info: ValidationInfo):
        ego = info.data.get("ego")  # absent when the ego failed its own validation (reported there)
        for k, o in enumerate(objects if ego is not None else ()):
            metres = ground_distance_m(ego.lat, ego.lon, o.lat, o.lon)
            if metres > MAX_OBJECT_RANGE_M:
                raise ValueError(f"object {k} is placed {metres:.0f} m from its ego position, at most "
                                 f"{MAX_OBJECT_RANGE_M:.0f} m (lat and lon swapped, or radians?)")
        return objects

    def wire(self) -> dict:
        """The batch as JSON values with the wire names ("class", not "cls")."""
        return self.model_dump(mode="json", by_alias=True)

    def content_hash(self) -> str:
        """SHA-256 of the canonical JSON of the validated batch: a re-post of the same batch hashes
        the same even if its keys come in another order or a score is written 1 instead of 1.0."""
        canonical = json.dumps(self.wire(), sort_keys=True, separators=(",", ":"), allow_nan=False)
        return hashlib.sha256(canonical.encode()).hexdigest()


def ground_distance_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Great-circle distance (haversine on the mean Earth radius): a bound check, not surveying."""
    p1, p2 = math.radians(lat1), math.radians(lat2)
    a = math.sin((p2 - p1) / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(math.radians(lon2 - lon1) / 2) ** 2
    return 2 * R_EARTH_M * math.asin(min(1.0, math.sqrt(a)))


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
