"""The RadarNeXt family's record: what shared code needs to know of RadarNeXt."""

from __future__ import annotations

from ...boxes.center_decode import decode_center_head
from ...core.grid import VOD_GRID, Grid
from ..family import Family, MetricProtocol, PointParts, SearchRecipe
from .center_head import BOX_OUTPUTS
from .loss import center_head_loss
from .net import RadarNeXtConfig, deploy_config, deploy_variables
from .targets import center_head_targets
from .variants import RADARNEXT_VARIANTS


def head_classes(cfg: RadarNeXtConfig) -> dict:
    return {"center": tuple(cfg.classes)}  # one CenterHead, one heatmap channel per class


def decoder(cfg: RadarNeXtConfig, top_k: int):
    return lambda maps: decode_center_head(maps, cfg.grid, cfg.output_stride, top_k)


def targets(cfg: RadarNeXtConfig):
    return lambda boxes, grid: center_head_targets(boxes, tuple(cfg.classes), grid, cfg.output_stride)


def loss(cfg: RadarNeXtConfig):
    return lambda outputs, target_maps: center_head_loss(outputs, target_maps, cfg)


def map_outputs(cfg: RadarNeXtConfig) -> tuple[str, ...]:
    """The deployed CenterHead's maps (the training-only corner heatmap is not exported)."""
    return tuple(f"center_{k}" for k, _ in BOX_OUTPUTS) + ("center_hm",)


def head_maps(cfg: RadarNeXtConfig, maps: dict) -> tuple:
    return tuple(maps[name.removeprefix("center_")] for name in map_outputs(cfg))


def neck_axis(base: RadarNeXtConfig, overrides: dict, value) -> dict:
    """The neck; mdfen keeps the DCNv3 positions ((4,) when the base has none), fpn/pan drop
    them, as the paper's three variants do."""
    positions = overrides.get("dcn_positions", base.dcn_positions) or (4,)
    return {**overrides, "neck": value, "dcn_positions": positions if value == "mdfen" else ()}


# The View-of-Delft 3D AP (entire area headline; params of the fused form; no stem-memory column)
VOD_PROTOCOL = MetricProtocol(
    name="vod", headline="mAP",
    columns=(("mAP", "mAP (VoD 3D)", 2), ("mAP_corridor", "mAP corridor", 2), ("AP_car", "Car AP", 2),
             ("AP_pedestrian", "Pedestrian AP", 2), ("AP_bicycle", "Cyclist AP", 2),
             ("gflops", "GFLOPs", 2), ("params", "Params (M)", 3), ("latency_ms", "Latency (ms)", 1)),
    keep=("mAP", "mAP_corridor", "AP", "AP_corridor"))

# a synthetic-4D frame holds ~1,100 points, so 2,048 pillar slots never drop one (the config's
# 16,000 is the public code's bound for real 5-scan VoD); fewer slots make each step cheaper
SMOKE_GRID = Grid((0.0, 12.8), (-6.4, 6.4), VOD_GRID.z_range, VOD_GRID.cell)
RECIPES = {
    "smoke": SearchRecipe("radarnext", {"steps": 2, "batch_size": 2, "warmup_steps": 1}, 4, 2, SMOKE_GRID, 256,
                          None, 1, supernet_steps=None, light_profile=True),
    # the paper's decay points (35/80, 45/80) would spend half of a short run at 1 % of the rate
    "quick": SearchRecipe("radarnext", {"steps": 300, "batch_size": 4, "warmup_steps": 30, "decay_at": (0.7, 0.9)},
                          400, 40, None, 2048, 96, 10, supernet_steps=None, light_profile=True),
    "paper": SearchRecipe("radarnext", {}, 4800, 500, None, 16000, None, 20, supernet_steps=None, light_profile=False),
}

FAMILY = Family(
    name="radarnext", config_class=RadarNeXtConfig, variants=RADARNEXT_VARIANTS,
    benchmark="synthetic4d", loss=loss, head_classes=head_classes,
    # the public config's test settings: 500 decoded candidates, rotated NMS IoU 0.2, 83 boxes a frame
    points=PointParts(input_columns="native", targets=targets, origin_input=True, decoder=decoder,
                      predictor={"top_k": 500, "nms_iou": 0.2, "max_boxes": 83}, map_outputs=map_outputs,
                      head_maps=head_maps),
    metric=VOD_PROTOCOL, recipes=RECIPES,
    axes={"neck": neck_axis}, deploy_config=deploy_config, deploy_variables=deploy_variables,
)
