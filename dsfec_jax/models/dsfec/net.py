"""The DSFEC family (arXiv 2412.07411) and its residual Baseline, as one configurable network.

pillar points -> PillarFeatureNet (FEC or PointPillars) -> scatter -> stem -> 4 stages
(DSConv or PIXOR bottleneck) -> top-down neck -> Car / Truck / VRU heads.
"""

from __future__ import annotations

import dataclasses

import flax.linen as nn
import jax.numpy as jnp
import numpy as np

from ...core.grid import DSFEC_GRID, Grid
from ...core.columns import NUSCENES_FEATURES
from ...layers.conv import KERNELS
from ...layers import ACTIVATIONS, ConvBNAct, DSConv, PillarFeatureNet, ResidualBottleneck, check_fec_filters, scatter_to_bev
from .heads import DenseHead
from .necks import TopDownNeck
from ..pillar_inputs import random_pillar_inputs

RADAR_FEATURES = NUSCENES_FEATURES
HEAD_NAMES = ("car", "truck", "vru")
ACT_FIELDS = ("act_fec", "act_stem", "act_backbone", "act_car_head", "act_truck_head", "act_vru_head")


@dataclasses.dataclass(frozen=True)
class DSFECConfig:
    """Every knob of a DSFEC-family detector. Variants in the zoo are instances of this."""

    name: str = "dsfec_l"
    grid: Grid = DSFEC_GRID
    point_features: tuple[str, ...] = RADAR_FEATURES
    max_pillars: int = 8000
    max_points: int = 8
    # pillar encoder
    encoder: str = "fec"  # "fec" (DSFEC) | "pointpillars" (Baseline)
    fec_filters: tuple[int, int, int] = (32, 128, 12)
    pointpillars_filters: int = 32
    # stem and backbone
    stem_filters: int = 12
    stem_convs: int = 1
    block: str = "dsconv"  # "dsconv" | "residual"
    stage_blocks: tuple[int, int, int, int] = (3, 6, 6, 3)
    stage_widths: tuple[int, int, int, int] = (96, 192, 256, 384)
    stage_strides: tuple[int, int, int, int] = (1, 2, 2, 2)
    depthwise_impl: str = "shifted"  # "shifted" (fast jitted CPU) | "grouped" (ONNX export)
    kernels: str = "auto"  # "auto" (the CPU training formulations on the CPU) | "fast" | "plain" (layers/kernels.py)
    # neck and heads
    neck_widths: tuple[int, ...] = (192, 128, 64)
    head_convs: int = 4
    head_width: int = 96
    head_kind: str = "conv"  # "conv" | "dsconv"
    head_classes: tuple[tuple[str, ...], ...] = (("car",), ("truck",), ("pedestrian", "bicycle"))
    box_code_size: int = 6  # PIXOR: cos, sin, dx, dy, log w, log l
    # the paper's activation mix (§3.3)
    act_fec: str = "relu"
    act_stem: str = "leaky_relu"
    act_backbone: str = "leaky_relu"
    act_car_head: str = "swish"
    act_truck_head: str = "swish"
    act_vru_head: str = "relu"
    notes: str = ""  # where a variant departs from the paper, and why


    def __post_init__(self):
        validate(self)

    @property
    def in_channels(self) -> int:
        return self.fec_filters[-1] if self.encoder == "fec" else self.pointpillars_filters

    @property
    def output_stride(self) -> int:
        """Cells of the grid per cell of the head maps."""
        used = len(self.neck_widths)
        return int(np.prod(self.stage_strides[: 4 - used + 1]))

    def build(self) -> "DSFECNet":
        return DSFECNet(self)

    def dummy_inputs(self, batch_size: int = 1, seed: int = 0, occupancy: float = 0.5) -> dict:
        return random_pillar_inputs(self, batch_size, seed, occupancy)


def validate(cfg: DSFECConfig) -> None:
    """Fail early, naming the field and what was expected."""
    def need(ok, field, expected):
        if not ok:
            raise ValueError(f"{cfg.name}: {field}={getattr(cfg, field)!r}; expected {expected}")

    need(cfg.encoder in ("fec", "pointpillars"), "encoder", "'fec' or 'pointpillars'")
    if cfg.encoder == "fec":
        check_fec_filters(tuple(cfg.fec_filters))
    need(cfg.block in ("dsconv", "residual"), "block", "'dsconv' or 'residual'")
    need(cfg.head_kind in ("conv", "dsconv"), "head_kind", "'conv' or 'dsconv'")
    need(cfg.depthwise_impl in ("shifted", "grouped"), "depthwise_impl", "'shifted' or 'grouped'")
    need(cfg.kernels in KERNELS, "kernels", " or ".join(map(repr, KERNELS)))
    for field in ("stage_blocks", "stage_widths", "stage_strides"):
        values = getattr(cfg, field)
        need(len(values) == 4 and all(int(v) >= 1 for v in values), field, "4 integers >= 1 (one per stage)")
    need(1 <= len(cfg.neck_widths) <= 4 and all(w >= 1 for w in cfg.neck_widths), "neck_widths", "1-4 positive widths")
    need(len(cfg.head_classes) == len(HEAD_NAMES), "head_classes", f"one class tuple per head {HEAD_NAMES}")
    for field in ("stem_filters", "stem_convs", "head_width", "max_pillars", "max_points", "pointpillars_filters"):
        need(int(getattr(cfg, field)) >= 1, field, "an integer >= 1")
    need(cfg.head_convs >= 0, "head_convs", "an integer >= 0")
    need(tuple(cfg.point_features[:3]) == ("x", "y", "z"), "point_features", "x, y, z as the first three columns")
    for field in ACT_FIELDS:
        need(getattr(cfg, field) in ACTIVATIONS, field, f"one of {sorted(ACTIVATIONS)}")


class DSFECNet(nn.Module):
    """Pillar tensors in, per-head class logits and box codes out (at the neck's resolution)."""

    cfg: DSFECConfig

    def setup(self):
        c = self.cfg
        filters = c.fec_filters if c.encoder == "fec" else (c.pointpillars_filters,)
        self.pillar_net = PillarFeatureNet(c.grid, c.encoder, tuple(filters), c.act_fec, c.kernels)
        self.stem = [ConvBNAct(c.stem_filters, 3, 1, c.act_stem, c.kernels, name=f"stem{i}") for i in range(c.stem_convs)]
        self.stages = [self._stage(i) for i in range(4)]
        self.neck = TopDownNeck(tuple(c.neck_widths), c.kernels)
        acts = (c.act_car_head, c.act_truck_head, c.act_vru_head)
        self.heads = {
            name: DenseHead(len(classes), c.box_code_size, c.head_convs, c.head_width, c.head_kind, act,
                            c.depthwise_impl, c.kernels, name=f"head_{name}")
            for name, classes, act in zip(HEAD_NAMES, c.head_classes, acts)
        }

    def _stage(self, i: int) -> list:
        c = self.cfg
        blocks = []
        for b in range(c.stage_blocks[i]):
            stride = c.stage_strides[i] if b == 0 else 1
            name = f"stage{i + 1}_block{b}"
            if c.block == "dsconv":
                blocks.append(DSConv(c.stage_widths[i], stride, c.act_backbone, c.depthwise_impl, c.kernels, name=name))
            else:
                blocks.append(ResidualBottleneck(c.stage_widths[i], stride, c.act_backbone, kernels=c.kernels, name=name))
        return blocks

    def encode(self, points, mask, coords, train: bool = False):
        """Pillar feature net + scatter: the BEV pseudo-image (B, nx, ny, C)."""
        pillars = self.pillar_net(points, mask, coords, train)
        return scatter_to_bev(pillars, coords, self.cfg.grid)

    def backbone(self, image, train: bool = False, depth=None) -> list:
        """Stem + 4 stages. `depth` (int array (4,), may be traced) runs only the first depth[i]
        blocks of stage i, the rest pass x through: every subnet of a supernet in one compiled
        function (the one-shot search). Block 0 (the strided one) always runs."""
        x = image
        for layer in self.stem:
            x = layer(x, train)
        stages = []
        for i, blocks in enumerate(self.stages):
            for b, block in enumerate(blocks):
                y = block(x, train)
                x = y if depth is None or b == 0 else jnp.where(b < depth[i], y, x)
            stages.append(x)
        return stages

    def detect(self, stages: list, train: bool = False) -> dict:
        x = self.neck(stages, train)
        return {name: head(x, train) for name, head in self.heads.items()}

    def __call__(self, points, mask, coords, train: bool = False, depth=None):
        return self.detect(self.backbone(self.encode(points, mask, coords, train), train, depth), train)
