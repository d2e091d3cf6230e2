"""A timing's spread over its repetitions: the median with the 10th and 90th percentiles, and how
each command prints it ("27.4 (25.1-31.0)").

Every latency a command reports carries its spread, so a reader sees at once whether the repeats
agreed (a tight interval on an idle machine) or a noisy neighbour scattered them.
"""

from __future__ import annotations

import numpy as np


def percentiles(values, digits: int = 3) -> dict:
    """{'median', 'p10', 'p90'} of `values` (repetitions of one timing), rounded to `digits`."""
    v = np.asarray(list(values), dtype=float)
    if v.size == 0:
        raise ValueError("no repetitions to summarise")
    p10, med, p90 = np.percentile(v, [10, 50, 90])
    return {"median": round(float(med), digits), "p10": round(float(p10), digits), "p90": round(float(p90), digits)}


def text(median: float, p10: float | None, p90: float | None, digits: int = 1) -> str:
    """'median (p10-p90)'; 'median (p90 X)' when only the 90th percentile is known (older records)."""
    if p10 is None and p90 is None:
        return f"{median:.{digits}f}"
    if p10 is None:
        return f"{median:.{digits}f} (p90 {p90:.{digits}f})"
    return f"{median:.{digits}f} ({p10:.{digits}f}-{p90:.{digits}f})"
