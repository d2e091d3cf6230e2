"""The embedded camera benchmark: procedural street scenes from a pinhole camera behind the
windscreen of an ego car on a GPS track (images, 2D boxes, per-pixel depth, a right stereo image).

    from dsfec_jax.data.camera.street import StreetConfig, generate_frame, generate_drive
    frame = generate_frame(StreetConfig(), "train", index=0, seed=0)      # a StreetFrame
    drive = generate_drive(StreetConfig(), "val", index=0, num_frames=50)  # frames of one world

Modules: camera (pinhole presets, mount), road (centre line, cross-section, road coordinates),
world (road users, clutter, light; sampling), bodies (objects as a few boxes, palettes), render
(exact ray casting with a depth buffer), shade (textures and light), labels (visible boxes and the
occlusion rules), geo (ENU <-> WGS84 with pymap3d, GPS fixes), generate (frames, drives, splits),
cache (PNG + NPZ + manifest), stats / preview / inspect (what `python -m dsfec_jax.data inspect
--source street` prints and draws). The benchmark is synthetic: see config.py for every assumption.
"""

from .camera import CAMERAS, PinholeCamera
from .config import CLASSES, FORMAT_VERSION, StreetConfig
from .frame import StreetFrame, StreetObjects
from .generate import StreetDataset, StreetDrive, generate_drive, generate_frame, render_frame
from .geo import EgoPose, GpsTrack

__all__ = ["CAMERAS", "CLASSES", "FORMAT_VERSION", "EgoPose", "GpsTrack", "PinholeCamera", "StreetConfig",
           "StreetDataset", "StreetDrive", "StreetFrame", "StreetObjects", "generate_drive", "generate_frame",
           "render_frame"]
