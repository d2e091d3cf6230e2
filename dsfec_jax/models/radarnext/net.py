"""The RadarNeXt family (arXiv 2501.02314): a 4D-radar pillar detector built for edge GPUs.

pillar points (13 features) -> PointPillars pillar net (64) -> scatter -> Rep-DWC backbone
(MobileOne depthwise + pointwise layers, or the Dense PointPillars/SECOND backbone) -> FPN, PAN or
MDFEN neck -> CenterHead. Training uses the branched MobileOne form; `deploy` turns the trained
variables into the single-conv form that is exported and timed. Facts from the public RadarNeXt
code (github Pay246-git468/RadarNeXt, commit 72676df): projects/RadarNeXt/configs/*.py,
projects/RadarNeXt/radarnext/*.py and mmdet3d/models/voxel_encoders/pillar_encoder.py; the code
is ours.
"""

from __future__ import annotations

import dataclasses

import flax.linen as nn

from ...core.grid import TJ4D_GRID, VOD_GRID, Grid
from ...core.columns import TJ4D_FEATURES, VOD_FEATURES
from ...layers import ConvBNAct, PillarFeatureNet, RepDWSeparable, reparameterize_tree, scatter_to_bev
from ...layers.conv import KERNELS
from .center_head import CenterHead
from ..pillar_inputs import random_pillar_inputs
from .necks import DCN_POSITIONS, SECONDFPN, PANeck

# The public config's heatmap order (Pedestrian, Cyclist, Car) in the project's canonical class
# names: VoD's "Cyclist" (a bicycle with its rider) is "bicycle" here, as in data.points.sources.KITTI_CLASS_MAP.
VOD_CLASSES = ("pedestrian", "bicycle", "car")
# TJ4DRadSet: its own 8 columns, a 69.12 m x 69.12 m grid (432 x 432) and Truck as a fourth class
TJ4D_CLASSES = ("pedestrian", "bicycle", "car", "truck")
NECKS = ("fpn", "pan", "mdfen")
BACKBONES = ("rep_dwc", "dense")


@dataclasses.dataclass(frozen=True)
class RadarNeXtConfig:
    """Every knob of a RadarNeXt-family detector; the zoo's variants are instances of this."""

    name: str = "radarnext_mdfen"
    grid: Grid = VOD_GRID
    point_features: tuple[str, ...] = VOD_FEATURES
    max_pillars: int = 16000  # training; the public code allows 40,000 at test time
    max_points: int = 10
    pillar_filters: int = 64
    backbone: str = "rep_dwc"  # "rep_dwc" | "dense"
    layer_nums: tuple[int, int, int] = (3, 5, 5)
    channels: tuple[int, int, int] = (64, 128, 256)
    branches: int = 1  # MobileOne k (num_conv_branches); 1 in every public config
    deploy: bool = False  # the fused single-branch form (see `deploy`)
    neck: str = "mdfen"  # "fpn" | "pan" | "mdfen"
    dcn_positions: tuple[int, ...] = (4,)
    dcn_groups: int = 4
    dcn_offset_scale: float = 2.0
    fpn_channels: int = 128
    head_width: int = 64
    classes: tuple[str, ...] = VOD_CLASSES
    corner_head: bool = True
    depthwise_impl: str = "shifted"  # "shifted" (fast jitted CPU) | "grouped" (ONNX export)
    kernels: str = "auto"  # "auto" (the CPU training formulations on the CPU) | "fast" | "plain" (layers/kernels.py)
    notes: str = ""


    def __post_init__(self):
        validate(self)

    @property
    def output_stride(self) -> int:
        """Grid cells per cell of the head maps (backbone /2, /4, /8; neck at /4; head deblock x2)."""
        return 2

    def build(self) -> "RadarNeXtNet":
        return RadarNeXtNet(self)

    def dummy_inputs(self, batch_size: int = 1, seed: int = 0, occupancy: float = 0.5) -> dict:
        return random_pillar_inputs(self, batch_size, seed, occupancy)


def for_tj4d(cfg: RadarNeXtConfig, name: str) -> RadarNeXtConfig:
    """The same network configured for TJ4DRadSet (grid, point columns, classes)."""
    return dataclasses.replace(cfg, name=name, grid=TJ4D_GRID, point_features=TJ4D_FEATURES, classes=TJ4D_CLASSES,
                               notes="TJ4DRadSet grid 432x432, 0.16 m; 8 TJ4D columns; 4 classes (+ truck)")


def validate(cfg: RadarNeXtConfig) -> None:
    """Fail early, naming the field and what was expected."""
    def need(ok, field, expected):
        if not ok:
            raise ValueError(f"{cfg.name}: {field}={getattr(cfg, field)!r}; expected {expected}")

    need(cfg.backbone in BACKBONES, "backbone", f"one of {BACKBONES}")
    need(cfg.neck in NECKS, "neck", f"one of {NECKS}")
    need(len(cfg.layer_nums) == 3 and all(int(n) >= 1 for n in cfg.layer_nums), "layer_nums", "3 integers >= 1")
    need(len(cfg.channels) == 3 and all(int(c) >= 1 for c in cfg.channels), "channels", "3 positive widths")
    need(cfg.neck == "fpn" or tuple(cfg.channels) == (64, 128, 256), "channels",
         "(64, 128, 256) with the PAN/MDFEN neck (its channels_list is fixed)")
    need(all(p in DCN_POSITIONS for p in cfg.dcn_positions) and len(set(cfg.dcn_positions)) == len(cfg.dcn_positions),
         "dcn_positions", f"distinct positions from {DCN_POSITIONS}")
    need((cfg.neck == "mdfen") == bool(cfg.dcn_positions), "dcn_positions",
         "at least one position with neck='mdfen' and none with 'fpn' or 'pan'")
    for field in ("branches", "max_pillars", "max_points", "pillar_filters", "fpn_channels", "head_width", "dcn_groups"):
        need(int(getattr(cfg, field)) >= 1, field, "an integer >= 1")
    need(len(cfg.classes) >= 1, "classes", "at least one class")
    need(cfg.depthwise_impl in ("shifted", "grouped"), "depthwise_impl", "'shifted' or 'grouped'")
    need(cfg.kernels in KERNELS, "kernels", " or ".join(map(repr, KERNELS)))
    need(tuple(cfg.point_features[:3]) == ("x", "y", "z"), "point_features", "x, y, z as the first three columns")


class RepDWCBackbone(nn.Module):
    """Stages of `layer_nums` Rep-DWC layers; the first layer of each stage has stride 2."""

    layer_nums: tuple[int, ...]
    channels: tuple[int, ...]
    branches: int = 1
    deploy: bool = False
    depthwise_impl: str = "shifted"
    kernels: str = "auto"  # layers.conv.Kernels

    @nn.compact
    def __call__(self, x, train: bool = False) -> list:
        outs = []
        for s, (n, c) in enumerate(zip(self.layer_nums, self.channels)):
            for i in range(n):
                x = RepDWSeparable(c, 2 if i == 0 else 1, self.branches, self.deploy, self.depthwise_impl, self.kernels,
                                   name=f"stage{s + 1}_layer{i}")(x, train)
            outs.append(x)
        return outs


class DenseBackbone(nn.Module):
    """PointPillars' SECOND backbone: per stage a stride-2 3x3 conv, then `layer_nums` 3x3 convs."""

    layer_nums: tuple[int, ...]
    channels: tuple[int, ...]
    kernels: str = "auto"

    @nn.compact
    def __call__(self, x, train: bool = False) -> list:
        outs = []
        for s, (n, c) in enumerate(zip(self.layer_nums, self.channels)):
            for i in range(n + 1):
                x = ConvBNAct(c, 3, 2 if i == 0 else 1, "relu", self.kernels, name=f"stage{s + 1}_conv{i}")(x, train)
            outs.append(x)
        return outs


class RadarNeXtNet(nn.Module):
    """Pillar tensors in; CenterHead maps at H/2 out."""

    cfg: RadarNeXtConfig

    def setup(self):
        c = self.cfg
        self.pillar_net = PillarFeatureNet(c.grid, "pointpillars", (c.pillar_filters,), "relu", c.kernels)
        if c.backbone == "rep_dwc":
            self.backbone_net = RepDWCBackbone(tuple(c.layer_nums), tuple(c.channels), c.branches, c.deploy,
                                               c.depthwise_impl, c.kernels)
        else:
            self.backbone_net = DenseBackbone(tuple(c.layer_nums), tuple(c.channels), c.kernels)
        if c.neck == "fpn":
            self.neck = SECONDFPN(c.fpn_channels, c.kernels)
        else:
            self.neck = PANeck(tuple(c.dcn_positions), c.dcn_groups, c.dcn_offset_scale, c.branches, c.deploy,
                               c.depthwise_impl, c.kernels)
        self.head = CenterHead(len(c.classes), c.head_width, c.corner_head, c.kernels)

    def encode(self, points, mask, coords, train: bool = False, origin=None):
        """Pillar feature net + scatter: the BEV pseudo-image (B, nx, ny, 64). `origin` (B, 2), if
        given, is each sample's grid (x_min, y_min): a training window's, without a recompile."""
        return scatter_to_bev(self.pillar_net(points, mask, coords, train, origin), coords, self.cfg.grid)

    def backbone(self, image, train: bool = False) -> list:
        return self.backbone_net(image, train)

    def detect(self, stages: list, train: bool = False) -> dict:
        return self.head(self.neck(stages, train), train)

    def __call__(self, points, mask, coords, train: bool = False, origin=None):
        return self.detect(self.backbone(self.encode(points, mask, coords, train, origin), train), train)


def deploy_config(cfg: RadarNeXtConfig) -> RadarNeXtConfig:
    """The inference form: fused MobileOne blocks, no training-only corner heatmap."""
    return dataclasses.replace(cfg, deploy=True, corner_head=False)


def deploy_variables(cfg: RadarNeXtConfig, variables: dict) -> dict:
    """Trained variables of `cfg` -> variables of `deploy_config(cfg)` (eval-mode outputs agree)."""
    if cfg.deploy:
        return variables
    fused = reparameterize_tree(variables)
    head = dict(fused["params"]["head"])
    for key in [k for k in head if k.startswith("corner_hm")]:
        del head[key]
    head_stats = {k: v for k, v in fused["batch_stats"].get("head", {}).items() if not k.startswith("corner_hm")}
    return {"params": {**fused["params"], "head": head}, "batch_stats": {**fused["batch_stats"], "head": head_stats}}
