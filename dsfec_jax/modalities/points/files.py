"""A user's own radar point clouds as a point model's input (modalities/files.py reads the PATHs).

- `.pcd`: a nuScenes radar sweep (the 18-field binary layout nuScenes writes), read, filtered and
  turned into the nuScenes columns as the nuScenes reader does for one sweep (data/points/nuscenes.py).
- `.bin`: float32 rows as VoD and TJ4DRadSet write them. The file does not say its columns: they
  come from `--columns` (vod, tj4d, nuscenes or names such as x,y,z,rcs,v_r,v_r_comp,time), else
  from a model that reads a source's own columns (RadarNeXt: its config's point_features). DSFEC
  reads nuScenes columns, which no .bin source writes, so a .bin needs --columns for it.

The points then map onto the model's columns as the dataset sources do (data/points/sources.MAPPERS:
VoD / TJ4D columns -> DSFEC's). Non-finite values are refused, naming the file, rather than dropped
(the dataset readers drop them: a user's file with NaNs is more likely a wrong --columns).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ... import zoo
from ...boxes.structures import Boxes
from ...core.columns import NUSCENES_FEATURES, TJ4D_FEATURES, VOD_FEATURES
from ...data.points.frame import Frame
from ...data.points.nuscenes import filter_radar_points, radar_features, read_radar_pcd
from ...data.points.pillarize import select_columns
from ...data.points.sources import MAPPERS
from ..files import FileReader, InputFileError, fail

LAYOUTS = {"nuscenes": NUSCENES_FEATURES, "vod": VOD_FEATURES, "tj4d": TJ4D_FEATURES}
MAX_FILE_BYTES = 256 << 20  # a radar scan is KBs (VoD ~20 kB, a nuScenes sweep ~4 kB): bigger is not a scan
SOURCE = "file"


def bin_columns(columns: str | None, cfg, path: Path) -> tuple[str, ...]:
    """The column names of a .bin: --columns (a layout name or comma-separated names, x, y, z
    first), else the model's own when it reads a source's columns; InputFileError otherwise."""
    if columns is None:
        if zoo.family_of(cfg).points.input_columns == "native":
            return tuple(cfg.point_features)
        raise fail(path, f"a .bin does not say its columns; pass --columns ({' | '.join(LAYOUTS)} or names "
                         f"such as x,y,z,rcs,v_r,v_r_comp,time) for {cfg.name}")
    names = LAYOUTS.get(columns) or tuple(c.strip() for c in columns.split(",") if c.strip())
    if names[:3] != ("x", "y", "z") or len(set(names)) != len(names):
        raise InputFileError(f"--columns {columns!r}: expected {' | '.join(LAYOUTS)} or unique names starting x,y,z")
    return names


def read_bin(path: Path, names: tuple[str, ...]) -> np.ndarray:
    """(N, len(names)) float32 rows of a .bin; InputFileError naming the file for a size that is
    not whole rows or a non-finite value."""
    size = path.stat().st_size
    if size > MAX_FILE_BYTES:
        raise fail(path, f"{size} B; a radar scan file is at most {MAX_FILE_BYTES} B")
    row = 4 * len(names)
    if size % row:
        raise fail(path, f"size {size} B is not a multiple of {row} B ({len(names)} float32 per point: "
                         f"{','.join(names)}); another --columns?")
    return np.frombuffer(path.read_bytes(), "<f4").reshape(-1, len(names)).astype(np.float32)


def read_pcd(path: Path) -> np.ndarray:
    """(N, 7) nuScenes columns of one radar sweep, filtered as the nuScenes reader filters."""
    if path.stat().st_size > MAX_FILE_BYTES:
        raise fail(path, f"{path.stat().st_size} B; a radar sweep file is at most {MAX_FILE_BYTES} B")
    try:
        return radar_features(filter_radar_points(read_radar_pcd(path)))
    except ValueError as err:  # the reader's message names the file
        raise InputFileError(str(err)) from None


def read_frame(path: Path, cfg, columns: str | None = None) -> Frame:
    """One file as a Frame in the model's columns, id = the path; InputFileError naming the file."""
    if path.suffix.lower() == ".pcd":
        names, points = NUSCENES_FEATURES, read_pcd(path)
    else:
        names = bin_columns(columns, cfg, path)
        points = read_bin(path, names)
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        raise fail(path, f"{int(bad.sum())} of {len(points)} points hold NaN or infinity (first: row "
                         f"{int(np.flatnonzero(bad)[0])}); another --columns?")
    frame = Frame(points, names, Boxes.empty(), frame_id=str(path), source=SOURCE)
    try:
        frame = MAPPERS[zoo.family_of(cfg).points.input_columns](frame)
        select_columns(frame, tuple(cfg.point_features))  # what the predictor will ask for
    except KeyError as err:
        raise fail(path, f"its columns {names} do not give {cfg.name}'s {tuple(cfg.point_features)} "
                         f"({err.args[0]}); pass --columns") from None
    return frame


def entry(frame: Frame, found) -> dict:
    """A frame's detections: centre and size in metres (sensor frame, x forward, y left, size
    w, l, h), yaw in radians about +z from +x."""
    boxes = found.boxes
    return {"points": len(frame.points),
            "detections": [{"class": str(n), "score": round(float(s), 5),
                            "center_m": [round(float(v), 3) for v in c], "size_m": [round(float(v), 3) for v in z],
                            "yaw_rad": round(float(y), 4)}
                           for n, s, c, z, y in zip(boxes.names, found.scores, boxes.center, boxes.size, boxes.yaw)]}


READER = FileReader(suffixes=(".pcd", ".bin"), read=read_frame, entry=entry, ident=lambda frame: frame.frame_id,
                    kinds="radar point clouds: nuScenes .pcd sweeps, VoD / TJ4DRadSet .bin scans")
