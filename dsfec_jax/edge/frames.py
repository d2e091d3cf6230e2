"""What an edge device sees: camera frames with timestamps on the GPS clock, and its camera.

Two sources give the same `EdgeFrame`s:
- a folder of frames (`folder_frames`): the images (PNG or JPEG, in file-name order), a
  `times.csv` with columns `frame,time_s` (frame = the image's file name; time on the GPS file's
  clock), and a `camera.json` with the intrinsics `{"fx", "cx", "width", "height"}` (optionally fy,
  cy, baseline_m). A folder without times.csv needs `fps` and `start_s`: frame k is at
  start_s + k / fps.
- the street benchmark's synthetic drive (`drive_frames`), whose frames carry the right image
  and the ground truth that the error tables are scored with.

Times are seconds on one clock shared with the GPS fixes. For the synthetic drive that clock starts
at 0 at the drive's first frame; `drive_epoch_s` maps it to UNIX time for the outputs (a fixed,
recorded instant, so outputs are reproducible).
"""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path
from typing import Iterator

import numpy as np

from ..data.camera.voc import load_image
from ..data.camera.street.camera import PinholeCamera

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
DRIVE_EPOCH_S = 1_767_225_600.0  # 2026-01-01T00:00:00Z: UNIX time of a synthetic drive's t = 0


@dataclasses.dataclass(frozen=True)
class EdgeFrame:
    frame_id: str
    time_s: float                 # on the GPS fixes' clock
    image: np.ndarray             # (H, W, 3) uint8 RGB, the left camera
    right: np.ndarray | None = None
    truth: object | None = None   # the synthetic StreetFrame (ground truth), None for real frames


def _read_camera(path: Path) -> tuple[PinholeCamera, float | None]:
    try:
        d = json.loads(path.read_text())
        cam = PinholeCamera(int(d["width"]), int(d["height"]), float(d["fx"]), float(d.get("fy", d["fx"])),
                            float(d["cx"]), float(d.get("cy", d["height"] / 2)))
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: missing; expected the camera intrinsics "
                                f'{{"fx", "cx", "width", "height"}} (pixels) beside the frames') from None
    except (KeyError, TypeError, ValueError, json.JSONDecodeError) as err:
        raise ValueError(f"{path}: {err!r}; expected a JSON object with numbers fx, cx, width, height "
                         f"(optional fy, cy, baseline_m)") from None
    baseline = d.get("baseline_m")
    return cam, None if baseline is None else float(baseline)


def _read_times(path: Path, names: list[str]) -> dict[str, float]:
    times = {}
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        if not reader.fieldnames or not {"frame", "time_s"} <= set(reader.fieldnames):
            raise ValueError(f"{path}: header {reader.fieldnames}; expected columns frame,time_s")
        for row_number, row in enumerate(reader, start=2):
            try:
                t = float(row["time_s"])
            except (TypeError, ValueError):
                raise ValueError(f"{path} row {row_number}: time_s={row['time_s']!r} is not a number") from None
            if not np.isfinite(t):
                raise ValueError(f"{path} row {row_number}: time_s={t} must be finite")
            times[row["frame"]] = t
    missing = [n for n in names if n not in times]
    if missing:
        raise ValueError(f"{path}: no time for {len(missing)} frame(s), e.g. {missing[:3]}")
    return times


@dataclasses.dataclass(frozen=True)
class FrameFolder:
    directory: Path
    names: tuple[str, ...]
    times: tuple[float, ...]
    camera: PinholeCamera
    baseline_m: float | None

    def __len__(self) -> int:
        return len(self.names)

    def __iter__(self) -> Iterator[EdgeFrame]:
        return self.frames()

    def frames(self, skip=frozenset()) -> Iterator[EdgeFrame]:
        """The frames in time order, without reading those whose id is in `skip` (a resumed run)."""
        for name, t in zip(self.names, self.times):
            if Path(name).stem in skip:
                continue
            image = load_image(self.directory / name)
            if image.shape[:2] != (self.camera.height, self.camera.width):
                raise ValueError(f"{self.directory / name}: {image.shape[1]} x {image.shape[0]} px; camera.json "
                                 f"says {self.camera.width} x {self.camera.height}")
            yield EdgeFrame(Path(name).stem, t, image)


def folder_frames(directory: str | Path, fps: float | None = None, start_s: float = 0.0) -> FrameFolder:
    directory = Path(directory)
    if not directory.is_dir():
        raise FileNotFoundError(f"{directory}: not a directory of frames")
    names = sorted(p.name for p in directory.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not names:
        raise ValueError(f"{directory}: no {'/'.join(IMAGE_SUFFIXES)} frames")
    camera, baseline = _read_camera(directory / "camera.json")
    if (directory / "times.csv").exists():
        by_name = _read_times(directory / "times.csv", names)
        times = [by_name[n] for n in names]
    elif fps:
        times = [start_s + k / fps for k in range(len(names))]
    else:
        raise ValueError(f"{directory}: no times.csv (columns frame,time_s); give the frame rate instead (--fps)")
    if np.any(np.diff(times) <= 0):
        raise ValueError(f"{directory}: frame times must increase in file-name order")
    return FrameFolder(directory, tuple(names), tuple(float(t) for t in times), camera, baseline)


def drive_frames(drive, skip=frozenset()) -> Iterator[EdgeFrame]:
    """The street benchmark's StreetDrive as EdgeFrames (rendered one at a time; ids in `skip` not)."""
    for j in range(len(drive)):
        if f"{j:06d}" in skip:
            continue
        f = drive.frame(j)
        yield EdgeFrame(f"{j:06d}", float(drive.times[j]), f.image, f.right, f)
