"""One class's evaluation outcome, kept per prediction so that any resample of the evaluation set
scores again without matching again (resampling.py explains why that is exact): every
prediction's sample, score and hit flag at each threshold, and the ground-truth count per sample.
nuScenes tables (resampling.match_table) and COCO ones (boxes2d/coco_matches.py) share it, and
both scorers read it, so it lives in a leaf of its own.
"""

from __future__ import annotations

import base64
import dataclasses
import io

import numpy as np

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
