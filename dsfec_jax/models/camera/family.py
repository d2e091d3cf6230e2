"""The camera family's record: what shared code needs to know of Shuffle-YOLOv3 and Darknet53-YOLOv3.

The family reads RGB images (modality 'image'): its data (data/camera: the street benchmark, VOC),
predictor (modalities/image/predict.py), metric (modalities/image/evaluate.py: VOC mAP@0.5 as
voc_eval.py, COCO AP through pycocotools) and training (modalities/image/fit.py: multi-scale
letterboxed batches) live in the image rooms, not in the point-cloud ones. Its loss is darknet's YOLOv3 loss (loss.py, yolov3-voc.cfg's
ignore_thresh 0.5); its `paper` profile is yolov3-voc.cfg's SGD schedule (train/schedules.py).

Search trials (search/trial.py) load point frames or RD samples only, so the family has no search
recipes yet: `search.recipes.get_recipe` refuses it, naming the empty list.
"""

from __future__ import annotations

from ..family import Family, MetricProtocol
from .config import CameraConfig
from .footprint import paper_memory_mib
from .loss import Yolo3LossConfig, yolo3_loss
from .variants import VARIANTS


def head_classes(cfg: CameraConfig) -> dict:
    return {"detect": tuple(cfg.classes)}  # one YOLO head over three scales, one logit per class


def loss(cfg: CameraConfig):
    """fn(raw outputs, {'gt_boxes', 'gt_labels', 'gt_mask'}) -> (loss, parts): darknet's YOLOv3 loss."""
    settings = Yolo3LossConfig()
    return lambda outputs, t: yolo3_loss(outputs, t["gt_boxes"], t["gt_labels"], t["gt_mask"], settings)


# VOC mAP@0.5 (voc_eval.py: VOC07 11-point, the paper's Table 3 convention for VOC2007, and all-point)
# plus COCO mAP@[.5:.95] and AP50 through pycocotools, all in percent; the headline is VOC07 mAP@0.5
CAMERA_VOC_PROTOCOL = MetricProtocol(
    name="camera_voc", headline="mAP50",
    columns=(("mAP50", "VOC07 mAP@0.5", 1), ("mAP50_all", "VOC mAP@0.5 (all-point)", 1),
             ("coco_mAP50_95", "COCO mAP@[.5:.95]", 1), ("params", "Params (M)", 3), ("gflops", "GFLOPs", 2),
             ("latency_ms", "Latency (ms)", 1)),
    keep=("mAP50", "mAP50_all", "coco_mAP50_95", "coco_AP50", "AP50", "AP50_all"))

MEMORY_CONVENTION = ("the paper's Sec. 3.4 formula at 416 x 416: every conv's C_in C_out K^2 + C_out parameters "
                     "plus every layer's C_out H W output (convs, shortcuts, concatenations, upsample, route), "
                     "float32, batch 1, MiB (models/camera/footprint.py)")

FAMILY = Family(
    name="camera", config_class=CameraConfig, variants=VARIANTS, benchmark="street", loss=loss,
    head_classes=head_classes, metric=CAMERA_VOC_PROTOCOL, modality="image",
    schedules={"quick": "yolo3_quick", "paper": "yolo3_paper"}, weight_ema=True, recipes={},
    stem_memory=paper_memory_mib, memory_convention=MEMORY_CONVENTION,
    weight_fields=("num_classes", "class_names"),  # `dsfec train` takes them from the data (modalities/image/cli.py)
)


def class_fields(classes) -> dict:
    """The config fields (FAMILY.weight_fields) that give a camera model these classes: what `dsfec
    train` sets from its data's class names."""
    classes = tuple(classes)
    return {"num_classes": len(classes), "class_names": classes}
