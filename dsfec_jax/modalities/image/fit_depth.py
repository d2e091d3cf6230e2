"""Self-supervised training of the monodepth network on the street benchmark's stereo pairs.

    variables, info = fit_depth("runs/depth/monodepth_street", MonodepthConfig(), frames=2000,
                                steps=800, batch_size=8, seed=0)

Data: the first `frames` independent frames of the street benchmark's train split (data seed
`data_seed`, StreetConfig(render_right=True) unless given), rendered once, area-resized to the
network's input and kept in memory as uint8 pairs (left, right). Rendering is deterministic in
(config, split, index, seed), so a resumed run rebuilds the same pairs.

Batches (DepthBatchStream): batch s is a pure function of (seed, s): the frame order is a
permutation per epoch drawn from (seed, epoch), the augmentation of each sample from
(seed, s, sample). Augmentation as monodepth_dataloader.py: with probability 0.5 the pair is
mirrored and swapped (left' = mirror(right), right' = mirror(left): still a rectified pair with
the right camera on the right); with probability 0.5 one gamma U(0.8, 1.2), brightness U(0.5, 2)
and per-channel colour U(0.8, 1.2)^3 shift applied to both images, then clipped to [0, 1].

Optimisation as monodepth_main.py: Adam (b1 0.9, b2 0.999, eps 1e-8), learning rate 1e-4 halved
at 3/5 and again at 4/5 of the steps, no weight decay, no clipping; the loss is models/depth/loss.py.

The loop is the project's (train/loop.py): RUN_DIR/run.json, metrics.jsonl (loss, its parts,
grad_norm, frames/s every `log_every` steps), checkpoints/last/step_* (whole train state, last
3), resumable at the last checkpoint with identical batches. At the end the weights go to
RUN_DIR/monodepth.msgpack in the zoo's layout, run.json as the manifest's training record
(depth.load_depth_predictor reads it; `dsfec depth ship` adds the measured figures).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import time
from pathlib import Path
from typing import Sequence

import jax
import numpy as np
import optax
from tqdm import tqdm

from ...data.camera.street import StreetConfig, StreetDataset
from ...metrics.depth.dense import MAX_DEPTH, MIN_DEPTH, depth_errors, mean_errors
from ...models.depth import MonodepthConfig, MonodepthNet, init_variables
from ...core import checkpoint
from ...core.run_checkpoints import read_extra, resolve
from .depth import WEIGHTS_NAME, MonodepthPredictor, load_depth_variables, resize_image, save_depth_weights
from ...models.depth.loss import MonodepthLoss, monodepth_loss
from ...train.loop import RunSpec, run_record, train
from ...train.parallel import is_writer
from ...train.schedules import Schedule

DECAY_AT = (3 / 5, 4 / 5)   # monodepth_main.py: lr, lr / 2, lr / 4
DECAY_FACTOR = 0.5
AUGMENT_TAG = 1             # keeps the augmentation stream apart from the epoch permutations


@dataclasses.dataclass(frozen=True)
class DepthAugment:
    """monodepth_dataloader.py's augmentation (module docstring)."""
    flip_prob: float = 0.5
    augment_prob: float = 0.5
    gamma: tuple[float, float] = (0.8, 1.2)
    brightness: tuple[float, float] = (0.5, 2.0)
    colour: tuple[float, float] = (0.8, 1.2)


def augment_pair(left: np.ndarray, right: np.ndarray, rng: np.random.Generator, cfg: DepthAugment):
    """One (H, W, 3) float32 [0, 1] pair, flipped-and-swapped and/or photometrically shifted."""
    if rng.uniform() < cfg.flip_prob:
        left, right = right[:, ::-1], left[:, ::-1]
    if rng.uniform() < cfg.augment_prob:
        gamma, brightness = rng.uniform(*cfg.gamma), rng.uniform(*cfg.brightness)
        colour = rng.uniform(*cfg.colour, size=3).astype(np.float32)
        shift = lambda im: np.clip(im ** np.float32(gamma) * np.float32(brightness) * colour, 0.0, 1.0)
        left, right = shift(left), shift(right)
    return np.ascontiguousarray(left), np.ascontiguousarray(right)


class DepthBatchStream:
    """Batch s of uint8 pairs (N, h, w, 3): {'inputs': {'left', 'right'} float32 [0, 1], 'targets': {},
    'window': 0} (train/loop.py's batch layout; the stereo loss needs no targets)."""

    def __init__(self, left: np.ndarray, right: np.ndarray, batch_size: int, seed: int,
                 augment: DepthAugment | None = DepthAugment()):
        if left.shape != right.shape or left.ndim != 4 or left.dtype != np.uint8:
            raise ValueError(f"stereo pairs: expected two equal (N, H, W, 3) uint8 arrays, got {left.shape} "
                             f"{left.dtype} and {right.shape} {right.dtype}")
        if len(left) < batch_size or batch_size < 1:
            raise ValueError(f"{len(left)} training pairs cannot fill a batch of {batch_size}")
        self.left, self.right, self.batch_size, self.seed, self.augment = left, right, batch_size, seed, augment
        self.per_epoch = len(left) // batch_size

    def indices(self, step: int) -> np.ndarray:
        epoch, k = divmod(step, self.per_epoch)
        order = np.random.default_rng((self.seed, epoch)).permutation(len(self.left))
        return order[k * self.batch_size:(k + 1) * self.batch_size]

    def batch(self, step: int, rows: slice = slice(None)) -> dict:
        """`rows`: only those rows of the batch (each pair draws its own augmentation)."""
        lefts, rights = [], []
        for i, index in list(enumerate(self.indices(step)))[rows]:
            left = self.left[index].astype(np.float32) / 255.0
            right = self.right[index].astype(np.float32) / 255.0
            if self.augment is not None:
                rng = np.random.default_rng((self.seed, AUGMENT_TAG, step, i))
                left, right = augment_pair(left, right, rng, self.augment)
            lefts.append(left)
            rights.append(right)
        return {"inputs": {"left": np.stack(lefts), "right": np.stack(rights)}, "targets": {}, "window": 0}


@functools.lru_cache(maxsize=16)
def monodepth_adam(learning_rate: float, decay_at: tuple[float, ...], decay_factor: float, b1: float,
                   total_steps: int) -> optax.GradientTransformation:
    """Adam with monodepth's piecewise-constant learning rate. Cached, so that runs of one setup
    in a process share one optimizer object, and with it one compiled step (_jitted_step)."""
    boundaries = {max(int(f * total_steps), 1): decay_factor for f in decay_at}
    return optax.adam(optax.piecewise_constant_schedule(learning_rate, boundaries), b1=b1)


class MonodepthTrainer:
    """What train/loop.py needs of a model: name, config, init, its own optimizer and step."""

    def __init__(self, config: MonodepthConfig, loss: MonodepthLoss = MonodepthLoss()):
        self.config, self.loss, self.name = config, loss, config.name

    def init(self, rng: jax.Array) -> dict:
        return init_variables(self.config, rng)

    def optimizer(self, schedule: Schedule, total_steps: int) -> optax.GradientTransformation:
        return monodepth_adam(schedule.learning_rate, tuple(schedule.decay_at), schedule.decay_factor, schedule.b1,
                              total_steps)

    def make_train_step(self, tx: optax.GradientTransformation):
        """The jitted step (state, batch) -> (state, metrics), state donated."""
        return _jitted_step(self.config, self.loss, tx)


def train_step_fn(config: MonodepthConfig, loss: MonodepthLoss, tx: optax.GradientTransformation):
    """The un-jitted step (state, batch) -> (new state, {'loss', 'grad_norm', loss parts})."""
    net = MonodepthNet(config)

    def loss_fn(params, inputs):
        disps = net.apply({"params": params}, inputs["left"])
        return monodepth_loss(disps, inputs["left"], inputs["right"], loss)

    def step(state, batch):
        (total, parts), grads = jax.value_and_grad(loss_fn, has_aux=True)(state["params"], batch["inputs"])
        updates, opt_state = tx.update(grads, state["opt_state"], state["params"])
        new_state = {**state, "params": optax.apply_updates(state["params"], updates), "opt_state": opt_state,
                     "step": state["step"] + 1}
        return new_state, {"loss": total, "grad_norm": optax.tree.norm(grads), **parts}

    return step


@functools.lru_cache(maxsize=16)
def _jitted_step(config: MonodepthConfig, loss: MonodepthLoss, tx: optax.GradientTransformation):
    """One jitted step per (config, loss, optimizer): a resumed or repeated run in the same process
    reuses its compilation (seconds even for the tiny test network; docs/edge-and-map-service.md)."""
    return jax.jit(train_step_fn(config, loss, tx), donate_argnums=0)


def render_pairs(street_config: StreetConfig, frames: int, config: MonodepthConfig, seed: int = 0,
                 split: str = "train", progress: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The first `frames` frames of `split` as uint8 (frames, h, w, 3) left and right images at the
    network's input size."""
    if not street_config.render_right:
        raise ValueError("StreetConfig.render_right is False: self-supervised depth needs the right image")
    data = StreetDataset(street_config, split, seed, frames)
    left = np.empty((frames, config.height, config.width, 3), np.uint8)
    right = np.empty_like(left)
    for i in tqdm(range(frames), disable=not progress, desc="stereo pairs"):
        frame = data[i]
        left[i] = resize_image(frame.image, config.height, config.width)
        right[i] = resize_image(frame.right, config.height, config.width)
    return left, right


def monodepth_schedule(batch_size: int, steps: int, learning_rate: float = 1e-4) -> Schedule:
    """The run.json record of the optimisation (Adam; weight_decay and clipping unused: 0 / none)."""
    return Schedule("monodepth", learning_rate, 0, batch_size, steps=steps, decay_at=DECAY_AT,
                    decay_factor=DECAY_FACTOR, weight_decay=0.0, clip_norm=0.0)


def read_losses(run_dir: str | Path) -> list[dict]:
    """metrics.jsonl's training rows (step, loss, parts)."""
    path = Path(run_dir) / "metrics.jsonl"
    rows = [json.loads(l) for l in path.read_text().splitlines() if l.strip()] if path.exists() else []
    return [r for r in rows if "loss" in r]


def fit_depth(run_dir: str | Path, config: MonodepthConfig, frames: int, steps: int, batch_size: int, seed: int,
              street_config: StreetConfig | None = None, progress: bool = True, *, learning_rate: float = 1e-4,
              loss: MonodepthLoss = MonodepthLoss(), augment: DepthAugment | None = DepthAugment(),
              data_seed: int = 0, stop_at: int | None = None, log_every: int = 10,
              ckpt_every: int = 100, init: str | Path | None = None,
              command: str | None = None) -> tuple[dict, dict]:
    """Train (or resume) in run_dir -> ({'params'}, info). info: run_dir, step (reached), steps,
    weights (the final weights file, None before the end: `stop_at`), train_frames, render_s,
    train_s, losses (metrics.jsonl rows). `init`: monodepth weights or a checkpoint of the same
    config to start from (a longer run continued, or the shipped weights fine-tuned on other pairs);
    its sha256 goes into run.json, so a resume with other init weights is refused. `command`: the
command line, for run.json (and the shipped weights' manifest: `dsfec depth ship`)."""
    run_dir = Path(run_dir)
    street_config = street_config or StreetConfig(render_right=True)
    init_variables, init_record = _init_weights(init, config)
    t0 = time.perf_counter()
    left, right = render_pairs(street_config, frames, config, data_seed, progress=progress)
    render_s = time.perf_counter() - t0
    trainer = MonodepthTrainer(config, loss)
    schedule = monodepth_schedule(batch_size, steps, learning_rate)
    stream = DepthBatchStream(left, right, batch_size, seed, augment)
    spec = RunSpec(run_dir, schedule, seed, total_steps=steps, stop_at=stop_at, log_every=log_every,
                   ckpt_every=ckpt_every, progress=progress)
    info = run_record({**({"command": command} if command else {}), "data": {"source": "street", "split": "train", "seed": data_seed, "frames": frames,
                                "street_config": street_config.to_dict()}},
                      config.name, {}, config, schedule, seed, steps, augment, loss=dataclasses.asdict(loss),
                      optimizer="adam (monodepth: b2 0.999, eps 1e-8, no weight decay, no clipping)",
                      **({"init": init_record} if init_record else {}))
    t1 = time.perf_counter()
    state, _ = train(trainer, stream, spec, info, init_variables=init_variables)
    variables = {"params": jax.device_get(state["params"])}
    reached = int(state["step"])
    weights = None
    if reached >= steps and is_writer():  # process 0 of a run on several hosts (train/parallel.py)
        weights = run_dir / WEIGHTS_NAME
        run = json.loads((run_dir / "run.json").read_text())  # as stored when the run started
        save_depth_weights(weights, config, variables, {**run, "train_frames": frames}, step=reached)
    return variables, {"run_dir": str(run_dir), "step": reached, "steps": steps,
                       "weights": str(weights) if weights else None, "train_frames": frames,
                       "render_s": round(render_s, 1), "train_s": round(time.perf_counter() - t1, 1),
                       "losses": read_losses(run_dir)}


def _init_weights(init: str | Path | None, config: MonodepthConfig) -> tuple[dict | None, dict | None]:
    """(variables, run.json record: path, sha256, step) of the weights a run starts from."""
    if init is None:
        return None, None
    init_config, variables = load_depth_variables(init)
    if init_config != config:
        raise ValueError(f"{init}: weights of {init_config}; this run trains {config} (same --input expected)")
    if Path(init).is_file():
        manifest = checkpoint.read_manifest(Path(init))
        return variables, {"path": str(init), "sha256": manifest.get("sha256"), "step": manifest.get("step")}
    # a training checkpoint (an Orbax step directory): no single file to hash; its step names it
    return variables, {"path": str(resolve(init)), "sha256": None, "step": read_extra(init).get("step")}


def evaluate_dense(predictor: MonodepthPredictor, frames: Sequence, min_depth: float = MIN_DEPTH,
                   max_depth: float = MAX_DEPTH) -> dict:
    """Mean per-image dense metrics (metrics/depth/dense.py) of street frames: predicted depth =
    baseline * fx / (W * disparity), W the frame's width, against frame.depth."""
    rows = []
    for frame in frames:
        disp = predictor(frame.image)
        with np.errstate(divide="ignore"):
            depth = frame.baseline_m * frame.camera.fx / (frame.camera.width * disp)
        rows.append(depth_errors(frame.depth, depth, min_depth, max_depth))
    return mean_errors(rows)
