"""Statistics of RD maps from any source (the simulator, a real TI capture, RADDet, CARRADA), so the
synthetic maps can be set beside real ones. Nothing here needs boxes: box statistics are simply
empty for unlabelled captures.

Per frame:
- noise floor: the median of the map (most cells hold noise only) and its spread, the robust
  standard deviation 1.4826 * MAD (median absolute deviation), in map units and in dB;
- zero-Doppler ridge share: linear power in the zero-velocity column and its `ridge_bins`
  neighbours on each side, over the map's total linear power (a Hann window spreads a static
  return over +-1 column, hence ridge_bins=1 by default);
- map structure (`structure_stats`, dB, for log-power maps): each range row's floor is the median
  over its Doppler columns; the zero-Doppler ridge's excess is the zero-velocity column over its
  row's floor (its median over rows, and the rows where it reaches RIDGE_STRONG_DB); the floor's
  std across rows; its shape: near rows (5-25 % of the range) and the last 5 % of rows against the
  far rows (70-90 %), where an IF high-pass and the anti-alias low-pass show; the map's maximum
  (on real data the Tx->Rx leakage) and its 99th percentile over the median. Rows before
  SKIP_ROWS (range bin 0, which DC removal empties) are left out;
per box:
- size in bins (range rows, Doppler columns), and the peak above the floor: the map's maximum
  inside the box minus the frame's floor, in dB;
- under the ridge: the zero-Doppler ridge in the box's own rows outshines the box's peak (the
  share of such boxes says how often an object must be told from the static returns).
dB: a 'log10' map holds log10(P + 1), so a difference of d is 10 d dB (P >> 1); a 'db' map is in
dB already; a 'normalised' map is not a log-power any more (no dB figures, no linear power).
"""

from __future__ import annotations

import time
from collections.abc import Iterable

import numpy as np

from .classes import RD_CLASSES
from .sample import RDSample

MAD_TO_SD = 1.4826  # robust sd of a Gaussian from its median absolute deviation
RIDGE_STRONG_DB = 30.0  # a row's ridge counts as strong at this excess over the row's floor
SKIP_ROWS = 1  # range bin 0: DC removal empties it, so its floor says nothing about the IF chain
NEAR_ROWS, FAR_ROWS, EDGE_ROWS = (0.05, 0.25), (0.70, 0.90), (0.95, 1.0)  # fractions of the range rows
STRUCTURE_KEYS = ("ridge_excess_db", "strong_ridge_rows", "floor_std_db", "near_minus_far_db",
                  "edge_minus_far_db", "max_minus_median_db", "p99_minus_median_db")


def db_per_unit(scale: str) -> float | None:
    return {"log10": 10.0, "db": 1.0}.get(scale)


def linear_power(power: np.ndarray, scale: str) -> np.ndarray | None:
    if scale == "log10":
        return np.power(10.0, np.asarray(power, np.float64)) - 1.0
    if scale == "db":
        return np.power(10.0, np.asarray(power, np.float64) / 10.0)
    return None


def noise_floor(power: np.ndarray) -> tuple[float, float]:
    """(median, robust sd) of a map, in its units."""
    p = np.asarray(power, np.float64)
    median = float(np.median(p))
    return median, float(MAD_TO_SD * np.median(np.abs(p - median)))


def zero_doppler_share(sample: RDSample, ridge_bins: int = 1) -> float | None:
    lin = linear_power(sample.power, sample.scale)
    if lin is None:
        return None
    zero = int(np.argmin(np.abs(sample.axes.velocity_mps)))
    cols = np.abs(np.arange(lin.shape[1]) - zero) <= ridge_bins
    total = float(lin.sum())
    return float(lin[:, cols].sum() / total) if total > 0 else 0.0


def _band(floors: np.ndarray, fractions: tuple[float, float]) -> float:
    n = len(floors)
    lo, hi = int(round(fractions[0] * n)), max(int(round(fractions[1] * n)), int(round(fractions[0] * n)) + 1)
    return float(np.median(floors[lo:hi]))


def structure_stats(sample: RDSample) -> dict | None:
    """The map's structure in dB (module docstring): ridge, floor shape, peak; None for a
    'normalised' map, which is no log-power."""
    per_db = db_per_unit(sample.scale)
    if per_db is None:
        return None
    power = np.asarray(sample.power, np.float64) * per_db
    rows = power[SKIP_ROWS:]
    floors = np.median(rows, axis=1)
    zero = int(np.argmin(np.abs(sample.axes.velocity_mps)))
    excess = rows[:, zero] - floors
    far = _band(floors, FAR_ROWS)
    median = float(np.median(power))
    return dict(ridge_excess_db=float(np.median(excess)), strong_ridge_rows=int(np.sum(excess >= RIDGE_STRONG_DB)),
                rows=int(len(rows)), floor_std_db=float(np.std(floors)),
                near_minus_far_db=_band(floors, NEAR_ROWS) - far, edge_minus_far_db=_band(floors, EDGE_ROWS) - far,
                max_minus_median_db=float(power.max()) - median,
                p99_minus_median_db=float(np.percentile(power, 99)) - median)


def _box_cells(sample: RDSample):
    """(rows, columns) slices of each box: the cells it covers, at least one of each."""
    for x1, y1, x2, y2 in np.asarray(sample.boxes.xyxy):
        r0, c0 = int(np.floor(y1)), int(np.floor(x1))
        yield slice(r0, max(int(np.ceil(y2)), r0 + 1)), slice(c0, max(int(np.ceil(x2)), c0 + 1))


def box_peaks_db(sample: RDSample, floor: float) -> np.ndarray:
    """Per box: max of the map inside it minus the floor, in dB (NaN for 'normalised' maps)."""
    per_db = db_per_unit(sample.scale)
    out = np.full(len(sample.boxes), np.nan)
    for i, (rows, cols) in enumerate(_box_cells(sample)):
        cell = sample.power[rows, cols]
        if per_db is not None and cell.size:
            out[i] = (float(cell.max()) - floor) * per_db
    return out


def boxes_under_ridge(sample: RDSample, ridge_bins: int = 1) -> np.ndarray:
    """Per box: whether the zero-Doppler ridge (+-ridge_bins columns) in the box's own rows is
    stronger than the box's peak, i.e. the object has to be told from the static returns."""
    power = np.asarray(sample.power)
    zero = int(np.argmin(np.abs(sample.axes.velocity_mps)))
    ridge = slice(max(zero - ridge_bins, 0), zero + ridge_bins + 1)
    out = np.zeros(len(sample.boxes), bool)
    for i, (rows, cols) in enumerate(_box_cells(sample)):
        cell = power[rows, cols]
        if cell.size and power[rows, ridge].size:
            out[i] = power[rows, ridge].max() > cell.max()
    return out


def _summary(x) -> dict | None:
    x = np.asarray(x, np.float64)
    x = x[np.isfinite(x)]
    if not len(x):
        return None
    return dict(median=float(np.median(x)), p10=float(np.percentile(x, 10)), p90=float(np.percentile(x, 90)),
                count=int(len(x)))


def _objects_in(sample: RDSample) -> np.ndarray:
    """Class names of the objects (a box split at the Doppler edge is one object when the source
    says so through meta['box_object'])."""
    names = np.asarray(sample.boxes.names)
    owner = sample.meta.get("box_object")
    if owner is None or len(owner) != len(names):
        return names
    _, first = np.unique(np.asarray(owner), return_index=True)
    return names[np.sort(first)]


def dataset_stats(samples: Iterable[RDSample], classes=RD_CLASSES, ridge_bins: int = 1) -> dict:
    floors, spreads, shares, objects, heights, widths, names, peaks, under = [], [], [], [], [], [], [], [], []
    scales = set()
    for s in samples:
        scales.add(s.scale)
        floor, spread = noise_floor(s.power)
        floors.append(floor)
        spreads.append(spread)
        shares.append(zero_doppler_share(s, ridge_bins))
        objects.append(_objects_in(s))
        wh = np.asarray(s.boxes.wh, np.float64).reshape(-1, 2)
        widths.append(wh[:, 0])
        heights.append(wh[:, 1])
        names.append(np.asarray(s.boxes.names))
        peaks.append(box_peaks_db(s, floor))
        under.append(boxes_under_ridge(s, ridge_bins))
    if not floors:
        raise ValueError("dataset_stats: no samples")
    n = len(floors)
    per_db = db_per_unit(scales.pop()) if len(scales) == 1 else None
    names, heights, widths = np.concatenate(names), np.concatenate(heights), np.concatenate(widths)
    all_objects = np.concatenate(objects)
    counts = np.array([len(o) for o in objects])
    floor_db = None if per_db is None else dict(median=float(np.median(floors)) * per_db,
                                                robust_sd=float(np.median(spreads)) * per_db)
    return dict(
        frames=n,
        empty_frame_share=float(np.mean(counts == 0)),
        objects_per_frame=dict(all=float(counts.mean()),
                               **{c: float(np.sum(all_objects == c) / n) for c in classes}),
        boxes=int(len(names)),
        box_range_bins=_summary(heights),
        box_doppler_bins=_summary(widths),
        box_bins_by_class={c: dict(range=_summary(heights[names == c]), doppler=_summary(widths[names == c]))
                           for c in classes if np.any(names == c)},
        noise_floor=dict(median=float(np.median(floors)), robust_sd=float(np.median(spreads)), db=floor_db),
        peak_above_floor_db=_summary(np.concatenate(peaks)),
        boxes_under_ridge=float(np.concatenate(under).mean()) if len(names) else None,
        zero_doppler_share=None if any(x is None for x in shares) else _summary(shares),
        ridge_bins=ridge_bins,
    )


def _fmt(summary: dict | None, unit: str = "", digits: int = 1) -> str:
    if summary is None:
        return "-"
    return (f"{summary['median']:.{digits}f}{unit} [{summary['p10']:.{digits}f}, {summary['p90']:.{digits}f}]")


def stats_rows(s: dict) -> list[tuple[str, str]]:
    """(label, value) rows of one source's statistics; medians with [p10, p90]."""
    floor = s["noise_floor"]
    db = floor["db"]
    rows = [("frames", str(s["frames"])), ("empty frames", f"{s['empty_frame_share']:.0%}"),
            ("objects / frame", f"{s['objects_per_frame']['all']:.2f}")]
    rows += [(f"  {c} / frame", f"{v:.2f}") for c, v in s["objects_per_frame"].items() if c != "all"]
    rows += [("box range bins", _fmt(s["box_range_bins"], digits=0)),
             ("box Doppler bins", _fmt(s["box_doppler_bins"], digits=0)),
             ("noise floor (map units)", f"{floor['median']:.3f} (robust sd {floor['robust_sd']:.3f})"),
             ("noise floor (dB)", "-" if db is None else f"{db['median']:.1f} (robust sd {db['robust_sd']:.2f})"),
             ("peak above floor (dB)", _fmt(s["peak_above_floor_db"])),
             ("boxes under the ridge", "-" if s["boxes_under_ridge"] is None else f"{s['boxes_under_ridge']:.1%}"),
             (f"zero-Doppler share (+-{s['ridge_bins']} col)", _fmt(s["zero_doppler_share"], digits=3))]
    return rows


def format_stats_table(named: dict[str, dict]) -> str:
    """Several sources side by side: {'rd-synthetic val': stats, 'ti-adc': stats} -> text table."""
    columns = {name: dict(stats_rows(s)) for name, s in named.items()}
    return _side_by_side(columns, list(dict.fromkeys(label for s in named.values() for label, _ in stats_rows(s))))


def _side_by_side(columns: dict[str, dict[str, str]], labels: list[str]) -> str:
    """A text table: one row per label, one column per source ('-' where a source has no value)."""
    width = max(map(len, labels)) + 2
    cols = [max(len(name), *(len(c.get(label, "-")) for label in labels)) + 2 for name, c in columns.items()]
    lines = [" " * width + "".join(f"{name:>{w}}" for name, w in zip(columns, cols))]
    for label in labels:
        lines.append(f"{label:<{width}}" + "".join(f"{c.get(label, '-'):>{w}}" for c, w in zip(columns.values(), cols)))
    return "\n".join(lines)


def structure_summary(samples: Iterable[RDSample]) -> dict | None:
    """p10 / median / p90 over maps of each `structure_stats` figure (None: no log-power map)."""
    per_map = [x for x in map(structure_stats, samples) if x is not None]
    if not per_map:
        return None
    out = {key: _summary([m[key] for m in per_map]) for key in STRUCTURE_KEYS}
    out["rows"] = int(np.median([m["rows"] for m in per_map]))
    return out


STRUCTURE_LABELS = {
    "ridge_excess_db": "zero-Doppler ridge over row floor, median row (dB)",
    "strong_ridge_rows": f"rows with ridge >= {RIDGE_STRONG_DB:.0f} dB over floor",
    "floor_std_db": "floor std across rows (dB)",
    "near_minus_far_db": "floor near (5-25 %) - far (70-90 %) (dB)",
    "edge_minus_far_db": "floor last 5 % of rows - far (dB)",
    "max_minus_median_db": "map max - median (dB)",
    "p99_minus_median_db": "p99 - median (dB)",
}


def format_structure_table(named: dict[str, dict | None]) -> str:
    """Map structure of several sources side by side: medians with [p10, p90] over maps (a single
    map shows its value); the ridge row count says of how many rows."""
    columns = {name: {} if s is None else {label: _structure_cell(s, key) for key, label in STRUCTURE_LABELS.items()}
               for name, s in named.items()}
    return _side_by_side(columns, list(STRUCTURE_LABELS.values()))


def _structure_cell(s: dict, key: str) -> str:
    x, digits = s[key], 0 if key == "strong_ridge_rows" else 1
    value = f"{x['median']:.{digits}f}" if x["count"] == 1 else _fmt(x, digits=digits)
    return value + (f" of {s['rows']}" if key == "strong_ridge_rows" else "")


def generation_rate(make, count: int = 100) -> float:
    """Maps per second of `make(index)` over `count` calls in this process, after one warm-up call
    (run under `taskset -c 0` for a per-core figure; numpy's FFT is single-threaded)."""
    make(0)
    start = time.perf_counter()
    for i in range(count):
        make(i)
    return count / (time.perf_counter() - start)
