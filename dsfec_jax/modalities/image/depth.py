"""From a camera image to a dense disparity map with the monodepth network (models/depth).

    predictor = load_depth_predictor("runs/depth/monodepth_street/monodepth.msgpack")
    disp = predictor(image)   # (H, W) float32, a fraction of the image width

The image (H, W, 3) uint8 RGB is area-resized (Pillow's BOX filter, monodepth's resize_area) to
the network's input, scaled to [0, 1], and run by one jitted function together with its mirror
(one batch of 2; `post_process=False`: the image alone); the left-view disparities of the two are
blended by monodepth's post-processing (models/depth/postprocess.py); the map is resized back to
(H, W) bilinearly (monodepth's evaluation resizes with cv2.INTER_LINEAR).
A fraction of the width survives the resizes unchanged, so disparity in pixels of the original
image is disp * W, and depth = baseline * fx / (W * disp) for a camera of focal length fx pixels
at width W. That conversion, and its calibration, is the caller's.

Weights files: `save_depth_weights` writes {'params'} with core/checkpoint.save and the config in
the manifest ('config', 'format'). `load_depth_predictor` reads those and, for a training
checkpoint (checkpoints/step_*.msgpack: the whole train state, no config in its manifest), takes
the params from the state and the config from the run directory's run.json.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import flax.serialization
import jax
import jax.numpy as jnp
import numpy as np
from PIL import Image

from ...core import checkpoint
from ...models.depth import MonodepthConfig, MonodepthNet, init_variables, post_process_disparity

WEIGHTS_FORMAT = "dsfec_jax.monodepth"
WEIGHTS_NAME = "monodepth.msgpack"  # a finished run's weights: RUN_DIR/monodepth.msgpack


def resize_image(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """(H, W, 3) uint8 -> (height, width, 3) uint8 by area averaging (Pillow BOX)."""
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise ValueError(f"image: expected (H, W, 3) uint8 RGB, got {image.shape} {image.dtype}")
    if image.shape[:2] == (height, width):
        return image
    return np.asarray(Image.fromarray(image).resize((width, height), Image.Resampling.BOX))


def resize_map(values: np.ndarray, height: int, width: int) -> np.ndarray:
    """(h, w) float -> (height, width) float32, bilinear (half-pixel centres, as cv2.INTER_LINEAR)."""
    values = np.asarray(values, np.float32)
    if values.shape == (height, width):
        return values
    return np.asarray(Image.fromarray(values, mode="F").resize((width, height), Image.Resampling.BILINEAR))


def disparity_function(cfg: MonodepthConfig, post_process: bool = True):
    """fn(variables, image (1, h, w, 3) float32 in [0, 1]) -> (h, w) left-view disparity: the image
    and its mirror in one batch, blended by monodepth's post-processing (or the image alone)."""
    net = MonodepthNet(cfg)

    def disparity(variables, image):
        batch = jnp.concatenate([image, image[:, :, ::-1]], axis=0) if post_process else image
        left = net.apply(variables, batch)[0][..., 0]  # full scale, left view: (2 or 1, h, w)
        return post_process_disparity(left[0], left[1]) if post_process else left[0]

    return disparity


class MonodepthPredictor:
    """image (H, W, 3) uint8 -> disparity (H, W) float32 as a fraction of the width (module docstring)."""

    def __init__(self, config: MonodepthConfig, variables: dict, post_process: bool = True):
        self.config, self.post_process = config, post_process
        self.variables = {"params": variables["params"]}
        self._disparity = jax.jit(disparity_function(config, post_process))

    def network_input(self, image: np.ndarray) -> np.ndarray:
        """(1, h, w, 3) float32 in [0, 1] at the network's input size."""
        small = resize_image(image, self.config.height, self.config.width)
        return (small.astype(np.float32) / 255.0)[None]

    def network_disparity(self, image: np.ndarray) -> np.ndarray:
        """The (h, w) map at the network's resolution, before the resize back."""
        return np.asarray(self._disparity(self.variables, self.network_input(image)))

    def __call__(self, image: np.ndarray) -> np.ndarray:
        h, w = np.shape(image)[:2]
        return resize_map(self.network_disparity(image), h, w)


def save_depth_weights(path: str | os.PathLike, config: MonodepthConfig, variables: dict, extra: dict | None = None) -> None:
    """{'params'} to PATH with the config (and `extra`, e.g. the training step) in its manifest."""
    checkpoint.save(path, {"params": jax.device_get(variables["params"])},
                    {"format": WEIGHTS_FORMAT, "config": config.to_dict(), **(extra or {})})


def ship_depth_weights(run_dir: str | os.PathLike, out: str | os.PathLike, ship_command: str) -> dict:
    """A finished run's weights to OUT with their provenance -> OUT's manifest: step, seed,
    train_frames, train_command, the runs it continued ('init_chain': each start's weights, step,
    sha256 and command, read from the run directory that made them) and the versions."""
    run_dir = Path(run_dir)
    weights = run_dir / WEIGHTS_NAME
    if not weights.is_file():
        raise ValueError(f"{weights}: not found; expected the weights of a finished `dsfec depth train` run")
    config, variables = load_depth_variables(weights)
    run = _run_json(run_dir)
    manifest = checkpoint.read_manifest(weights)
    extra = {"step": manifest.get("step"), "seed": run.get("seed"), "train_frames": manifest.get("train_frames"),
             "train_command": run.get("command"), "init_chain": _init_chain(run), "ship_command": ship_command,
             "source": str(weights), "versions": run.get("versions")}
    save_depth_weights(out, config, variables, extra)
    return checkpoint.read_manifest(Path(out))


def _run_json(run_dir: Path) -> dict:
    path = run_dir / "run.json"
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f"{path}: not readable ({err}); expected the run.json of a depth training run") from err


def _init_chain(run: dict) -> list[dict]:
    """The weights a run started from, and theirs, back to a run from scratch. Where the start
    was a shipped file rather than a run directory, its own manifest says how it was trained."""
    chain = []
    while run.get("init") and len(chain) < 16:
        init = dict(run["init"])
        parent = Path(init["path"]).parent
        parent = parent.parent if parent.name == "checkpoints" else parent
        if (parent / "run.json").is_file():
            run = _run_json(parent)
            chain.append({**init, "command": run.get("command"), "seed": run.get("seed")})
            continue
        start = Path(init["path"])
        shipped = checkpoint.read_manifest(start) if checkpoint.manifest_path(start).is_file() else {}
        chain.append({**init, "command": shipped.get("train_command"), "seed": shipped.get("seed"),
                      **({"init_chain": shipped["init_chain"]} if shipped.get("init_chain") else {})})
        break
    return chain


def _config_for(path: Path, manifest: dict) -> MonodepthConfig:
    if "config" in manifest:
        return MonodepthConfig.from_dict(manifest["config"])
    run_json = path.parent.parent / "run.json"  # RUN_DIR/checkpoints/step_*.msgpack
    if not run_json.is_file():
        raise ValueError(f"{checkpoint.manifest_path(path)}: no 'config' in the manifest, and no {run_json} to "
                         "read it from; expected a file written by save_depth_weights or a training checkpoint")
    return MonodepthConfig.from_dict(json.loads(run_json.read_text())["config"])


def load_depth_variables(path: str | os.PathLike) -> tuple[MonodepthConfig, dict]:
    """(config, {'params'}) of a weights file or a training checkpoint (module docstring)."""
    path = Path(path)
    config = _config_for(path, checkpoint.read_manifest(path))
    raw = checkpoint.load(path)  # checks the bytes against the manifest
    if "params" not in raw:
        raise ValueError(f"{path}: expected a tree with 'params', found keys {sorted(raw)}")
    target = {"params": init_variables(config, jax.random.key(0))["params"]}
    return config, _restore(path, raw, target)


def _restore(path: Path, raw: dict, target: dict) -> dict:
    """raw['params'] into the structure of target (shapes checked, naming the first mismatch)."""
    restored = flax.serialization.from_state_dict(target, {"params": raw["params"]})
    for (kp, a), b in zip(jax.tree_util.tree_flatten_with_path(target)[0], jax.tree.leaves(restored)):
        if np.shape(a) != np.shape(b):
            raise ValueError(f"{path}: {jax.tree_util.keystr(kp)} has shape {np.shape(b)}, the config expects {np.shape(a)}")
    return restored


def load_depth_predictor(path: str | os.PathLike, post_process: bool = True) -> MonodepthPredictor:
    config, variables = load_depth_variables(path)
    return MonodepthPredictor(config, variables, post_process)
