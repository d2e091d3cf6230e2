"""The YOLO-RD family's record: what shared code needs to know of YOLOv8/v9t/v10n on
range-Doppler maps (with or without the Adapter).

The family reads RD maps as images (modality 'rd'): its data, predictor, metric and export live in
the image-like rooms (data/rd; modalities/rd/predict.py, evaluate.py, export.py; metrics/boxes2d),
not in the point-cloud ones. Its losses are ultralytics' (loss.yolo_loss: YOLOv8's for v8 and v9t, the dual
one-to-many + one-to-one loss for v10n); its schedules are ultralytics' SGD recipe.
"""

from __future__ import annotations

from ..family import Family, MetricProtocol, SearchRecipe
from .assigner import AssignerConfig
from .config import YoloRDConfig
from .loss import YoloLossConfig
from .loss_v10 import yolo_loss
from .variants import VARIANTS


def head_classes(cfg: YoloRDConfig) -> dict:
    return {"detect": tuple(cfg.classes)}  # one decoupled head, one logit per class


def loss(cfg: YoloRDConfig):
    """fn(raw outputs, {'gt_boxes', 'gt_labels', 'gt_mask'}) -> (loss, parts), ultralytics' gains."""
    settings = YoloLossConfig(reg_max=cfg.reg_max, strides=cfg.strides,
                              assigner=AssignerConfig(small_side=cfg.assign_small_side))
    return lambda outputs, t: yolo_loss(outputs, t["gt_boxes"], t["gt_labels"], t["gt_mask"], settings)


# COCO AP through pycocotools on the RD maps' pixel boxes (the paper's mAP@30/@50/@50-95) plus DAROD's
# protocol; the headline is mAP@50 (the paper's first column), reported in percent
RD_COCO_PROTOCOL = MetricProtocol(
    name="rd_coco", headline="mAP50",
    columns=(("mAP50", "mAP@50", 1), ("mAP50_95", "mAP@50-95", 1), ("mAP30", "mAP@30", 1), ("mAP70", "mAP@70", 1),
             ("darod_mAP50", "DAROD mAP@50", 1), ("params", "Params (M)", 3), ("gflops", "GFLOPs", 2),
             ("latency_ms", "Latency (ms)", 1)),
    keep=("mAP50", "mAP50_95", "mAP30", "mAP70", "AP50", "AP", "darod_mAP50", "darod_mAP30"),
    # every class's per-sample matches, so a table's bootstrap intervals resample the headline itself
    match_class="*", interval_statistic="mAP@50", interval_thresholds=(0.5,))

# Search trials (search/): RD samples of the embedded benchmark; no grid, pillars or windows.
# `quick` is the CLI's quick profile (yolo_quick: batch 16, 15 epochs, ultralytics' recipe) on 600
# samples, so a table row costs minutes, not hours, on the 2-core CPU; `paper` is the paper's
# profile (300 epochs at batch 64) on a RADDet-sized synthetic split.
RECIPES = {
    "smoke": SearchRecipe("yolo_quick", {"steps": 2, "batch_size": 2}, 4, 2, None, None, None, 1,
                          supernet_steps=None, light_profile=True),
    "quick": SearchRecipe("yolo_quick", {}, 600, 100, None, None, None, 10, supernet_steps=None, light_profile=True),
    "paper": SearchRecipe("yolo_paper", {}, 8000, 1000, None, None, None, 20, supernet_steps=None, light_profile=False),
}

FAMILY = Family(
    # the benchmark's version named: records and search journals say which maps they were made on
    name="yolo_rd", config_class=YoloRDConfig, variants=VARIANTS, benchmark="rd-synthetic:v2", loss=loss,
    head_classes=head_classes, metric=RD_COCO_PROTOCOL, modality="rd",
    schedules={"quick": "yolo_quick", "paper": "yolo_paper"}, weight_ema=True, recipes=RECIPES,
)
