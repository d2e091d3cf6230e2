"""PASCAL VOC files -> records and Boxes2D: the XML annotations, the `voc.names` class list, the
per-image detection text files `class_id score x1 y1 x2 y2`, and the JPEG/PNG images.

The records keep every number as the file gives it, so that a metric can be checked against the
file by eye. VOC's bndbox (xmin, ymin, xmax, ymax) is in 1-based *inclusive* pixel indices: the box
covers columns xmin..xmax, xmax - xmin + 1 pixels (that is why py-faster-rcnn's voc_eval.py adds 1
to every width). Boxes2D holds pixel *edges* (boxes/boxes2d.py), so the conversion is

    edges = (xmin - 1, ymin - 1, xmax, ymax)          (inclusive_to_edges; edges_to_inclusive undoes it)

and a width xmax - (xmin - 1) is voc_eval's xmax - xmin + 1: the plain edge IoU of Boxes2D is
voc_eval's "+1" IoU, exactly on integer coordinates. Detection files get the same conversion,
because voc_eval applies the same "+1" formula to detections (py-faster-rcnn writes them 1-based).
Tools differ here: CVAT's COCO export of these XMLs writes bbox (xmin, ymin, xmax - xmin,
ymax - ymin), one pixel left of ours and one pixel narrower.

Boxes2D holds float32 (its type): exact for integer pixels below 2**24; the records keep the file's
values as Python floats. The `difficult` flag (missing = 0) goes into Boxes2D.difficult;
`truncated` (missing = 0) stays in the record. Bad input is a ValueError naming the file (with the
line number for text files), the field and what was expected: a bndbox corner more than a margin
(2 px or 2 % of the side) outside its image, a number float32 cannot hold, an image that does not
decode (UnreadableImage). Corners a pixel or two outside are kept as written, as voc_eval scores them. XML is parsed with ElementTree
(expat >= 2.4 refuses entity expansion bombs; external entities are never fetched).
"""

from __future__ import annotations

import dataclasses
import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ...boxes.boxes2d import Boxes2D

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
# PASCAL VOC's 20 classes, line order of darknet's data/voc.names (class id = index); the models keep
# their own copy (models/camera/config.py: models never import data), a test holds the two equal
VOC_CLASSES = tuple("aeroplane bicycle bird boat bottle bus car cat chair cow diningtable dog horse motorbike "
                    "person pottedplant sheep sofa train tvmonitor".split())
DETECTION_COLUMNS = "class_id score x1 y1 x2 y2"
MAX_IMAGE_SIDE = 65535  # JPEG's limit: a larger <size> is a broken file, not an image
# VOC's corners lie in 1..width and 1..height, yet a few files are a pixel or two off (xmin 0,
# xmax width + 1); voc_eval scores those as written, so they are kept. A corner further out than
# this margin (the larger of the two) is a broken annotation.
OFF_IMAGE_MARGIN_PX, OFF_IMAGE_MARGIN_FRACTION = 2.0, 0.02
# detection files carry no image size: coordinates past this are broken (and would not fit float32)
MAX_DETECTION_COORDINATE = 1e6
FLOAT32_MAX = float(np.finfo(np.float32).max)


@dataclasses.dataclass(frozen=True)
class VocObject:
    name: str
    bbox: tuple[float, float, float, float]  # xmin, ymin, xmax, ymax as in the file (1-based inclusive)
    difficult: bool = False
    truncated: bool = False


@dataclasses.dataclass(frozen=True)
class VocAnnotation:
    image_id: str                  # the XML file's stem (VOC's image id, e.g. "2007_000027")
    filename: str                  # <filename>: the image, relative to the images folder
    width: int
    height: int
    depth: int | None              # <size><depth>; None where the file has none
    objects: tuple[VocObject, ...]

    def boxes(self) -> Boxes2D:
        """Ground truth as Boxes2D: pixel edges, scores None, difficult flags."""
        if not self.objects:
            return dataclasses.replace(Boxes2D.empty(), difficult=np.zeros(0, bool))
        return Boxes2D(inclusive_to_edges([o.bbox for o in self.objects]).astype(np.float32),
                       np.array([o.name for o in self.objects]), None,
                       np.array([o.difficult for o in self.objects], bool))


@dataclasses.dataclass(frozen=True)
class VocDetection:
    name: str
    score: float
    bbox: tuple[float, float, float, float]  # x1, y1, x2, y2 as in the file (1-based inclusive)


# --------------------------------------------------------------------------- coordinates


def inclusive_to_edges(xyxy) -> np.ndarray:
    """VOC (xmin, ymin, xmax, ymax), 1-based inclusive -> Boxes2D edges (xmin - 1, ymin - 1, xmax, ymax)."""
    out = np.array(xyxy, np.float64).reshape(-1, 4)
    out[:, :2] -= 1.0
    return out


def edges_to_inclusive(xyxy) -> np.ndarray:
    """Boxes2D edges -> VOC 1-based inclusive (x1 + 1, y1 + 1, x2, y2): what a VOC detection file holds."""
    out = np.array(xyxy, np.float64).reshape(-1, 4)
    out[:, :2] += 1.0
    return out


def detection_boxes(detections: Sequence[VocDetection]) -> Boxes2D:
    """Detections as Boxes2D: pixel edges and scores, in file order."""
    if not detections:
        return Boxes2D.empty(with_scores=True)
    return Boxes2D(inclusive_to_edges([d.bbox for d in detections]).astype(np.float32),
                   np.array([d.name for d in detections]), np.array([d.score for d in detections], np.float32))


# --------------------------------------------------------------------------- voc.names


def read_names(path) -> tuple[str, ...]:
    """A `voc.names` file: one class per line, line index = class id. Trailing blank lines are
    allowed; a blank line inside would shift every later id, so it is an error, as are duplicates."""
    path = Path(path)
    lines = _read_text(path).splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    names = [line.strip() for line in lines]
    for i, name in enumerate(names):
        if not name:
            raise ValueError(f"{path}:{i + 1}: empty class name (line index = class id, so blank lines "
                             "are not allowed before the last class)")
        if name in names[:i]:
            raise ValueError(f"{path}:{i + 1}: class {name!r} is listed twice")
    if not names:
        raise ValueError(f"{path}: no class names")
    return tuple(names)


# --------------------------------------------------------------------------- XML annotations


def read_annotation(path) -> VocAnnotation:
    """One VOC XML file -> VocAnnotation."""
    path = Path(path)
    try:
        root = ET.fromstring(_read_bytes(path))  # bytes: the XML declaration's encoding applies
    except ET.ParseError as e:
        raise ValueError(f"{path}: malformed XML ({e})") from None
    if root.tag != "annotation":
        raise ValueError(f"{path}: root element is <{root.tag}>; expected <annotation>")
    size = _child(root, "size", path)
    depth = size.find("depth")
    width, height = (_int(size, k, "size", path, maximum=MAX_IMAGE_SIDE) for k in ("width", "height"))
    objects = tuple(_object(o, f"object[{i}]", path, (width, height)) for i, o in enumerate(root.findall("object")))
    return VocAnnotation(path.stem, _text(root, "filename", path), width, height,
                         None if depth is None else _int(size, "depth", "size", path, minimum=0), objects)


def _object(node: ET.Element, where: str, path: Path, image_wh: tuple[int, int]) -> VocObject:
    box = _child(node, "bndbox", path, where)
    xmin, ymin, xmax, ymax = (_corner(box, k, f"{where}.bndbox", path, image_wh) for k in ("xmin", "ymin", "xmax", "ymax"))
    if xmin > xmax or ymin > ymax:
        raise ValueError(f"{path}: {where}.bndbox: expected xmin <= xmax and ymin <= ymax; "
                         f"got ({xmin:g}, {ymin:g}, {xmax:g}, {ymax:g})")
    return VocObject(_text(node, "name", path, where), (xmin, ymin, xmax, ymax),
                     _flag(node, "difficult", where, path), _flag(node, "truncated", where, path))


def _child(node: ET.Element, tag: str, path: Path, where: str = "") -> ET.Element:
    child = node.find(tag)
    if child is None:
        raise ValueError(f"{path}: {where + '.' if where else ''}{tag}: missing element <{tag}>")
    return child


def _text(node: ET.Element, tag: str, path: Path, where: str = "") -> str:
    text = (_child(node, tag, path, where).text or "").strip()
    if not text:
        raise ValueError(f"{path}: {where + '.' if where else ''}{tag}: empty; expected text")
    return text


def _number(node: ET.Element, tag: str, where: str, path: Path) -> float:
    return _field(_text(node, tag, path, where), f"{where}.{tag}", str(path))


def _corner(box: ET.Element, tag: str, where: str, path: Path, image_wh: tuple[int, int]) -> float:
    """A bndbox corner, within the image give or take the off-by-a-pixel margin (kept as written)."""
    value = _number(box, tag, where, path)
    side = image_wh[1] if tag.startswith("y") else image_wh[0]
    margin = max(OFF_IMAGE_MARGIN_PX, OFF_IMAGE_MARGIN_FRACTION * side)
    if not 1 - margin <= value <= side + margin:
        raise ValueError(f"{path}: {where}.{tag}: {value:g} lies outside the {image_wh[0]} x {image_wh[1]} image "
                         f"(expected 1..{side}, give or take {margin:g} px)")
    return value


def _int(node: ET.Element, tag: str, where: str, path: Path, minimum: int = 1, maximum: int | None = None) -> int:
    text = _text(node, tag, path, where)
    if not (text.isascii() and text.isdigit()) or int(text) < minimum or (maximum is not None and int(text) > maximum):
        expected = f"an integer >= {minimum}" if maximum is None else f"an integer in {minimum}..{maximum}"
        raise ValueError(f"{path}: {where}.{tag}: expected {expected}; got {text!r:.40}")
    return int(text)


def _flag(node: ET.Element, tag: str, where: str, path: Path) -> bool:
    """A 0/1 flag; a missing element is 0 (VOC2012 files omit <difficult> on some objects)."""
    if node.find(tag) is None:
        return False
    text = _text(node, tag, path, where)
    if text not in ("0", "1"):
        raise ValueError(f"{path}: {where}.{tag}: expected 0 or 1; got {text!r:.40}")
    return text == "1"


# --------------------------------------------------------------------------- detection files


def read_detections(path, names: Sequence[str]) -> tuple[VocDetection, ...]:
    """A detection file, one `class_id score x1 y1 x2 y2` per line (blank lines skipped); class_id
    indexes `names` (read_names)."""
    path = Path(path)
    out = []
    for number, line in enumerate(_read_text(path).splitlines(), start=1):
        fields = line.split()
        if not fields:
            continue
        where = f"{path}:{number}"
        if len(fields) != 6:
            raise ValueError(f"{where}: expected 6 columns '{DETECTION_COLUMNS}'; got {len(fields)}")
        if not (fields[0].isascii() and fields[0].isdigit()) or int(fields[0]) >= len(names):
            raise ValueError(f"{where}: class_id: expected an integer in 0..{len(names) - 1} (a line of "
                             f"the names file); got {fields[0]!r:.40}")
        score, *box = (_field(v, k, where) for v, k in zip(fields[1:], DETECTION_COLUMNS.split()[1:]))
        for value, name in zip(box, DETECTION_COLUMNS.split()[2:]):
            if abs(value) > MAX_DETECTION_COORDINATE:
                raise ValueError(f"{where}: {name}: {value:g} is no pixel coordinate (expected at most "
                                 f"{MAX_DETECTION_COORDINATE:g} in size)")
        if box[0] > box[2] or box[1] > box[3]:
            raise ValueError(f"{where}: expected x1 <= x2 and y1 <= y2; got {tuple(box)}")
        out.append(VocDetection(str(names[int(fields[0])]), score, tuple(box)))
    return tuple(out)


def _field(text: str, name: str, where: str) -> float:
    """A finite number that float32 (Boxes2D) holds as a finite number too."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise ValueError(f"{where}: {name}: expected a finite number; got {text!r:.40}")
    if abs(value) > FLOAT32_MAX:
        raise ValueError(f"{where}: {name}: {text!r:.40} does not fit float32 (at most {FLOAT32_MAX:.3g} in size)")
    return value


# --------------------------------------------------------------------------- folders and images


def read_annotation_dir(directory) -> dict[str, VocAnnotation]:
    """Every *.xml of a folder, image id -> VocAnnotation, sorted by image id."""
    return {p.stem: read_annotation(p) for p in _files(directory, ".xml")}


def read_detection_dir(directory, names: Sequence[str]) -> dict[str, tuple[VocDetection, ...]]:
    """Every *.txt of a folder, image id (file stem) -> its detections, sorted by image id."""
    return {p.stem: read_detections(p, names) for p in _files(directory, ".txt")}


def image_path(annotation: VocAnnotation, images_dir) -> Path:
    """The image an annotation names (<filename>, a bare name inside images_dir)."""
    name = Path(annotation.filename)
    if name.name != annotation.filename or name.suffix.lower() not in IMAGE_SUFFIXES:
        raise ValueError(f"annotation {annotation.image_id!r}: filename {annotation.filename!r} is not a "
                         f"bare image name ending in one of {IMAGE_SUFFIXES}")
    return Path(images_dir) / name


class UnreadableImage(ValueError):
    """An image file that does not decode (truncated, corrupt, not an image); the message names it.
    Images are decoded on access, so the commands catch it around their loops over images."""


def load_image(path) -> np.ndarray:
    """A JPEG/PNG -> (H, W, 3) uint8 RGB (Pillow; grey and palette images are converted)."""
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such image")
    try:
        with Image.open(path) as image:
            return np.asarray(image.convert("RGB"))
    except (UnidentifiedImageError, OSError) as e:
        raise UnreadableImage(f"{path}: not a readable image ({e})") from None


def _files(directory, suffix: str) -> list[Path]:
    directory = Path(directory)
    if not directory.is_dir():
        raise FileNotFoundError(f"{directory}: no such folder")
    files = sorted(p for p in directory.iterdir() if p.suffix == suffix and p.is_file())
    if not files:
        raise ValueError(f"{directory}: no *{suffix} files")
    return files


def _read_bytes(path: Path) -> bytes:
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    return path.read_bytes()


def _read_text(path: Path) -> str:
    try:
        return _read_bytes(path).decode("utf-8")
    except UnicodeDecodeError as e:
        raise ValueError(f"{path}: not UTF-8 text ({e})") from None
