"""VOC-style ground truth (Boxes2D with difficult flags, sample ids like "2007_000027") <-> COCO
JSON, through coco_json (the one COCO reader and writer of the project); this module adds only the
two things COCO has no field for.

- difficult <-> iscrowd. COCO has no "difficult"; its nearest notion is the crowd region, which
  COCOeval also neither rewards nor penalises. So a difficult box is written with iscrowd 1 and a
  crowd box reads back as difficult. The semantics are close, not equal: COCOeval lets any number
  of detections fall on a crowd region and measures their overlap as intersection / detection area.
- Sample ids are not integers in VOC, so coco_json numbers the images 1..N and writes the sample
  id as "file_name". Reading, the sample id is the file_name's stem ("2007_000027.jpg" ->
  "2007_000027", which also reads CVAT's exports), falling back to str(image id) without one.

Coordinates are Boxes2D's pixel edges both ways (coco_json: bbox = [x1, y1, x2 - x1, y2 - y1]).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import PurePosixPath

import numpy as np

from ...boxes.boxes2d import Boxes2D
from .coco_json import coco_gt_from_dict, coco_gt_to_dict, read_json


def voc_gt_to_coco(gts: Mapping[str, Boxes2D], classes: Sequence[str]) -> dict:
    """Ground truth per sample -> a COCO ground-truth object, difficult written as iscrowd."""
    crowd = {sid: (np.zeros(len(b), bool) if b.difficult is None else np.asarray(b.difficult, bool))
             for sid, b in gts.items()}
    return coco_gt_to_dict(gts, classes, iscrowd=crowd)


def voc_gt_from_coco(data, source: str = "<dict>") -> dict[str, Boxes2D]:
    """A COCO ground-truth object -> sample id (file_name stem) -> Boxes2D, iscrowd read as difficult."""
    gt = coco_gt_from_dict(data, source)
    stems = {str(image["id"]): PurePosixPath(str(image["file_name"])).stem if image.get("file_name") else
             str(image["id"]) for image in data["images"]}
    if len(set(stems.values())) != len(stems):
        raise ValueError(f"{source}: images: two images share a file_name stem; sample ids must be unique")
    return {stems[key]: dataclasses.replace(boxes, difficult=gt.iscrowd[key]) for key, boxes in gt.boxes.items()}


def load_voc_gt_from_coco(path) -> dict[str, Boxes2D]:
    return voc_gt_from_coco(read_json(path), str(path))
