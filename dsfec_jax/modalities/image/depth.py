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

Weights files are the zoo's (the network is its auxiliary model 'depth', models/depth/auxiliary.py):
{'params'} written by core/checkpoint.save, the manifest naming the model and holding its training
record with the whole config. `load_depth_predictor` reads them through zoo.auxiliary_config and
zoo.model_variables: a finished run's or shipped weights, a training checkpoint (checkpoints/
last/step_N or checkpoints/best: the whole train state; the config from the run directory's run.json), or a file in
the network's first format (before it joined the zoo), which its record reads.
"""

from __future__ import annotations

import functools
import os

import jax
import jax.numpy as jnp
import numpy as np
from PIL import Image

from ... import zoo
from ...core import checkpoint
from ...models.depth import MonodepthConfig, MonodepthNet, post_process_disparity

DEPTH = "depth"  # the network's record in zoo.AUXILIARIES
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


@functools.lru_cache(maxsize=8)
def jitted_disparity(cfg: MonodepthConfig, post_process: bool = True):
    """disparity_function, jitted once per (config, post_process): the predictors of one process
    (a run's weights, then the shipped file measured) share its compilation."""
    return jax.jit(disparity_function(cfg, post_process))


class MonodepthPredictor:
    """image (H, W, 3) uint8 -> disparity (H, W) float32 as a fraction of the width (module docstring)."""

    def __init__(self, config: MonodepthConfig, variables: dict, post_process: bool = True):
        self.config, self.post_process = config, post_process
        # on the device once (numpy weights are converted again on every jitted call)
        self.variables = jax.device_put({"params": variables["params"]})
        self._disparity = jitted_disparity(config, post_process)

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


def save_depth_weights(path: str | os.PathLike, config: MonodepthConfig, variables: dict, training: dict | None = None,
                       **fields) -> None:
    """{'params'} to PATH in the zoo's layout: the manifest names the model, holds `fields` (the
    step; a shipped file's measured figures, ship command and versions) and the `training` record
    with the whole config (zoo.auxiliary_config reads it back)."""
    checkpoint.save(path, {"params": jax.device_get(variables["params"])},
                    {"model": config.name, **fields, "training": {**(training or {}), "config": config.to_dict()}})


def load_depth_variables(path: str | os.PathLike) -> tuple[MonodepthConfig, dict]:
    """(config, {'params'}) of a weights file or a training checkpoint, through the zoo's loader
    (module docstring)."""
    config = zoo.auxiliary_config(path, DEPTH)
    return config, zoo.model_variables(zoo.AuxiliaryNet(config), path)


def load_depth_predictor(path: str | os.PathLike, post_process: bool = True) -> MonodepthPredictor:
    config, variables = load_depth_variables(path)
    return MonodepthPredictor(config, variables, post_process)
