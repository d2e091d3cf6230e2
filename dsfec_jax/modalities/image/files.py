"""A user's own photos as a camera model's input (modalities/files.py reads the PATHs): JPEG or PNG,
decoded by Pillow (grey and palette images become RGB). A truncated or corrupt file is refused,
naming it; so is one with more than MAX_PIXELS pixels (Pillow's decompression-bomb limit)."""

from __future__ import annotations

from pathlib import Path

from PIL import Image

from ...boxes.boxes2d import Boxes2D
from ...data.camera.images import CameraImage
from ...data.camera.voc import UnreadableImage, load_image
from ..files import FileReader, InputFileError, fail

MAX_PIXELS = Image.MAX_IMAGE_PIXELS  # ~89 M: a photo is far below it


def read_image(path: Path, cfg=None, columns: str | None = None) -> CameraImage:
    """One image file as a CameraImage (no boxes), id = the path; InputFileError naming the file."""
    if columns is not None:
        raise InputFileError(f"--columns applies to point-cloud files; {path} is an image")
    try:
        with Image.open(path) as header:  # the size, before decoding anything
            width, height = header.size
        if width * height > MAX_PIXELS:
            raise fail(path, f"{width} x {height} pixels; at most {MAX_PIXELS}")
        return CameraImage(str(path), load_image(path), Boxes2D.empty())
    except UnreadableImage as err:  # its message names the file
        raise InputFileError(str(err)) from None
    except OSError as err:  # Pillow cannot even read the header
        raise fail(path, f"not a readable image ({err})") from None


def entry(item: CameraImage, found: Boxes2D) -> dict:
    """An image's detections: (x1, y1, x2, y2) in its pixels (edges)."""
    return {"image_hw": list(item.hw),
            "detections": [{"class": str(n), "score": round(float(s), 5), "xyxy_px": [round(float(c), 1) for c in b]}
                           for n, s, b in zip(found.names, found.scores, found.xyxy)]}


READER = FileReader(suffixes=(".jpg", ".jpeg", ".png"), read=read_image, entry=entry,
                    ident=lambda item: item.image_id, kinds="camera images (.jpg, .jpeg, .png)", lazy=True)
