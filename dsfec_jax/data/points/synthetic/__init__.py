"""Embedded synthetic radar benchmark: road scenes, radar returns, clutter, sweeps.

    from dsfec_jax.data.points.synthetic import SyntheticConfig, SyntheticDataset, generate_frame, radar4d_config
    frame = generate_frame(SyntheticConfig(difficulty="normal"), "train", index=0, seed=0)  # nuScenes-like
    frame4d = generate_frame(radar4d_config("normal"), "train", index=0, seed=0)  # VoD-like 4D radar

Modules: config (classes, physics constants, difficulty, SyntheticConfig), layout (road lines),
scene (actors, ego motion), sensor (sweeps, measurement), returns (object detections),
occlusion, clutter (structures, false alarms, ghosts), simulate (one frame), dataset (splits,
determinism, cache), stats (dataset statistics, throughput), bev_png (BEV picture as PNG).
"""

from .bev_png import render_bev, save_bev_png
from .config import CLASSES, DIFFICULTIES, POINT_FORMATS, RADAR4D_CONFIG, RADAR_FEATURES, SOURCES, SyntheticConfig, radar4d_config
from .dataset import SPLITS, CachedDataset, SyntheticDataset, frame_rng, generate_frame, open_cache, read_manifest, write_cache
from .stats import dataset_stats, format_stats, throughput

__all__ = ["CLASSES", "DIFFICULTIES", "POINT_FORMATS", "RADAR4D_CONFIG", "RADAR_FEATURES", "SOURCES", "SPLITS",
           "CachedDataset", "SyntheticConfig", "SyntheticDataset", "dataset_stats", "format_stats", "frame_rng",
           "generate_frame", "open_cache", "radar4d_config", "read_manifest", "render_bev", "save_bev_png",
           "throughput", "write_cache"]
