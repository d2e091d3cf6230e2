"""The street benchmark on disk: PNG images plus one compressed .npz per frame, and a manifest.

Layout (`write_cache`): street_000000.png (left image), street_000000_right.png (when the config
renders the right camera), street_000000.npz (depth float32, instances int32, boxes, names,
difficult flags, the 3D objects, the ego pose and camera as JSON, the GPS fixes, meta), each file
written atomically, and, written last, manifest.json in data/npz_cache.py's layout (format
"dsfec_jax.street.frames", its version, the package and numpy versions, the generator's config,
split, seed, count, the camera it implies, the .npz names) plus the lists `images` and
`right_images`. A rewrite deletes the manifest first, so a directory without one was not
finished. `StreetCachedDataset` checks the manifest (npz_cache's checks, and that every listed
PNG is a relative path inside the cache and exists) before reading; a damaged file raises
ValueError naming it. PNGs are written by core/png.py and read back with Pillow (a project
dependency for the camera family); loading needs no pickle.
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
from pathlib import Path

import numpy as np

from .... import __version__
from ....boxes.boxes2d import Boxes2D
from ....core import atomic
from ....core.png import png_bytes
from ....core.progress import generating
from ...npz_cache import MANIFEST, NpzCachedDataset, NpzCacheFormat, npz_meta
from ...paths import inside
from ...records import check_fields
from ...splits import check_index
from .camera import PinholeCamera
from .config import FORMAT_VERSION, StreetConfig
from .frame import StreetFrame, StreetObjects
from .generate import StreetDataset
from .geo import EgoPose, GpsTrack


def frame_npz_bytes(frame: StreetFrame) -> bytes:
    """Everything of a frame but its images, as compressed .npz bytes (meta as JSON, no pickle)."""
    b = frame.boxes
    arrays = dict(depth=frame.depth.astype(np.float32), instances=frame.instances.astype(np.int32),
                  box_xyxy=b.xyxy.astype(np.float32), box_names=np.asarray(b.names).astype("<U16"),
                  box_difficult=np.asarray(b.difficult, bool), frame_id=np.array(frame.frame_id),
                  baseline_m=np.array(frame.baseline_m, np.float64),
                  camera_json=np.array(json.dumps(dataclasses.asdict(frame.camera))),
                  ego_json=np.array(json.dumps(frame.ego.to_dict())),
                  meta_json=np.array(json.dumps(frame.meta)),
                  **frame.objects.arrays(), **frame.gps.arrays())
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def frame_fields_from_npz(z) -> dict:
    """The StreetFrame fields of a `frame_npz_bytes` file, without the images."""
    xyxy, names, difficult = z["box_xyxy"], z["box_names"], z["box_difficult"]
    if xyxy.dtype.kind != "f" or names.dtype.kind != "U" or difficult.dtype != bool or z["depth"].dtype != np.float32:
        raise ValueError(f"box_xyxy must be float, box_names text, box_difficult bool and depth float32; got "
                         f"{xyxy.dtype}, {names.dtype}, {difficult.dtype}, {z['depth'].dtype}")
    camera = json.loads(str(z["camera_json"]))
    ego = json.loads(str(z["ego_json"]))
    if not isinstance(camera, dict) or not isinstance(ego, dict):
        raise ValueError("camera_json and ego_json must hold JSON objects")
    return dict(boxes=Boxes2D(xyxy, names, None, difficult), objects=StreetObjects.from_arrays(z),
                depth=z["depth"], instances=z["instances"], camera=PinholeCamera(**camera),
                baseline_m=float(z["baseline_m"]), ego=EgoPose.from_dict(ego),
                gps=GpsTrack(*(np.asarray(z[f"gps_{k}"]) for k in ("time_s", "lat", "lon", "alt", "enu"))),
                frame_id=str(z["frame_id"]), meta=npz_meta(z))


def read_png(path: Path) -> np.ndarray:
    """An (H, W, 3) uint8 RGB image; ValueError naming the file when it is not a readable image."""
    from PIL import Image, UnidentifiedImageError
    try:
        with Image.open(path) as im:
            return np.asarray(im.convert("RGB"))
    except (OSError, UnidentifiedImageError, ValueError, SyntaxError) as e:
        raise ValueError(f"{path}: not a readable PNG image ({type(e).__name__}: {e})") from None


class StreetCacheFormat(NpzCacheFormat):
    """npz_cache's format with the frame's PNGs written beside each .npz and listed in the manifest."""

    def write(self, dataset, directory: str | os.PathLike) -> Path:
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        (directory / MANIFEST).unlink(missing_ok=True)  # an unfinished rewrite must not look valid
        files, images, rights = [], [], []
        for i in generating(range(len(dataset)), f"rendering {len(dataset)} street frames into the cache {directory}",
                            unit="frame"):
            frame = dataset[i]
            stem = f"{self.prefix}_{i:06d}"
            atomic.write_bytes(directory / f"{stem}.png", png_bytes(frame.image))
            images.append(f"{stem}.png")
            if frame.right is not None:
                atomic.write_bytes(directory / f"{stem}_right.png", png_bytes(frame.right))
                rights.append(f"{stem}_right.png")
            atomic.write_bytes(directory / f"{stem}.npz", self.encode(frame))
            files.append(f"{stem}.npz")
        derived = {key: value(dataset.cfg) for key, (_, value) in self.derived.items()}
        atomic.write_json(directory / MANIFEST, dict(
            format=self.name, format_version=self.version, dsfec_jax_version=__version__,
            numpy_version=np.__version__, config=dataset.cfg.to_dict(), split=dataset.split, seed=dataset.seed,
            count=len(files), **derived, files=files, images=images, right_images=rights))
        return directory

    def read_manifest(self, directory: str | os.PathLike) -> dict:
        m = super().read_manifest(directory)
        path = Path(directory) / MANIFEST
        check_fields(m, {"images": ("str_list", True), "right_images": ("str_list", True)}, str(path))
        if len(m["images"]) != m["count"] or len(m["right_images"]) not in (0, m["count"]):
            raise ValueError(f"{path}: {len(m['images'])} images and {len(m['right_images'])} right images listed "
                             f"for {m['count']} frames")
        missing = [f for f in m["images"] + m["right_images"] if not inside(directory, f, path, "images").is_file()]
        if missing:
            raise ValueError(f"{path}: {len(missing)} image files missing, e.g. {missing[0]}")
        return m


FRAMES = StreetCacheFormat(
    name="dsfec_jax.street.frames", version=FORMAT_VERSION, prefix="street", noun="frame",
    item_title="street frame", cache_title="a street benchmark cache", encode=frame_npz_bytes,
    decode=frame_fields_from_npz, config_type=StreetConfig, config_title="a StreetConfig",
    derived={"classes": ("str_list", lambda cfg: list(cfg.classes)),
             "camera": ("object", lambda cfg: cfg.camera_model().describe())})


class StreetCachedDataset(NpzCachedDataset):
    """Frames read back from a `write_cache` directory; optionally checked against a config, split, seed."""

    FORMAT = FRAMES

    def __getitem__(self, index: int) -> StreetFrame:
        index = check_index(index, len(self), self.FORMAT.noun)
        fields = self.FORMAT.read_item(self.directory / self.manifest["files"][index])
        image = read_png(self.directory / self.manifest["images"][index])
        rights = self.manifest["right_images"]
        right = read_png(self.directory / rights[index]) if rights else None
        try:
            return StreetFrame(image=image, right=right, **fields)
        except ValueError as e:
            raise ValueError(f"{self.directory / self.manifest['files'][index]}: {e}") from None


write_cache = FRAMES.write  # (dataset, directory) -> directory: PNGs and .npz per frame, then manifest.json
read_manifest = FRAMES.read_manifest


def open_cache(directory, cfg: StreetConfig, split: str, seed: int, num_frames: int) -> StreetCachedDataset:
    """The cache at `directory` if it holds exactly this dataset, else (re)build it first."""
    return StreetCachedDataset.open(directory, StreetDataset(cfg, split, seed, num_frames))


__all__ = ["FRAMES", "StreetCachedDataset", "open_cache", "read_manifest", "read_png", "write_cache"]
