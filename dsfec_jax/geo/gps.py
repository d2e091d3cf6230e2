"""The ego's GPS track: reading fixes, skipping (or refusing) bad ones, and the ego's position and
heading at any frame time.

Conventions:
- A fix is (time_s, lat, lon, alt): seconds (any epoch: since the drive's start or UNIX time, as
  long as the frames use the same one), WGS84 degrees and ellipsoidal height in metres. The paper's
  module gives one fix a second (shuffle_yolov3_edge.txt §3.3); frames come faster.
- Bad fixes (`clean_fixes`): a value that is NaN or infinite, a latitude outside [-90, 90], a
  longitude outside [-180, 180], and a timestamp that does not increase. The kept fixes are a
  longest strictly increasing subsequence of timestamps among the valid ones: a single wild timestamp
  (a jump forward and back) costs one fix, where "drop whatever is not later than the last kept
  fix" would drop every fix after it. Each skipped fix is counted by reason in a `FixReport`;
  strict=True raises instead, naming the file, the row and the field.
- `EgoTrack` turns fixes into a local East-North-Up frame (geodesy.py; origin: the first fix by
  default) and interpolates the position linearly in time between the two fixes around a frame.
  Heading is a compass angle in radians, clockwise from north: forward = (sin h, cos h) in (E, N),
  the convention of data/camera/street/camera.py. It comes from the track itself: each segment
  between consecutive fixes has the chord heading atan2(dE, dN). With `heading="midpoint"` (the
  default) that heading belongs to the segment's middle time and frames between two middles get
  the linear blend (the chord of a curve is parallel to the tangent at its middle, so this tracks
  a turning ego better than holding one chord heading for the whole second; the measured errors
  are in docs/edge-and-map-service.md); `heading="chord"` holds the chord heading over its segment.
  `heading_span` = k draws each segment's chord from fix i - k to fix i + 1 + k instead: noisy
  fixes move a chord's ends by their noise, so a longer chord turns less with it, at the price
  of cutting corners (k = 0, the default, is exact for clean fixes; k = 1 or 2 for metre-level
  noise).
- A segment shorter than `min_move_m` is stationary: its chord direction is noise, so the ego
  keeps its last moving heading; a track that starts stationary takes its first moving heading
  backwards. A track that never moves has no heading (asking for one raises).
- Coverage: a time outside [first fix, last fix], or inside a segment longer than `max_gap_s`
  (missing fixes: interpolating across them guesses the path), is not covered. `position` and
  `heading` raise on uncovered times; `covered` tells a caller which frames to skip and count.
- Headings are relative to the local frame's grid north, which is true north at the origin and
  turns by the meridian convergence away from it (0.01 deg per km east at 49 deg N): negligible
  for a drive, and the first-fix origin keeps it so. Placement is the same in any origin's frame
  (heading and positions turn together): the street benchmark's test drives lie ~40 km east of
  its world origin, where its grid headings are 0.4 deg off a first-fix track's, and the placed
  objects agree to 1 mm.
"""

from __future__ import annotations

import bisect
import csv
import dataclasses
import io
import json
import math
from pathlib import Path

import numpy as np

from ..core import atomic
from .geodesy import enu_to_geodetic, geodetic_to_enu

FIELDS = ("time_s", "lat", "lon", "alt")
REASONS = ("not_finite", "latitude", "longitude", "time_order")


@dataclasses.dataclass(frozen=True)
class GpsFixes:
    """(F,) float64 arrays, and where each fix came from (for error messages): `source` (a file
    name) and `rows` (its CSV line number, JSON item index or plain index, named by `row_name`)."""

    time_s: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    alt: np.ndarray
    source: str = "<fixes>"
    rows: np.ndarray | None = None
    row_name: str = "fix"

    def __post_init__(self):
        arrays = [np.asarray(getattr(self, f), np.float64).reshape(-1) for f in FIELDS]
        if len({len(a) for a in arrays}) != 1:
            raise ValueError(f"{self.source}: time_s, lat, lon, alt have lengths {[len(a) for a in arrays]}; "
                             "expected one value of each per fix")
        for name, a in zip(FIELDS, arrays):
            object.__setattr__(self, name, a)
        rows = np.arange(len(arrays[0])) if self.rows is None else np.asarray(self.rows, np.int64).reshape(-1)
        if len(rows) != len(arrays[0]):
            raise ValueError(f"{self.source}: {len(rows)} row numbers for {len(arrays[0])} fixes")
        object.__setattr__(self, "rows", rows)

    def __len__(self) -> int:
        return len(self.time_s)

    def where(self, k: int) -> str:
        return f"{self.source} {self.row_name} {int(self.rows[k])}"

    def select(self, keep) -> "GpsFixes":
        return dataclasses.replace(self, **{f: getattr(self, f)[keep] for f in FIELDS}, rows=self.rows[keep])

    @classmethod
    def from_track(cls, track, source: str = "<track>") -> "GpsFixes":
        """From anything with time_s, lat, lon, alt arrays (data/camera/street's GpsTrack)."""
        return cls(*(np.asarray(getattr(track, f)) for f in FIELDS), source=source)


@dataclasses.dataclass(frozen=True)
class FixReport:
    """What `clean_fixes` kept and skipped: counts by reason (REASONS order) and the first few
    skipped fixes, each as 'where: field = value; why'."""

    source: str
    total: int
    kept: int
    skipped: dict
    examples: tuple = ()

    @property
    def num_skipped(self) -> int:
        return self.total - self.kept

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def __str__(self) -> str:
        why = ", ".join(f"{n} {r}" for r, n in self.skipped.items() if n) or "none"
        return f"{self.source}: kept {self.kept} of {self.total} GPS fixes (skipped: {why})"


# --------------------------------------------------------------------------- reading


def read_gps(path) -> GpsFixes:
    """Fixes from a CSV file with a header naming time_s, lat, lon, alt (any order, other columns
    ignored) or a JSON list of objects with those keys. An empty cell or a JSON null reads as NaN
    (a receiver without a fix: `clean_fixes` skips it); text that is not a number is an error
    naming the file, the row and the field."""
    path = Path(path)
    try:
        text = path.read_text().removeprefix("\ufeff")   # a spreadsheet's byte-order mark is not a column name
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"{path}: cannot read the GPS file ({e})") from None
    if text.lstrip().startswith("["):
        return _read_json(text, str(path))
    return _read_csv(text, str(path))


def _number(value, where: str, field: str) -> float:
    if value is None or (isinstance(value, str) and not value.strip()):
        return math.nan
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ValueError(f"{where}: {field} = {value!r}; expected a number")
    try:
        return float(value)
    except ValueError:
        raise ValueError(f"{where}: {field} = {value!r}; expected a number") from None


def _read_csv(text: str, source: str) -> GpsFixes:
    reader = csv.reader(io.StringIO(text))
    header = [h.strip() for h in next(reader, [])]
    missing = [f for f in FIELDS if f not in header]
    if missing:
        raise ValueError(f"{source} line 1: header {header} lacks {missing}; expected the columns "
                         f"{','.join(FIELDS)}")
    cols = [header.index(f) for f in FIELDS]
    values, rows = [], []
    for row in reader:
        line = reader.line_num
        if not row or not "".join(row).strip():
            continue
        if len(row) != len(header):
            raise ValueError(f"{source} line {line}: {len(row)} values; expected {len(header)} ({','.join(header)})")
        values.append([_number(row[c], f"{source} line {line}", f) for c, f in zip(cols, FIELDS)])
        rows.append(line)
    v = np.array(values, np.float64).reshape(-1, 4)
    return GpsFixes(*v.T, source=source, rows=np.array(rows, np.int64), row_name="line")


def _read_json(text: str, source: str) -> GpsFixes:
    try:
        items = json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"{source}: not valid JSON ({e})") from None
    if not isinstance(items, list):
        raise ValueError(f"{source}: expected a JSON list of fixes")
    values = []
    for k, item in enumerate(items):
        where = f"{source} item {k}"
        if not isinstance(item, dict):
            raise ValueError(f"{where}: expected an object with keys {list(FIELDS)}")
        missing = [f for f in FIELDS if f not in item]
        if missing:
            raise ValueError(f"{where}: missing {missing}; expected keys {list(FIELDS)}")
        values.append([_number(item[f], where, f) for f in FIELDS])
    v = np.array(values, np.float64).reshape(-1, 4)
    return GpsFixes(*v.T, source=source, rows=np.arange(len(values)), row_name="item")


def write_gps_csv(path, fixes: GpsFixes) -> None:
    """The CSV `read_gps` reads (header time_s,lat,lon,alt; full float64 precision), atomically."""
    lines = [",".join(FIELDS)] + [",".join(repr(float(v)) for v in row)
                                  for row in zip(*(getattr(fixes, f) for f in FIELDS))]
    atomic.write_text(path, "\n".join(lines) + "\n")


# --------------------------------------------------------------------------- cleaning


def _value_problems(fixes: GpsFixes) -> list[tuple[int, str, str]]:
    """(index, reason, message) of each fix with a bad value, at most one per fix, in row order."""
    out = []
    for k in range(len(fixes)):
        vals = {f: float(getattr(fixes, f)[k]) for f in FIELDS}
        bad = [f for f, v in vals.items() if not math.isfinite(v)]
        if bad:
            out.append((k, "not_finite", f"{bad[0]} = {vals[bad[0]]}; expected a finite number"))
        elif not -90.0 <= vals["lat"] <= 90.0:
            out.append((k, "latitude", f"lat = {vals['lat']}; expected a latitude in [-90, 90] degrees"))
        elif not -180.0 <= vals["lon"] <= 180.0:
            out.append((k, "longitude", f"lon = {vals['lon']}; expected a longitude in [-180, 180] degrees"))
    return out


def _longest_increasing(times: np.ndarray) -> np.ndarray:
    """Indices of a longest strictly increasing subsequence (patience sorting, O(n log n))."""
    tails, tail_idx, prev = [], [], np.full(len(times), -1)
    for i, t in enumerate(times):
        j = bisect.bisect_left(tails, t)
        if j == len(tails):
            tails.append(t)
            tail_idx.append(i)
        else:
            tails[j], tail_idx[j] = t, i
        prev[i] = tail_idx[j - 1] if j else -1
    out, i = [], tail_idx[-1] if tail_idx else -1
    while i >= 0:
        out.append(i)
        i = prev[i]
    return np.array(out[::-1], np.int64)


def clean_fixes(fixes: GpsFixes, strict: bool = False) -> tuple[GpsFixes, FixReport]:
    """The usable fixes and what was skipped (module docstring); strict=True raises ValueError at
    the first bad fix in row order instead of skipping it."""
    problems = _value_problems(fixes)
    if strict and problems:
        k, _, msg = problems[0]
        raise ValueError(f"{fixes.where(k)}: {msg}")
    valid = np.ones(len(fixes), bool)
    valid[[k for k, _, _ in problems]] = False
    idx = np.flatnonzero(valid)
    if strict:
        back = np.flatnonzero(np.diff(fixes.time_s[idx]) <= 0)
        if len(back):
            a, b = idx[back[0]], idx[back[0] + 1]
            raise ValueError(f"{fixes.where(b)}: time_s = {fixes.time_s[b]} is not after {fixes.time_s[a]} "
                             f"({fixes.where(a)}); expected increasing timestamps")
    keep = idx[_longest_increasing(fixes.time_s[idx])]
    dropped = np.setdiff1d(idx, keep)
    problems += [(int(k), "time_order", f"time_s = {fixes.time_s[k]} breaks the increasing order of the timestamps")
                 for k in dropped]
    problems.sort()
    counts = {r: sum(1 for _, why, _ in problems if why == r) for r in REASONS}
    report = FixReport(fixes.source, len(fixes), len(keep), counts,
                       tuple(f"{fixes.where(k)}: {msg}" for k, _, msg in problems[:5]))
    return fixes.select(keep), report


# --------------------------------------------------------------------------- the ego track


@dataclasses.dataclass(frozen=True)
class EgoState:
    """The ego at one frame time: local ENU (m), WGS84, compass heading (rad)."""

    time_s: float
    enu: tuple
    lat: float
    lon: float
    alt: float
    heading_rad: float

    @property
    def heading_deg(self) -> float:
        return math.degrees(self.heading_rad) % 360.0

    def to_dict(self) -> dict:
        """The exchange format's "ego" object."""
        return {"lat": self.lat, "lon": self.lon, "alt": self.alt, "heading_deg": self.heading_deg}


HEADING_MODES = ("midpoint", "chord")


class EgoTrack:
    """Clean fixes in a local ENU frame, read at any covered time (module docstring)."""

    def __init__(self, fixes: GpsFixes, origin=None, *, min_move_m: float = 1.0, max_gap_s: float = 3.0,
                 heading: str = "midpoint", heading_span: int = 0):
        if len(fixes) < 2:
            raise ValueError(f"{fixes.source}: EgoTrack needs at least 2 fixes; got {len(fixes)}")
        if _value_problems(fixes) or np.any(np.diff(fixes.time_s) <= 0):
            raise ValueError(f"{fixes.source}: EgoTrack needs clean fixes (finite, in range, increasing time); "
                             "pass them through clean_fixes first")
        if heading not in HEADING_MODES:
            raise ValueError(f"heading={heading!r}; expected one of {HEADING_MODES}")
        if not (min_move_m >= 0 and max_gap_s > 0 and int(heading_span) == heading_span >= 0):
            raise ValueError(f"min_move_m={min_move_m} >= 0, max_gap_s={max_gap_s} > 0 and heading_span="
                             f"{heading_span} a whole number >= 0")
        self.heading_span = int(heading_span)
        self.fixes, self.heading_mode = fixes, heading
        self.origin = tuple(float(v) for v in (origin if origin is not None
                                               else (fixes.lat[0], fixes.lon[0], fixes.alt[0])))
        self.time_s = fixes.time_s
        self.enu = geodetic_to_enu(fixes.lat, fixes.lon, fixes.alt, self.origin)  # (F, 3)
        self.min_move_m, self.max_gap_s = float(min_move_m), float(max_gap_s)
        self.gap = np.diff(self.time_s) > self.max_gap_s                           # (F - 1,)
        self.segment_heading = self._segment_headings()                           # (F - 1,) unwrapped, or None

    def _segment_headings(self) -> np.ndarray | None:
        """Chord heading per segment, from fix i - span to fix i + 1 + span (clipped to the track);
        stationary segments and chords across a gap carry the last moving heading forward (the
        first moving one backward). None when no segment moves."""
        n, k = len(self.time_s), self.heading_span
        a, b = np.maximum(np.arange(n - 1) - k, 0), np.minimum(np.arange(n - 1) + 1 + k, n - 1)
        d = self.enu[b, :2] - self.enu[a, :2]
        gaps = np.concatenate([[0], np.cumsum(self.gap)])
        moving = (np.hypot(d[:, 0], d[:, 1]) >= max(self.min_move_m, 1e-9)) & (gaps[b] == gaps[a])
        if not moving.any():
            return None
        src = np.where(moving, np.arange(len(d)), -1)
        src = np.maximum.accumulate(src)                      # last moving segment at or before each
        src[src < 0] = np.flatnonzero(moving)[0]              # before the first: the first moving one
        return np.unwrap(np.arctan2(d[:, 0], d[:, 1])[src])

    # ---- coverage

    def _segment(self, t: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(self.time_s, t, side="right") - 1, 0, len(self.time_s) - 2)

    def covered(self, times) -> np.ndarray:
        """Bool per time: inside the fixes' span and not inside a gap longer than max_gap_s."""
        t = np.asarray(times, np.float64)
        inside = np.isfinite(t) & (t >= self.time_s[0]) & (t <= self.time_s[-1])
        seg = self._segment(np.where(inside, t, self.time_s[0]))
        return inside & (~self.gap[seg] | (t == self.time_s[seg]))  # a fix's own time is known

    def _checked(self, times) -> np.ndarray:
        t = np.asarray(times, np.float64)
        ok = self.covered(t)
        if not ok.all():
            bad = np.atleast_1d(t)[~np.atleast_1d(ok)]
            raise ValueError(f"{self.fixes.source}: {bad.size} time(s) not covered by the GPS track (first: "
                             f"{bad[:3].tolist()}); the fixes span [{self.time_s[0]}, {self.time_s[-1]}] s with "
                             f"{int(self.gap.sum())} gap(s) longer than {self.max_gap_s} s "
                             "(use covered() to skip them)")
        return t

    # ---- reading

    def position(self, times) -> np.ndarray:
        """(..., 3) ENU metres, linear in time between the two fixes around each time."""
        t = self._checked(times)
        return np.stack([np.interp(t, self.time_s, self.enu[:, k]) for k in range(3)], -1)

    def heading(self, times) -> np.ndarray:
        """(...) compass heading in [0, 2 pi) radians (module docstring)."""
        t = self._checked(times)
        if self.segment_heading is None:
            raise ValueError(f"{self.fixes.source}: the ego never moves {self.min_move_m} m between two fixes, "
                             "so the track gives no heading")
        if self.heading_mode == "chord":
            h = self.segment_heading[self._segment(t)]
        else:
            middle = 0.5 * (self.time_s[1:] + self.time_s[:-1])
            h = np.interp(t, middle, self.segment_heading)    # constant before the first / after the last middle
        return np.mod(h, 2 * math.pi)

    def state(self, time_s: float) -> EgoState:
        enu = self.position(float(time_s))
        lat, lon, alt = enu_to_geodetic(enu, self.origin)
        return EgoState(float(time_s), tuple(float(v) for v in enu), float(lat), float(lon), float(alt),
                        float(self.heading(float(time_s))))
