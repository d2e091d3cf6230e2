"""The named DSFEC-family variants of the paper (Table 1) as data.

The paper gives block counts, not widths. The sizes are our own fit of its published Tables 1-3
(params, GFLOPs, Table 2 memory; docs/dsfec-sizes.md, "How the sizes were fitted"). Baseline and DSFEC-L are
PIXOR-width networks: stage widths 96/192/256/384 and heads of 4 x 3x3 conv 96, as in the public
PIXOR re-implementations (e.g. github philip-huang/PIXOR, srcs/model.py); by our fit stage 1 runs
at the full 160x160 grid and the heads at 80x80, with a (192, 128, 64) top-down neck and the
pillar net counted on its 8000 x 8 point slots. The paper says DSFEC-M and -S change only block
counts, but no network with L's widths reaches their 8.29 / 4.45 GFLOPs and 0.58 M / 0.30 M
params (a linear program over any per-block costs shared by L, M and S leaves >= 20 % error), so
M and S also narrow the stages, extend the neck to the full 0.5 m resolution and shrink the
heads; those choices are written in `notes`.
"""

from __future__ import annotations

from pathlib import Path

from ..searched import searched_variants
from .net import DSFECConfig

# Subnets found by `python -m search.nas --space dsfec ... --register NAME` (models/searched.py)
SEARCHED = Path(__file__).parent / "searched.json"

PIXOR_NOTE = "PIXOR widths; neck (192,128,64) to 80x80 (an assumption: the paper gives no neck)"

VARIANTS: dict[str, DSFECConfig] = {
    "baseline": DSFECConfig(
        name="baseline", encoder="pointpillars", pointpillars_filters=32, stem_filters=32,
        stem_convs=2, block="residual", act_fec="relu", act_stem="relu", act_backbone="relu",
        act_car_head="relu", act_truck_head="relu", act_vru_head="relu",
        notes="PIXOR bottleneck residual backbone, PointPillars encoder (32), 2-conv stem; all ReLU. " + PIXOR_NOTE,
    ),
    "dsfec_l": DSFECConfig(name="dsfec_l", notes=PIXOR_NOTE),
    "dsfec_m": DSFECConfig(
        name="dsfec_m", stage_blocks=(3, 3, 2, 3), stage_widths=(48, 96, 192, 256),
        neck_widths=(128, 64, 64, 32), head_convs=2, head_width=48,
        notes="assumed: stages (48,96,192,256), 4-level neck to 160x160 ending at 32, heads 2 x 48 "
              "(block counts alone cannot reach the paper's size)",
    ),
    "dsfec_s": DSFECConfig(
        name="dsfec_s", stage_blocks=(1, 1, 3, 2), stage_widths=(64, 64, 128, 256),
        neck_widths=(64, 48, 32, 32), head_convs=3, head_width=24,
        notes="assumed: stages (64,64,128,256), 4-level neck to 160x160 ending at 32, heads 3 x 24 "
              "(block counts alone cannot reach the paper's size)",
    ),
}

VARIANTS.update(searched_variants(SEARCHED, VARIANTS))
