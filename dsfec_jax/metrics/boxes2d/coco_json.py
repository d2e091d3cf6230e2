"""COCO JSON <-> per-sample Boxes2D, the exchange format of 2D detection.

Ground truth is a dict {"images": [{"id"}], "annotations": [{"image_id", "category_id",
"bbox": [x, y, w, h], "area"?, "iscrowd"?}], "categories": [{"id", "name"}]}; detections are the
results list [{"image_id", "category_id", "bbox": [x, y, w, h], "score"}] (cocodataset.org
"results format"). COCO's bbox is (x, y) of the top-left pixel edge plus width and height, the same
edges as Boxes2D's xyxy, so the conversion is xyxy <-> xywh and nothing else.

- Classes are category names; category ids are kept as the file numbers them (writing from names
  numbers them 1..C in the order given, COCO's convention).
- Sample ids are strings, image ids integers. Reading, sample id = str(image id). Writing, image
  id = int(sample id) when every sample id is a plain decimal integer (so a file survives a round
  trip), otherwise 1..N in the mapping's order; the sample id goes to the image's "file_name".
- area: COCOeval sorts ground truth into small / medium / large by the annotation's "area", which
  COCO takes from the segmentation mask, not the box. A file's area is kept as read and written
  back unchanged; without one (or for boxes made here) it is w * h of the box.
- iscrowd: kept per box (COCOeval neither misses nor penalises crowd regions); default 0.
- Boxes2D holds float32 coordinates: a round trip moves a coordinate by <= 1 float32 ulp (about
  3e-5 px at 500 px), which changes no COCO number at the 1e-6 level (the oracle test checks it).

Malformed input is a ValueError naming the file (or "<dict>") and the field, e.g.
"gt.json: annotations[3].bbox: expected [x, y, w, h] with w, h >= 0".
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ...boxes.boxes2d import Boxes2D, xywh_to_xyxy, xyxy_to_xywh

INT64 = (-(2**63), 2**63)


@dataclasses.dataclass(frozen=True)
class CocoGroundTruth:
    """A COCO ground-truth file as Boxes2D per sample, plus what COCOeval reads beyond the boxes."""
    boxes: dict[str, Boxes2D]        # sample id -> ground truth (scores None), every image, even empty
    category_ids: dict[str, int]     # class name -> COCO category id, in category-id order
    image_ids: dict[str, int]        # sample id -> COCO image id
    areas: dict[str, np.ndarray]     # sample id -> (K,) float64, the file's area or w * h
    iscrowd: dict[str, np.ndarray]   # sample id -> (K,) bool

    @property
    def classes(self) -> tuple[str, ...]:
        return tuple(self.category_ids)

    def to_dict(self) -> dict:
        return coco_gt_to_dict(self.boxes, self.classes, image_ids=self.image_ids,
                               category_ids=self.category_ids, areas=self.areas, iscrowd=self.iscrowd)


# --------------------------------------------------------------------------- field checks


def read_json(path) -> object:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        return json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as e:
        raise ValueError(f"{path}: not valid JSON ({e})") from None


def _integer(value, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not INT64[0] <= value < INT64[1]:
        raise ValueError(f"{where}: expected an integer id; got {value!r:.40}")
    return int(value)


def _number(value, where: str, minimum: float | None = None) -> float:
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    try:
        number = float(value) if ok else math.nan
    except OverflowError:
        number = math.nan
    if not math.isfinite(number) or (minimum is not None and number < minimum):
        bound = "" if minimum is None else f" >= {minimum:g}"
        raise ValueError(f"{where}: expected a finite number{bound}; got {value!r:.40}")
    return number


def _bbox(value, where: str) -> list[float]:
    if not isinstance(value, (list, tuple)) or len(value) != 4:
        raise ValueError(f"{where}: expected [x, y, w, h] (4 numbers); got {value!r:.60}")
    x, y = (_number(v, where) for v in value[:2])
    w, h = (_number(v, where, minimum=0.0) for v in value[2:])
    # boxes are kept as float32 corners: a corner past float32's range would become inf there
    with np.errstate(over="ignore"):
        corners = np.array([x, y, x + w, y + h], np.float64).astype(np.float32)
    if not np.isfinite(corners).all():
        raise ValueError(f"{where}: expected corners x, y, x + w, y + h within float32's range "
                         f"(|v| <= {float(np.finfo(np.float32).max):.4g}); got {value!r:.60}")
    return [x, y, w, h]


def _records(data, key: str, source: str) -> list:
    if not isinstance(data, dict):
        raise ValueError(f"{source}: expected a COCO object with 'images', 'annotations', 'categories'; "
                         f"got {type(data).__name__}")
    records = data.get(key)
    if not isinstance(records, list):
        raise ValueError(f"{source}: field '{key}' must be a list; got {type(records).__name__}")
    for i, r in enumerate(records):
        if not isinstance(r, dict):
            raise ValueError(f"{source}: {key}[{i}] must be an object; got {type(r).__name__}")
    return records


def _get(record: dict, key: str, where: str):
    if key not in record:
        raise ValueError(f"{where}: missing field '{key}'")
    return record[key]


# --------------------------------------------------------------------------- ground truth


def _categories(data, source: str) -> dict[int, str]:
    names: dict[int, str] = {}
    for i, c in enumerate(_records(data, "categories", source)):
        where = f"{source}: categories[{i}]"
        cid = _integer(_get(c, "id", where), f"{where}.id")
        name = _get(c, "name", where)
        if not isinstance(name, str) or not name:
            raise ValueError(f"{where}.name: expected a non-empty string; got {name!r:.40}")
        if cid in names or name in names.values():
            raise ValueError(f"{where}: duplicate category id {cid} or name {name!r}")
        names[cid] = name
    return dict(sorted(names.items()))


def _image_ids(data, source: str) -> list[int]:
    ids = [_integer(_get(r, "id", f"{source}: images[{i}]"), f"{source}: images[{i}].id")
           for i, r in enumerate(_records(data, "images", source))]
    if len(set(ids)) != len(ids):
        raise ValueError(f"{source}: images: duplicate image ids")
    return ids


def _image_and_category(record, where: str, images: tuple, categories: tuple) -> tuple[int, int]:
    """A record's image_id and category_id, each checked against (known ids, what to say if not)."""
    ids = []
    for field, (known, unknown) in (("image_id", images), ("category_id", categories)):
        value = _integer(_get(record, field, where), f"{where}.{field}")
        if value not in known:
            raise ValueError(f"{where}.{field}: {value} {unknown}")
        ids.append(value)
    return ids[0], ids[1]


def coco_gt_from_dict(data, source: str = "<dict>") -> CocoGroundTruth:
    """A parsed COCO ground-truth object -> CocoGroundTruth (every image, including empty ones)."""
    categories = _categories(data, source)
    image_ids = _image_ids(data, source)
    rows: dict[int, list] = {i: [] for i in image_ids}
    for i, a in enumerate(_records(data, "annotations", source)):
        where = f"{source}: annotations[{i}]"
        image, category = _image_and_category(a, where, (rows, "is not in 'images'"),
                                              (categories, "is not in 'categories'"))
        bbox = _bbox(_get(a, "bbox", where), f"{where}.bbox")
        area = _number(a["area"], f"{where}.area", minimum=0.0) if "area" in a else bbox[2] * bbox[3]
        crowd = a.get("iscrowd", 0)
        if crowd not in (0, 1) or isinstance(crowd, float):
            raise ValueError(f"{where}.iscrowd: expected 0 or 1; got {crowd!r:.40}")
        rows[image].append((bbox, categories[category], area, bool(crowd)))
    boxes, areas, iscrowd = {}, {}, {}
    for image, found in rows.items():
        sid = str(image)
        boxes[sid] = _boxes([r[0] for r in found], [r[1] for r in found])
        areas[sid] = np.array([r[2] for r in found], np.float64)
        iscrowd[sid] = np.array([r[3] for r in found], bool)
    return CocoGroundTruth(boxes, {name: cid for cid, name in categories.items()},
                           {str(i): i for i in image_ids}, areas, iscrowd)


def _boxes(xywh: list, names: list, scores: list | None = None) -> Boxes2D:
    if not names:
        return Boxes2D.empty(with_scores=scores is not None)
    return Boxes2D(xywh_to_xyxy(np.array(xywh, np.float64)).astype(np.float32), np.array(names),
                   None if scores is None else np.array(scores, np.float32))


def default_image_ids(sample_ids: Sequence[str]) -> dict[str, int]:
    """int(sample id) when every sample id is a plain decimal integer, else 1..N in order."""
    ids = [str(s) for s in sample_ids]
    if ids and all(s.isascii() and s.isdigit() and str(int(s)) == s and int(s) < INT64[1] for s in ids):
        return {s: int(s) for s in ids}
    return {s: i + 1 for i, s in enumerate(ids)}


def default_category_ids(classes: Sequence[str]) -> dict[str, int]:
    return {str(name): i + 1 for i, name in enumerate(classes)}


def _checked_ids(ids: Mapping[str, int], keys, what: str) -> dict[str, int]:
    missing = [k for k in keys if k not in ids]
    if missing:
        raise ValueError(f"{what} has no id for {missing[:5]}")
    out = {str(k): _integer(v, f"{what}[{k!r}]") for k, v in ids.items()}
    if len(set(out.values())) != len(out):
        raise ValueError(f"{what}: ids must be unique")
    return out


def coco_gt_to_dict(gts: Mapping[str, Boxes2D], classes: Sequence[str], *,
                    image_ids: Mapping[str, int] | None = None, category_ids: Mapping[str, int] | None = None,
                    areas: Mapping[str, np.ndarray] | None = None,
                    iscrowd: Mapping[str, np.ndarray] | None = None) -> dict:
    """Per-sample ground truth -> a COCO ground-truth object (annotation ids 1..N: COCOeval needs
    them non-zero). areas / iscrowd per sample override w * h / 0."""
    image_ids = _checked_ids(image_ids or default_image_ids(list(gts)), list(gts), "image_ids")
    category_ids = _checked_ids(category_ids or default_category_ids(classes), [str(c) for c in classes],
                                "category_ids")
    annotations = []
    for sid, boxes in gts.items():
        xywh = xyxy_to_xywh(boxes.xyxy).reshape(-1, 4)
        area = np.prod(xywh[:, 2:], axis=1) if areas is None or sid not in areas else np.asarray(areas[sid])
        crowd = np.zeros(len(boxes), bool) if iscrowd is None or sid not in iscrowd else np.asarray(iscrowd[sid])
        if area.shape != (len(boxes),) or crowd.shape != (len(boxes),):
            raise ValueError(f"sample {sid!r}: areas / iscrowd must have one entry per box ({len(boxes)})")
        for k in range(len(boxes)):
            name = str(boxes.names[k])
            if name not in category_ids:
                raise ValueError(f"ground truth of sample {sid!r}: class {name!r} is not one of {tuple(classes)}")
            annotations.append({"id": len(annotations) + 1, "image_id": image_ids[sid],
                                "category_id": category_ids[name], "bbox": [float(v) for v in xywh[k]],
                                "area": float(area[k]), "iscrowd": int(crowd[k])})
    return {"images": [{"id": image_ids[sid], "file_name": sid} for sid in gts],
            "annotations": annotations,
            "categories": [{"id": cid, "name": name} for name, cid in category_ids.items()
                           if name in {str(c) for c in classes}]}


def load_coco_gt(path) -> CocoGroundTruth:
    return coco_gt_from_dict(read_json(path), str(path))


# --------------------------------------------------------------------------- detections


def coco_dets_from_list(results, category_ids: Mapping[str, int], image_ids: Mapping[str, int],
                        source: str = "<list>") -> dict[str, Boxes2D]:
    """A COCO results list -> sample id -> Boxes2D with scores, for every sample in image_ids (in
    that order), keeping each image's detections in file order (COCOeval breaks score ties by it)."""
    if not isinstance(results, list):
        raise ValueError(f"{source}: expected a COCO results list of detections; got {type(results).__name__}")
    names = {cid: name for name, cid in category_ids.items()}
    samples = {iid: sid for sid, iid in image_ids.items()}
    rows: dict[str, list] = {sid: [] for sid in image_ids}
    for i, d in enumerate(results):
        where = f"{source}: [{i}]"
        if not isinstance(d, dict):
            raise ValueError(f"{where}: expected an object; got {type(d).__name__}")
        image, category = _image_and_category(d, where, (samples, "is not an image of the ground truth"),
                                              (names, "is not a category of the ground truth"))
        bbox = _bbox(_get(d, "bbox", where), f"{where}.bbox")
        score = _number(_get(d, "score", where), f"{where}.score")
        rows[samples[image]].append((bbox, names[category], score))
    return {sid: _boxes([r[0] for r in found], [r[1] for r in found], [r[2] for r in found])
            for sid, found in rows.items()}


def coco_dets_to_list(dets: Mapping[str, Boxes2D], category_ids: Mapping[str, int],
                      image_ids: Mapping[str, int]) -> list[dict]:
    """sample id -> Boxes2D with scores -> a COCO results list, each sample's boxes in their order."""
    results = []
    for sid, boxes in dets.items():
        if sid not in image_ids:
            raise ValueError(f"detections for sample {sid!r}, which has no image id (no ground-truth entry)")
        if boxes.scores is None:
            raise ValueError(f"detections of sample {sid!r} need scores (Boxes2D.scores is None)")
        xywh = xyxy_to_xywh(boxes.xyxy).reshape(-1, 4)
        for k in range(len(boxes)):
            name = str(boxes.names[k])
            if name not in category_ids:
                raise ValueError(f"detections of sample {sid!r}: class {name!r} is not one of {tuple(category_ids)}")
            score = float(boxes.scores[k])
            if not math.isfinite(score):
                raise ValueError(f"detections of sample {sid!r}: score {score} is not finite")
            results.append({"image_id": image_ids[sid], "category_id": category_ids[name],
                            "bbox": [float(v) for v in xywh[k]], "score": score})
    return results


def load_coco_dets(path, gt: CocoGroundTruth) -> dict[str, Boxes2D]:
    """A results file (a list, or an object with the list under 'annotations') against its ground truth."""
    data = read_json(path)
    if isinstance(data, dict) and isinstance(data.get("annotations"), list):
        data = data["annotations"]
    return coco_dets_from_list(data, gt.category_ids, gt.image_ids, str(path))
