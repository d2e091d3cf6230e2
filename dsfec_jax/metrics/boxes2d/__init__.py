"""Metrics for axis-aligned 2D boxes (range-Doppler maps and camera images), all on
per-sample mappings sample id -> boxes.boxes2d.Boxes2D (ground truth: scores None; detections:
scores).

- ``coco_json``: COCO ground-truth / results JSON <-> per-sample Boxes2D.
- ``coco``: COCO AP through pycocotools (the reference): mAP@[.5:.95], AP50, AP75, AP@30, AP@70,
  per class, and the 12 standard stats.
- ``darod``: the DAROD protocol (IoU 0.1/0.3/0.5/0.7, class-agnostic best-GT matching, all-point
  AP, score > 0.5 and at most 30 detections): what the RD papers' DAROD rows mean.
- ``ultralytics_ap``: ultralytics' validation AP (101-point np.interp + trapezoid), for YOLO users.
- ``voc_ap``: PASCAL VOC AP as py-faster-rcnn's voc_eval.py (VOC07 11-point or all-point, strict
  IoU > 0.5 with +1-pixel widths, difficult GT neither TP nor FP); ``voc_coco``: VOC ground truth
  <-> COCO JSON (difficult as iscrowd).

The protocols give different numbers on the same detections; compare a number only with one
computed by the same protocol. Submodules are imported explicitly (nothing re-exported here), so
that importing the package does not import pycocotools.
"""
