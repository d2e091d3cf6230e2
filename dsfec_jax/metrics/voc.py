"""``python -m dsfec_jax.metrics.voc --gt-xml DIR --dets DIR --names voc.names [--metric voc07|all]
[--iou 0.5] [--json]``: PASCAL VOC AP per class and mAP of detection files against VOC XML.

A thin command: the files are read by data/camera/voc.py (XML with difficult flags; one
`class_id score x1 y1 x2 y2` file per image, the file stem = the XML stem, an image without a file
has no detections) and scored by metrics/boxes2d/voc_ap.py, voc_eval.py's protocol (strict IoU >
threshold, +1-pixel widths, difficult objects neither TP nor FP). This is the one metrics module
that imports data: a command must read files, and data never imports metrics, so no cycle forms.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence

from ..data.camera.voc import detection_boxes, read_annotation_dir, read_detection_dir, read_names
from .boxes2d.voc_ap import VOC_METRICS, VocAP, voc_ap


def evaluate_voc_files(gt_xml, dets, names, *, metric: str = "voc07", iou_threshold: float = 0.5) -> VocAP:
    """The command without printing: folders and names file -> VocAP."""
    classes = read_names(names)
    gts = {sid: a.boxes() for sid, a in read_annotation_dir(gt_xml).items()}
    detections = {sid: detection_boxes(d) for sid, d in read_detection_dir(dets, classes).items()}
    missing = [sid for sid in detections if sid not in gts]
    if missing:
        raise ValueError(f"{dets}: detection files without an XML in {gt_xml}: {missing[:5]}")
    return voc_ap(gts, detections, classes, iou_threshold=iou_threshold, metric=metric)


def format_table(result: VocAP) -> str:
    lines = [f"{'class':<14}{'npos':>6}{'dets':>7}{'AP':>9}"]
    for c, name in enumerate(result.classes):
        ap = "-" if math.isnan(result.ap[c]) else f"{result.ap[c]:.4f}"
        lines.append(f"{name:<14}{int(result.npos[c]):>6}{int(result.n_det[c]):>7}{ap:>9}")
    lines.append(f"mAP {result.map:.4f} ({result.metric}, IoU > {result.iou_threshold:g}, mean over the "
                 f"{int(result.scored.sum())} classes with ground truth)")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m dsfec_jax.metrics.voc",
                                description="PASCAL VOC AP per class and mAP of detection files against VOC XML, "
                                            "as py-faster-rcnn's voc_eval.py computes it")
    p.add_argument("--gt-xml", required=True, help="folder of VOC XML annotations")
    p.add_argument("--dets", required=True, help="folder of detection files, class_id score x1 y1 x2 y2")
    p.add_argument("--names", required=True, help="class names, one per line (line index = class_id)")
    p.add_argument("--metric", choices=VOC_METRICS, default="voc07", help="11-point VOC07 or all-point AP")
    p.add_argument("--iou", type=float, default=0.5, help="IoU threshold (a match needs IoU > it)")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = p.parse_args(argv)
    try:  # bad files end the command with their message, not a traceback
        result = evaluate_voc_files(args.gt_xml, args.dets, args.names, metric=args.metric, iou_threshold=args.iou)
    except (ValueError, FileNotFoundError) as err:
        sys.exit(f"{p.prog}: {err}")
    print(json.dumps(result.as_dict(), indent=2) if args.json else format_table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
