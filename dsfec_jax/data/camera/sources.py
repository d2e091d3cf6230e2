"""Named camera sources -> sequences of CameraImage, what camera training, evaluation and the
commands read, and how one source's class names meet another's.

- `street` (the default): the embedded street benchmark (data/camera/street; synthetic), rendered
  at its default 416 x 234 without the right camera (a detector does not read it, and it costs
  about as much to render as the left one: docs/camera.md, "Rate"),
  materialised in memory (a training run visits each frame many times). Splits train / val / test.
- `street:DIR`: the same frames through the PNG/NPZ cache (street/cache.py), one sub-folder per
  (split, seed, count) under DIR, built on first use and reused afterwards (then read lazily).
- `voc:DIR`: PASCAL VOC, read by data/camera/voc.py, images loaded on access. DIR is a VOCdevkit
  year folder (Annotations/, JPEGImages/, ImageSets/Main/<split>.txt) or the flat layout of the 100
  real VOC2012 images in ../shared/data/voc_review_od_metrics/data/database (gts/pascalvoc_format/,
  images/, voc.names). `--split all` takes every annotation; another split needs its
  ImageSets/Main/<split>.txt (the flat layout has none). Classes: DIR/voc.names when present,
  else VOC's 20 in darknet's order.

Classes across sources (`class_map`): a model answers in its own class names. Scored on a source
with other names, each model class goes to the source class of the same name, else to its alias
(ALIASES: the street benchmark's pedestrian is VOC's person, its cyclist VOC's bicycle); classes
with neither (street's truck on VOC) are not scored. The cyclist -> bicycle pair is loose: a street
cyclist box holds the bicycle and its rider, a VOC bicycle box the bicycle only.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Sequence

from ...core.progress import generating
from ..splits import SPLITS, check_index
from . import voc
from .images import CameraImage

SOURCE_KINDS = ("street", "street:DIR", "voc:DIR")
STREET_FRAMES = 200  # `street` without a count (evaluation's default, as the RD benchmark's 200 samples)
ALL = "all"          # VOC: every annotation
# (street benchmark name, VOC name) of the same object; class_map reads the pairs both ways
ALIASES = (("pedestrian", "person"), ("cyclist", "bicycle"))


class NoImages(ValueError):
    """A source, split or count that yields no images: training or scoring on nothing is refused."""


def street_config():
    """The street benchmark as the camera family reads it: the default scene, no right camera."""
    from .street import StreetConfig
    return StreetConfig(render_right=False)


def street_image(frame) -> CameraImage:
    """A StreetFrame -> its left image and boxes (depth, stereo and GPS stay with the frame)."""
    return CameraImage(frame.frame_id, frame.image, frame.boxes)


class StreetCacheImages:
    """The frames of a street cache as CameraImage, read on access."""

    def __init__(self, cached):
        self.cached = cached

    def __len__(self) -> int:
        return len(self.cached)

    def __getitem__(self, index: int) -> CameraImage:
        return street_image(self.cached[index])

    def shapes(self) -> list[tuple[int, int]]:
        """(h, w) of every frame: the cache's camera renders them all alike."""
        camera = self.cached.cfg.camera_model()
        return [(camera.height, camera.width)] * len(self)


class VocImages:
    """VOC annotations with their images, loaded on access (a VOC year is ~17,000 images)."""

    def __init__(self, annotations: Sequence[voc.VocAnnotation], images_dir: Path):
        self.annotations, self.images_dir = list(annotations), Path(images_dir)

    def __len__(self) -> int:
        return len(self.annotations)

    def __getitem__(self, index: int) -> CameraImage:
        a = self.annotations[check_index(index, len(self), "image")]
        image = voc.load_image(voc.image_path(a, self.images_dir))
        if image.shape[:2] != (a.height, a.width):
            raise ValueError(f"{a.image_id}: image is {image.shape[1]} x {image.shape[0]}, the XML says "
                             f"{a.width} x {a.height}")
        return CameraImage(a.image_id, image, a.boxes())

    def shapes(self) -> list[tuple[int, int]]:
        """(h, w) of every image as its XML gives it (the images are checked against it on loading)."""
        return [(a.height, a.width) for a in self.annotations]


@dataclasses.dataclass(frozen=True)
class VocLayout:
    annotations: Path
    images: Path
    image_sets: Path | None


def voc_layout(root: Path) -> VocLayout:
    """Where a VOC folder keeps its XML and images (the module docstring's two layouts)."""
    for xml, images, sets in (("Annotations", "JPEGImages", "ImageSets/Main"),
                              ("gts/pascalvoc_format", "images", None)):
        if (root / xml).is_dir() and (root / images).is_dir():
            return VocLayout(root / xml, root / images, root / sets if sets else None)
    raise FileNotFoundError(f"--data voc:{root}: expected Annotations/ + JPEGImages/ (a VOCdevkit year) or "
                            "gts/pascalvoc_format/ + images/ (the review_object_detection_metrics layout)")


def voc_images(root: Path, split: str) -> VocImages:
    layout = voc_layout(root)
    annotations = voc.read_annotation_dir(layout.annotations)
    if split != ALL:
        listing = layout.image_sets / f"{split}.txt" if layout.image_sets else None
        if listing is None or not listing.is_file():
            raise NoImages(f"--data voc:{root}: no ImageSets/Main/{split}.txt for split {split!r}; "
                           f"use --split {ALL} (every annotation)")
        ids = [line.split()[0] for line in listing.read_text().splitlines() if line.strip()]
        missing = [i for i in ids if i not in annotations]
        if missing:
            raise ValueError(f"{listing}: {len(missing)} ids without an XML in {layout.annotations}, e.g. {missing[0]}")
        annotations = {i: annotations[i] for i in ids}
    return VocImages(list(annotations.values()), layout.images)


def source_classes(data: str) -> tuple[str, ...]:
    """The class names a source labels its boxes with."""
    kind, _, path = data.partition(":")
    if kind == "street":
        from .street import CLASSES
        return CLASSES
    if kind == "voc" and path:
        names = Path(path) / "voc.names"
        return voc.read_names(names) if names.is_file() else voc.VOC_CLASSES
    raise ValueError(f"--data {data!r}: expected one of {', '.join(SOURCE_KINDS)}")


def load_camera_images(data: str, split: str, count: int | None = None, seed: int = 0) -> Sequence[CameraImage]:
    """The first `count` images of `split` of the source `data` (street: `count` generated frames,
    default STREET_FRAMES, with data seed `seed`; VOC: default the whole split, seed unused)."""
    if count is not None and count < 1:
        raise NoImages(f"count={count}: expected a positive number of images (or None for the source's default)")
    kind, _, path = data.partition(":")
    if kind == "street":
        if split not in SPLITS:
            raise NoImages(f"--data {data}: splits are {SPLITS}, not {split!r}")
        from .street import StreetDataset
        dataset = StreetDataset(street_config(), split, seed, count or STREET_FRAMES)
        if not path:
            return [street_image(frame) for frame in
                    generating(dataset, f"rendering {len(dataset)} street frames ({split})", unit="frame")]
        from .street.cache import StreetCachedDataset
        folder = Path(path) / f"{split}-seed{seed}-{len(dataset)}"
        return StreetCacheImages(StreetCachedDataset.open(folder, dataset))
    if kind != "voc":
        raise ValueError(f"--data {data!r}: expected one of {', '.join(SOURCE_KINDS)}")
    if not path or not Path(path).is_dir():
        raise FileNotFoundError(f"--data {data}: expected voc:DIR with an existing folder")
    images = voc_images(Path(path), split)
    if count is not None:
        images.annotations = images.annotations[:count]
    if not len(images):
        raise NoImages(f"--data {data}: split {split!r} holds no images")
    return images


def class_map(model_classes: Sequence[str], data_classes: Sequence[str]) -> dict[str, str]:
    """model class -> the data's class of the same object (same name, else its ALIASES partner);
    model classes with neither are left out. ValueError when no class maps at all."""
    partner = {a: b for pair in ALIASES for a, b in (pair, pair[::-1])}
    data = set(data_classes)
    out = {}
    for name in model_classes:
        if name in data:
            out[name] = name
        elif partner.get(name) in data:
            out[name] = partner[name]
    if not out:
        raise ValueError(f"no class of the model {list(model_classes)} is a class of the data {list(data_classes)} "
                         f"(aliases: {dict(ALIASES)})")
    return out
