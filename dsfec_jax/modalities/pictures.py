"""Which detections a predict picture draws, for every modality.

`--png-min-score S` draws exactly those scoring at least S. Without it, those scoring at least
PNG_MIN_SCORE; when no detection of a picture reaches it, the FALLBACK_BEST best are drawn and the title says so. A model trained on synthetic
frames often scores below 0.25 on real photos (the shipped Shuffle-YOLOv3 on the VOC images: best
0.22), and a picture with ground truth only read as "the model found nothing" when it had found
boxes at 0.2. The labels carry every drawn box's score, so a low one shows as low.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Iterator

import numpy as np
from tqdm import tqdm

from ..core.progress import quiet

# the predict pictures' default: ultralytics' predict confidence (ultralytics/ultralytics:
# ultralytics/engine/predictor.py sets conf 0.25 when none is given); at the evaluation thresholds
# (points 0.05, RD 0.001, camera 0.005) a picture would carry hundreds of boxes, mostly noise
PNG_MIN_SCORE = 0.25
FALLBACK_BEST = 3
PICTURE_BATCH = 8  # the predictors' default batch (predict_samples), which validations run at


def drawn(scores, given: float | None) -> tuple[np.ndarray, str]:
    """(which detections to draw, what the title says of them); `given`: --png-min-score."""
    scores = np.asarray(scores, np.float32)
    threshold = PNG_MIN_SCORE if given is None else given
    keep = scores >= threshold
    if keep.any() or given is not None or not len(scores):
        count = int(keep.sum())
        return keep, f"{count} detection{'' if count == 1 else 's'} >= {threshold:g}"
    best = np.zeros(len(scores), bool)
    best[np.argsort(-scores, kind="stable")[:FALLBACK_BEST]] = True
    return best, f"none >= {threshold:g}: the {int(best.sum())} best shown"


def picture_names(ids) -> dict[str, str]:
    """item id -> its picture's file name: the id's last part (an --input file's name, extension
    kept: 070099.bin.png), or the whole id made flat where two last parts are the same."""
    ids = list(ids)
    last = [i.replace("\\", "/").rstrip("/").rsplit("/", 1)[-1] for i in ids]
    clash = {n for n in last if last.count(n) > 1}
    flat = [i.strip("/").replace("/", "_").replace("\\", "_") for i in ids]
    return {i: f"{(f if n in clash else n) or f'item_{k:06d}'}.png" for k, (i, n, f) in enumerate(zip(ids, last, flat))}


def picture_title(item_id: str) -> str:
    """The id as a title: the file name and its folder for a path, the id itself otherwise."""
    parts = item_id.split("/")
    return "/".join(parts[-2:]) if len(parts) > 2 else item_id


def planned(args, items, detections: dict, ident: Callable) -> Iterator[tuple]:
    """(item, its detections, which of them to draw, the picture's path, its title) for each item,
    when --png-dir is given; `ident(item)` -> the item's key in `detections`."""
    if not args.png_dir:
        return
    names = picture_names(detections)
    for i in tqdm(range(len(items)), desc="figures", unit="figure", disable=quiet()):
        item = items[i]
        key = ident(item)
        keep, note = drawn(detections[key].scores, args.png_min_score)
        yield item, detections[key], keep, Path(args.png_dir) / names[key], f"{picture_title(key)}: {args.model}, {note}"


def training_picture(predictor, items, ident: Callable, render: Callable) -> bytes:
    """PNG bytes of the predict picture of `items[0]` (a validation's first item), for TensorBoard
    (train/tensorboard.py). The first full batch is predicted, the shape the validation has
    compiled, so the picture costs no compile. `render(item, its detections, which to draw,
    title)` -> PNG bytes; the detections drawn are those a predict picture draws (`drawn`)."""
    item = items[0]
    key = ident(item)
    first = [items[i] for i in range(min(len(items), PICTURE_BATCH))]  # by index: a lazy split does not slice
    found = predictor.predict_samples(first)[key]
    keep, note = drawn(found.scores, None)
    return render(item, found, keep, f"{picture_title(key)}: {note}")
