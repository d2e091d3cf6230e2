"""The DSFEC family's record: what shared code needs to know of DSFEC and its Baseline."""

from __future__ import annotations

from ...boxes.decode import decode_heads
from ...boxes.pixor import cell_centres
from ...core.grid import DSFEC_GRID, Grid
from ...layers.conv import BN_MOMENTUM
from ..family import Family, MetricProtocol, PointParts, SearchRecipe, Supernet
from .loss import LossConfig, detection_loss
from .net import HEAD_NAMES, DSFECConfig
from .stem_memory import stem_memory_mb
from .targets import detector_targets
from .variants import VARIANTS

MAP_KEYS = ("cls", "box")  # each dense head's two output maps


def head_classes(cfg: DSFECConfig) -> dict:
    return dict(zip(HEAD_NAMES, cfg.head_classes))


def decoder(cfg: DSFECConfig, top_k: int):
    cells, heads = cell_centres(cfg.grid, cfg.output_stride), head_classes(cfg)
    return lambda maps: decode_heads(maps, heads, cells, top_k)


def targets(cfg: DSFECConfig):
    heads = head_classes(cfg)
    return lambda boxes, grid: detector_targets(boxes, heads, grid, cfg.output_stride)


def loss(cfg: DSFECConfig):
    return lambda outputs, target_maps: detection_loss(outputs, target_maps, LossConfig())


def map_outputs(cfg: DSFECConfig) -> tuple[str, ...]:
    return tuple(f"{h}_{k}" for h in HEAD_NAMES for k in MAP_KEYS)


def head_maps(cfg: DSFECConfig, maps: dict) -> tuple:
    return tuple(maps[h][k] for h in HEAD_NAMES for k in MAP_KEYS)


def stage_blocks_axis(stage: int):
    """The derived axis stage{K}_blocks: blocks of one stage, the others kept from the base."""
    def apply(base: DSFECConfig, overrides: dict, value) -> dict:
        blocks = list(overrides.get("stage_blocks", base.stage_blocks))
        blocks[stage] = value
        return {**overrides, "stage_blocks": tuple(blocks)}
    return apply


def stem_filters_axis(base: DSFECConfig, overrides: dict, value) -> dict:
    """The stem width; with the FEC encoder its last width follows, as in the paper (FEC 32-128-12 -> stem 12)."""
    if base.encoder != "fec":
        return {**overrides, "stem_filters": value}
    f1, f2, _ = overrides.get("fec_filters", base.fec_filters)
    return {**overrides, "stem_filters": value, "fec_filters": (f1, f2, value)}


def supernet_blocks(cfg: DSFECConfig) -> dict[str, tuple[int, int]]:
    return {f"stage{s + 1}_block{b}": (s, b) for s in range(4) for b in range(cfg.stage_blocks[s])}


# The nuScenes-style detection AP of the paper (Car mAP over 0.5/1/2/4 m is the headline)
NUSCENES_PROTOCOL = MetricProtocol(
    name="nuscenes", headline="car_mAP",
    columns=(("car_mAP", "Car mAP", 2), ("car_AP4", "Car AP@4", 2), ("mAP", "mAP (4 classes)", 2),
             ("gflops", "GFLOPs", 2), ("params", "Params (M)", 3), ("memory_mb", "Memory (MB)", 2),
             ("latency_ms", "Latency (ms)", 1)),
    keep=("car_mAP", "car_AP4", "mAP", "class_mAP", "AP@4"), match_class="car", zero_class_note=True)

# search budgets: a 32 m x 32 m grid in front of the sensor (quick), 8 m x 8 m (smoke)
NEAR_GRID = Grid((0.0, 32.0), (-16.0, 16.0), DSFEC_GRID.z_range, DSFEC_GRID.cell)
SMOKE_GRID = Grid((0.0, 8.0), (-4.0, 4.0), DSFEC_GRID.z_range, DSFEC_GRID.cell)
RECIPES = {
    "smoke": SearchRecipe("quick", {"steps": 2, "batch_size": 2, "warmup_steps": 1}, 4, 2, SMOKE_GRID, 64, None, 1,
                          supernet_steps=4, light_profile=True),
    "quick": SearchRecipe("quick", {"steps": 150, "batch_size": 4, "warmup_steps": 15}, 400, 100, NEAR_GRID, 512,
                          None, 20, supernet_steps=480, light_profile=True, warm_start=True, oneshot_seeds=3),
    "paper": SearchRecipe("paper", {}, 4800, 500, None, 2048, None, 20, supernet_steps=None, light_profile=False),
}

FAMILY = Family(
    name="dsfec", config_class=DSFECConfig, variants=VARIANTS,
    benchmark="synthetic", loss=loss, head_classes=head_classes,
    points=PointParts(input_columns="dsfec", targets=targets, origin_input=False, decoder=decoder,
                      predictor={"top_k": 100, "nms_iou": 0.2, "max_boxes": 500}, map_outputs=map_outputs,
                      head_maps=head_maps),
    metric=NUSCENES_PROTOCOL, recipes=RECIPES,
    axes={**{f"stage{s + 1}_blocks": stage_blocks_axis(s) for s in range(4)}, "stem_filters": stem_filters_axis},
    supernet=Supernet("stage_blocks", supernet_blocks, BN_MOMENTUM), stem_memory=stem_memory_mb,
)
