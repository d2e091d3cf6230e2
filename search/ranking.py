"""Agreement of two rankings: Kendall's tau-b and its exact permutation p-value."""

from __future__ import annotations

import itertools


def kendall_tau(a: list[float], b: list[float]) -> float:
    """Tau-b over paired scores (ties counted as neither concordant nor discordant)."""
    n, conc, disc, ties_a, ties_b = len(a), 0, 0, 0, 0
    for i in range(n):
        for j in range(i + 1, n):
            da, db = a[i] - a[j], b[i] - b[j]
            if da == 0 and db == 0:
                continue
            if da == 0:
                ties_a += 1
            elif db == 0:
                ties_b += 1
            elif (da > 0) == (db > 0):
                conc += 1
            else:
                disc += 1
    denom = ((conc + disc + ties_a) * (conc + disc + ties_b)) ** 0.5
    return (conc - disc) / denom if denom else float("nan")


def tau_p_value(a: list[float], b: list[float], max_n: int = 8) -> float | None:
    """Exact one-sided permutation p-value of tau >= the observed tau (no rank agreement as the
    null); None past max_n candidates. With 6 candidates only tau >= 0.73 has p < 0.05."""
    if len(a) > max_n:
        return None
    observed = kendall_tau(a, b)
    taus = [kendall_tau(a, [b[i] for i in perm]) for perm in itertools.permutations(range(len(b)))]
    return sum(t >= observed - 1e-12 for t in taus) / len(taus)
