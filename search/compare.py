"""How well a cheap strategy ranks candidates against full training, and what it costs:
python -m search.compare RUN_TRAIN RUN_ONESHOT  (Kendall tau of the Car-mAP rankings, cost ratio)."""

from __future__ import annotations

import json
import sys

from .journal import Journal
from .ranking import kendall_tau, tau_p_value
from .report import headline, rows


def compare(run_a: str, run_b: str) -> dict:
    """Kendall tau of the two runs' rankings by their headline score (DSFEC: Car mAP; RadarNeXt:
    VoD mAP) over the candidates both finished, and their costs."""
    records_a = Journal(run_a).records()
    score, _ = headline(records_a)
    ra = {r["label"]: r for r in rows(records_a)}
    rb = {r["label"]: r for r in rows(Journal(run_b).records())}
    labels = [lbl for lbl in ra if lbl in rb and ra[lbl].get(score) is not None and rb[lbl].get(score) is not None]
    if len(labels) < 2:
        raise ValueError(f"{run_a} and {run_b} share fewer than two finished candidates")
    def cost(run, key):  # summed over the trials both runs share
        return sum(r.get(key) or 0 for r in Journal(run).records() if r["label"] in labels)

    a_scores, b_scores = [ra[x][score] for x in labels], [rb[x][score] for x in labels]
    out = {"candidates": labels, "kendall_tau": kendall_tau(a_scores, b_scores),
           "p_value": tau_p_value(a_scores, b_scores), score: {x: [ra[x][score], rb[x][score]] for x in labels}}
    for key in ("wall_s", "cpu_s"):  # CPU seconds are the fairer cost when the machine is shared
        a, b = cost(run_a, key), cost(run_b, key)
        out[key] = {"a": round(a, 1), "b": round(b, 1)}
        out[f"{key.split('_')[0]}_ratio_b_over_a"] = round(b / a, 4) if a else None
    return out


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        sys.exit("usage: python -m search.compare RUN_A RUN_B")
    print(json.dumps(compare(*argv), indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
