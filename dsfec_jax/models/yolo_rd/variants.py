"""The named YOLOv8-on-RD variants (paper Tables 3-6) as data.

YOLOv8 n/s/m/l read the heatmap (the paper: "For YOLOv8 models without the Adapter, we use the
heatmap representation"); YOLOv8n-Adapter feeds the heatmap to the backbone and the grayscale map
to the Adapter (Table 5's best row) with fusion option 1 (PAF) in every Exchanger. Table 5's
representation ablation and Table 6's fusion ablation are configs of the same network.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from ..searched import searched_variants as load_searched
from .config import YoloRDConfig

# Subnets found by the one-shot search (`python -m search.nas ... --register`, search/nas/register.py):
# {name: {"base": variant, "overrides": {field: value}, "provenance": {...}}}, registered below
SEARCHED = Path(__file__).parent / "searched.json"

ADAPTER_NOTE = ("Adapter widths are ours (the paper gives none): Stem 1->32->64->128 at stride 4, Exchangers "
                "after backbone layers 2-8, modes 1,2,1,2,1,2,1, fusion option 1 (see config.py)")

VARIANTS: dict[str, YoloRDConfig] = {
    **{f"yolov8{s}": YoloRDConfig(name=f"yolov8{s}", scale=s) for s in "nsml"},
    "yolov8n_adapter": YoloRDConfig(name="yolov8n_adapter", scale="n", adapter_input="gray", notes=ADAPTER_NOTE),
    # Table 4: the Adapter on YOLOv9t and YOLOv10n, same design and positions (after layers 2-8)
    "yolov9t": YoloRDConfig(name="yolov9t", arch="v9", scale="t"),
    "yolov9t_adapter": YoloRDConfig(name="yolov9t_adapter", arch="v9", scale="t", adapter_input="gray",
                                    notes=ADAPTER_NOTE),
    "yolov10n": YoloRDConfig(name="yolov10n", arch="v10", scale="n"),
    "yolov10n_adapter": YoloRDConfig(name="yolov10n_adapter", arch="v10", scale="n", adapter_input="gray",
                                     notes=ADAPTER_NOTE),
}


def searched_variants(path: Path = SEARCHED) -> dict[str, YoloRDConfig]:
    """The searched subnets recorded in `path` as variants (none when it does not exist)."""
    return load_searched(path, VARIANTS)


def representation_variant(backbone_input: str, adapter_input: str | None) -> YoloRDConfig:
    """A Table 5 row: YOLOv8n (adapter_input None) or YOLOv8n-Adapter on the given representations."""
    base = VARIANTS["yolov8n_adapter" if adapter_input else "yolov8n"]
    suffix = f"_{backbone_input}" + (f"_{adapter_input}" if adapter_input else "")
    return dataclasses.replace(base, name=base.name + suffix, backbone_input=backbone_input,
                               adapter_input=adapter_input)


def fusion_variant(option: int) -> YoloRDConfig:
    """A Table 6 row: YOLOv8n-Adapter with fusion `option` in every Exchanger."""
    return dataclasses.replace(VARIANTS["yolov8n_adapter"], name=f"yolov8n_adapter_fusion{option}", fusion=option)


# Table 5's rows: (backbone input, adapter input); None = plain YOLOv8n
TABLE5_ROWS = (("heat", None), ("gray", None), ("heat", "gray"), ("gray", "heat"), ("heat", "heat"), ("gray", "gray"))
TABLE6_OPTIONS = (2, 3, 1)  # in the paper's row order

VARIANTS.update(searched_variants())
