"""The nuScenes AP on resampled evaluation sets, for bootstrap confidence intervals.

A prediction's match in the devkit's greedy matching depends only on the ground truth and the
higher-scored predictions *of its own sample*, so whether it is a true positive does not change when
other samples are added, dropped or repeated. A `MatchTable` keeps, for one class, every prediction's
sample, score and hit flag at each threshold, plus the ground-truth count per sample; from it the AP of
any multiset of the samples (a bootstrap resample) follows exactly, without matching again: repeat each
prediction as often as its sample is drawn (copies stay adjacent in score order) and rebuild the
precision curve. With every sample drawn once it is `nuscenes.evaluate`'s AP to the last bit.

The same table holds a COCO class (metrics.boxes2d.coco_matches: `kind` "coco", IoU thresholds, images
as samples); `table_ap` scores either kind with its own AP.
"""

from __future__ import annotations

import base64
import dataclasses
import io
from typing import Mapping, Sequence

import numpy as np

from . import nuscenes

KINDS = ("nuscenes", "coco")


@dataclasses.dataclass(frozen=True)
class MatchTable:
    """One class: predictions in the evaluator's order (highest score first) with their hit flags."""

    class_name: str
    samples: tuple[str, ...]   # sample tokens; `sample_of` and `npos` index them
    npos: np.ndarray           # (S,) ground-truth boxes of the class per sample (after the filters)
    sample_of: np.ndarray      # (P,) the sample of each prediction
    scores: np.ndarray         # (P,)
    thresholds: tuple[float, ...]  # nuScenes: centre distances (m); COCO: IoUs
    is_tp: np.ndarray          # (T, P) bool: a hit at each threshold
    kind: str = "nuscenes"     # whose AP the table resamples: "nuscenes" or "coco"

    def to_bytes(self) -> bytes:
        buf = io.BytesIO()
        # the rows are stored in score order, so the AP never reads the scores: float32 is plenty
        np.savez_compressed(buf, class_name=self.class_name, samples=np.array(self.samples),
                            npos=self.npos.astype(np.int32), sample_of=self.sample_of.astype(np.int32),
                            scores=self.scores.astype(np.float32), dist_ths=np.array(self.thresholds),
                            is_tp=self.is_tp, kind=self.kind)  # "dist_ths": the key of older journals
        return buf.getvalue()

    def to_text(self) -> str:
        """base64 of `to_bytes`, to travel inside a JSON record."""
        return base64.b64encode(self.to_bytes()).decode("ascii")

    @classmethod
    def from_text(cls, text: str, source: str = "<text>") -> "MatchTable":
        try:
            data = base64.b64decode(text.encode("ascii"), validate=True)
        except (ValueError, UnicodeEncodeError) as err:
            raise ValueError(f"{source}: not a base64 match table ({err})") from err
        return cls.from_bytes(data, source)

    @classmethod
    def from_bytes(cls, data: bytes, source: str = "<bytes>") -> "MatchTable":
        try:
            z = np.load(io.BytesIO(data))
            table = cls(str(z["class_name"]), tuple(str(s) for s in z["samples"]), z["npos"], z["sample_of"],
                        z["scores"], tuple(float(t) for t in z["dist_ths"]), z["is_tp"].astype(bool),
                        str(z["kind"]) if "kind" in z.files else "nuscenes")
        except (KeyError, ValueError, OSError) as err:
            raise ValueError(f"{source}: not a match table ({err})") from err
        p = len(table.scores)
        if table.kind not in KINDS:
            raise ValueError(f"{source}: match table kind {table.kind!r}; expected one of {KINDS}")
        if table.is_tp.shape != (len(table.thresholds), p) or table.sample_of.shape != (p,) or \
                table.npos.shape != (len(table.samples),):
            raise ValueError(f"{source}: inconsistent match table shapes (is_tp {table.is_tp.shape}, "
                             f"{p} scores, {len(table.samples)} samples, npos {table.npos.shape})")
        return table


def match_table(gt: Mapping, pred: Mapping, class_name: str, dist_ths: Sequence[float] = nuscenes.DIST_THS,
                **filters) -> MatchTable:
    """Match one class as `nuscenes.evaluate` does (same filters, same `filters` keywords) and keep the
    per-prediction outcome."""
    gt, pred = nuscenes.prepare(gt, pred, **filters)
    cc = nuscenes.class_candidates(gt, pred, class_name, max(dist_ths))
    samples = tuple(gt)
    index = {tok: i for i, tok in enumerate(samples)}
    npos = np.array([len(cc.gts.get(tok, [])) for tok in samples], np.int64)
    sample_of = np.array([index[tok] for tok, _ in cc.preds], np.int64)
    scores = np.array([b["detection_score"] for _, b in cc.preds], float)
    is_tp = np.stack([nuscenes.greedy_match(cc, class_name, float(th))[0] for th in dist_ths]).astype(bool) \
        if cc.preds else np.zeros((len(dist_ths), 0), bool)
    return MatchTable(class_name, samples, npos, sample_of, scores, tuple(float(t) for t in dist_ths), is_tp)


def resampled_ap(table: MatchTable, counts: np.ndarray | None = None) -> np.ndarray:
    """(T,) AP at each threshold on the multiset where sample s appears counts[s] times (default: once)."""
    counts = np.ones(len(table.samples), np.int64) if counts is None else np.asarray(counts, np.int64)
    if counts.shape != (len(table.samples),):
        raise ValueError(f"counts has shape {counts.shape}; the table has {len(table.samples)} samples")
    npos = int(counts @ table.npos)
    if table.kind != "nuscenes":
        raise ValueError(f"resampled_ap scores nuScenes tables; this one is {table.kind!r} (use table_ap)")
    out = np.zeros(len(table.thresholds))
    if npos == 0:
        return out  # the devkit's no_predictions: AP 0
    rows = np.repeat(np.arange(len(table.scores)), counts[table.sample_of])
    recall_points = np.linspace(0, 1, nuscenes.NELEM)
    for t in range(len(table.thresholds)):
        hits = table.is_tp[t, rows]
        if not hits.any():
            continue
        tp = np.cumsum(hits)
        fp = np.cumsum(~hits)
        precision = np.interp(recall_points, tp / float(npos), tp / (fp + tp), right=0)
        out[t] = nuscenes.ap_of_precision(precision)
    return out


def table_ap(table: MatchTable, counts: np.ndarray | None = None, columns: Sequence[int] | None = None) -> np.ndarray:
    """(T,) AP at each threshold on a resampled set, with the AP of the table's kind: nuScenes' (0
    without ground truth) or COCO's (NaN without ground truth, as COCOeval's -1). `columns`: the
    thresholds the caller reads (COCO computes only those, NaN elsewhere; nuScenes' four are cheap)."""
    if table.kind == "coco":
        from .boxes2d.coco_matches import resampled_coco_ap
        return resampled_coco_ap(table, counts, columns)
    return resampled_ap(table, counts)


def bootstrap_counts(n_samples: int, resamples: int, seed: int = 0) -> np.ndarray:
    """(resamples, n_samples) draw counts: each row a bootstrap resample of the samples (with replacement)."""
    rng = np.random.default_rng(seed)
    return rng.multinomial(n_samples, np.full(n_samples, 1.0 / n_samples), size=resamples)
