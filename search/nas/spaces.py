"""The search spaces `python -m search.nas --space NAME` knows, by name (SPACES).

- `yolov8n_adapter`: the YOLOv8n-Adapter paper's Table 1 over the zoo's `yolov8n_adapter`:
  backbone blocks 1-2 at widths (1/2, 1), blocks 3-5 at (1/4, 1/2, 3/4, 1), the Adapter's three
  Stem convs at (1/4 .. 1), the fusion option (1, 2, 3) of each of the 7 Exchangers (whose widths
  follow the features they join: "adaptive"), and the neck and head at each of the 3 pyramid
  levels at (1/4 .. 1): 2^2 x 4^3 x 4^3 x 3^7 x 4^3 = 2^20 x 3^7 subnets. How blocks map to layers
  is the config's (models/yolo_rd/config.py: BACKBONE_BLOCKS, NECK_LEVELS).
- `dsfec`: DSFEC's own ablation axes, searched jointly over a base variant (default `dsfec_m`): the
  stem filters (Table 2's 32, 16, 12, 8, the FEC's last width tied as in search.stem), the width of
  each of the 4 backbone stages at (1/2, 3/4, 1) of the base's, and the blocks per stage (1, 2, 3):
  4 x 3^4 x 3^4 = 26,244 subnets. The paper sweeps these one at a time; no peer searches them jointly.
"""

from __future__ import annotations

from dsfec_jax import zoo
from dsfec_jax.models.yolo_rd.config import EARLIER_SMALL_SIDE, scaled_width

from .engines import POINT_ENGINE, RD_ENGINE
from .space import Choice, SearchSpace

QUARTERS = (0.25, 0.5, 0.75, 1.0)
HALVES = (0.5, 1.0)
FUSIONS = (1, 2, 3)


# The assigner's small-box rule of every subnet (supernet, stand-alone retraining, registered
# subnets): docs/search.md's NAS figures were measured with the family's pre-issue-49 default (8, 16),
# so the space pins it, and a registered subnet records it; ultralytics 8.4.190's (16, 16) is the
# family's default for everything else (models/yolo_rd/config.py).
YOLO_RD_SEARCH_SMALL_SIDE = EARLIER_SMALL_SIDE


def yolov8n_adapter_space(base: str = "yolov8n_adapter") -> SearchSpace:
    cfg = zoo.config(base)
    backbone = [Choice(f"backbone{b}", HALVES if b <= 2 else QUARTERS) for b in range(1, 6)]
    stem = [Choice(f"stem{j}", QUARTERS) for j in range(1, len(cfg.stem_widths) + 1)]
    exchangers = [Choice(f"exchanger{k}", FUSIONS, kind="categorical") for k in range(1, len(cfg.adapter_layout) + 1)]
    neck = [Choice(f"neck_head{lvl}", QUARTERS) for lvl in range(1, 4)]

    def to_overrides(c: dict) -> dict:
        return {"backbone_width_ratios": tuple(c[x.name] for x in backbone),
                "stem_widths": tuple(scaled_width(w, c[x.name]) for w, x in zip(cfg.stem_widths, stem)),
                "fusion": tuple(c[x.name] for x in exchangers),
                "neck_width_ratios": tuple(c[x.name] for x in neck),
                "assign_small_side": YOLO_RD_SEARCH_SMALL_SIDE}

    return SearchSpace("yolov8n_adapter", base, tuple(backbone + stem + exchangers + neck), to_overrides,
                       "the YOLOv8n-Adapter paper's Table 1", {x.name: 1 for x in exchangers}, RD_ENGINE)


def dsfec_space(base: str = "dsfec_m") -> SearchSpace:
    from ..space import apply_axis  # the family's derived axes (stem filters tie the FEC's last width)

    cfg = zoo.config(base)
    stem = Choice("stem_filters", (8, 12, 16, 32), kind="categorical")
    widths = [Choice(f"stage{s}_width", (0.5, 0.75, 1.0)) for s in range(1, 5)]
    blocks = [Choice(f"stage{s}_blocks", (1, 2, 3), kind="depth") for s in range(1, 5)]

    def to_overrides(c: dict) -> dict:
        out = apply_axis(cfg, {}, "stem_filters", c["stem_filters"])
        out["stage_widths"] = tuple(scaled_width(w, c[x.name]) for w, x in zip(cfg.stage_widths, widths))
        out["stage_blocks"] = tuple(c[x.name] for x in blocks)
        return out

    own = {stem.name: cfg.stem_filters, **{x.name: n for x, n in zip(blocks, cfg.stage_blocks)}}
    return SearchSpace("dsfec", base, (stem, *widths, *blocks), to_overrides,
                       "DSFEC's stem filters, stage widths and blocks per stage, jointly", own, POINT_ENGINE)


SPACES = {"yolov8n_adapter": yolov8n_adapter_space, "dsfec": dsfec_space}


def get_space(name: str, base: str | None = None) -> SearchSpace:
    if name not in SPACES:
        raise ValueError(f"unknown search space {name!r}; known: {sorted(SPACES)}")
    return SPACES[name]() if base is None else SPACES[name](base)
