"""SPOS for point-cloud families (DSFEC): a width x depth x stem supernet, trained by uniform
single-path sampling and scored with the weights each subnet inherits.

- The supernet is the space's largest subnet (every stage at 3 blocks and full width, the widest
  stem) at the search recipe's grid. Widths are leading-slice masks (search/nas/slices.py), depth
  the family's traced `depth` input (search.oneshot's: block b of stage s runs when b < depth[s]),
  so one compiled step trains every subnet. Its step puts the idle blocks' weights and statistics
  back, as search.oneshot's does (their gradients are 0, but momentum and weight decay must not
  move them: PyTorch SPOS leaves a module without a gradient alone).
- It starts from the base's shipped weights through their leading channels (train.warm_start's
  LeadingSlices): the base (DSFEC-M) is one of the subnets and starts as the trained network, the
  rest start from its slices. From scratch, a CPU budget of a few hundred steps leaves DSFEC at
  noise-level mAP (search.inherit); the price is a bias toward the base, named in every report.
- Batch s trains the subnet drawn from `default_rng([seed, SALT, s])` (spos.SPOSStream): a resumed
  supernet run (train.loop) trains what an uninterrupted one trains. `sampling="sandwich"`:
  the cycle largest, smallest, uniform, uniform, accumulated into one optimizer update
  (PointSupernet.optimizer, which train.loop uses); the accumulator is optimizer state, so a run
  killed mid-cycle resumes exactly.
- Scores: BN statistics recalibrated on fixed unaugmented training batches (spos.recalibrator),
  then the family's protocol (nuScenes Car mAP) on validation frames, all subnets through one
  compiled predictor.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax
import numpy as np

from dsfec_jax import zoo
from dsfec_jax.core import checkpoint
from dsfec_jax.core.provenance import jsonable, versions
from dsfec_jax.data.batches import BatchStream
from dsfec_jax.data.points.pillarize import PillarSpec, pillar_budget
from dsfec_jax.modalities.registry import protocol
from dsfec_jax.modalities.points.predict import Predictor
from dsfec_jax.train.loop import RunSpec, train
from dsfec_jax.train.schedules import optimizer
from dsfec_jax.train.step import train_step_fn
from dsfec_jax.train.warm_start import LeadingSlices

from ..oneshot import calibration_batches, keep_idle
from .slices import SliceMasks, masked_apply
from .space import Genes, SearchSpace
from .spos import (SANDWICH_CYCLE, SPOSStream, accumulating_optimizer, check_sampling, finished_supernet, recalibrator,
                   sampling_info, score_inherited)


class PointSupernet:
    """The supernet with the subnet as an input: `apply(variables, {pillars..., 'masks', 'depth'})`."""

    def __init__(self, supernet, sampling: str = "uniform"):
        self.supernet, self.config, self.module = supernet, supernet.config, supernet.module
        self.hooks = zoo.family_of(self.config).supernet
        self.blocks = self.hooks.blocks(self.config)
        self.sampling = check_sampling(sampling)

    def optimizer(self, schedule, total_steps: int):
        """train.loop's optimizer: the schedule's; sandwich: stepping once per cycle of 4 batches
        on their mean gradient (optax.MultiSteps), so one update sees max, min and 2 random subnets."""
        if self.sampling == "sandwich":
            return accumulating_optimizer(schedule, total_steps, SANDWICH_CYCLE)
        return optimizer(schedule, total_steps)

    @property
    def name(self) -> str:
        return f"{self.config.name}_supernet"

    def init(self, rng) -> dict:
        return self.supernet.init(rng)

    def apply(self, variables: dict, inputs: dict, train: bool = False):
        inputs = dict(inputs)
        masks = inputs.pop("masks")
        return masked_apply(self.supernet, variables, inputs, masks, train)

    def make_train_step(self, tx):
        """train.step's step, then the idle blocks put back (train.loop uses this one). Sandwich:
        the params are left to the accumulating optimizer (every cycle's largest subnet runs every
        block, so no block is idle over an update); the idle blocks' BN statistics are still put back."""
        inner = train_step_fn(self, tx)
        sandwich = self.sampling == "sandwich"

        def step(state, batch):
            new, metrics = inner(state, batch)
            depth = batch["inputs"][self.hooks.input]
            params = new["params"] if sandwich else keep_idle(new["params"], state["params"], depth, self.blocks)
            return {**new, "params": params,
                    "batch_stats": keep_idle(new["batch_stats"], state["batch_stats"], depth, self.blocks)}, metrics

        return jax.jit(step, donate_argnums=0)


class PointSubnetInputs:
    """genes -> the subnet's inputs {'masks', 'depth'}."""

    def __init__(self, space: SearchSpace):
        self.space, self.table = space, SliceMasks(space)
        self.hooks = zoo.family_of(space.base).supernet

    def __call__(self, genes: Genes) -> dict:
        depth = np.asarray(self.space.overrides(genes)[self.hooks.field], np.int32)
        return {"masks": self.table.masks(genes), self.hooks.input: depth}


def supernet_detectors(space: SearchSpace, recipe, frames, sampling: str = "uniform") -> tuple[PointSupernet, PointSupernet]:
    """(trainee, validator): the largest subnet at the recipe's grid, trained with pillar slots sized
    to the frames (data.points.pillarize.pillar_budget) and validated with the recipe's."""
    overrides = {**space.overrides(space.largest()), **recipe.model_overrides()}
    full = zoo.create(space.base, **overrides)
    trainee = zoo.create(space.base, **{**overrides, "max_pillars": pillar_budget(frames, full.config.max_pillars)})
    return PointSupernet(trainee, sampling), PointSupernet(full, sampling)


def base_init(base: str) -> LeadingSlices | None:
    path = zoo.shipped_weights(base)
    return LeadingSlices(checkpoint.load(path)) if path.is_file() else None


def train_point_supernet(space: SearchSpace, recipe, frames, run_dir: str | Path, steps: int, seed: int = 0,
                         progress: bool = True, stop_at: int | None = None, load_only: bool = False,
                         sampling: str = "uniform"):
    """Train (or resume) the space's supernet by SPOS in run_dir -> (trainee, validator, SubnetInputs, state, stream).
    `load_only`: nothing trains or writes; the state is the finished run's (spos.finished_supernet).
    `sampling`: "uniform" (one uniform subnet a batch) or "sandwich" (spos.SANDWICH, accumulated over
    its cycle); kept in run.json, and a directory trained with one rule refuses the other."""
    det, validator = supernet_detectors(space, recipe, frames, sampling)
    subnet_inputs = PointSubnetInputs(space)
    family, cfg = zoo.family_of(space.base), det.config
    stream = BatchStream(frames, PillarSpec.of(cfg), family.points.targets(cfg), recipe.schedule.batch_size, seed,
                         origin_input=family.points.origin_input)
    if load_only:
        return det, validator, subnet_inputs, finished_supernet(run_dir, steps), stream
    spec = RunSpec(Path(run_dir), recipe.schedule, seed, total_steps=steps, stop_at=stop_at, progress=progress)
    init = base_init(space.base)
    info = {"space": space.name, "base": space.base, "strategy": "spos", "config": jsonable(dataclasses.asdict(cfg)),
            "schedule": jsonable(dataclasses.asdict(recipe.schedule)), "seed": seed, "steps": steps,
            "train_frames": len(frames), "init": "leading slices of the shipped base" if init else "scratch",
            **sampling_info(run_dir, sampling), "versions": versions()}
    if sampling == "sandwich" and steps % SANDWICH_CYCLE:
        raise ValueError(f"sandwich sampling: {steps} steps is not a whole number of {SANDWICH_CYCLE}-batch cycles")
    state, _ = train(det, SPOSStream(stream, space, subnet_inputs, seed, sampling), spec, info, init_variables=init)
    return det, validator, subnet_inputs, state, stream


class SubnetPointPredictor(Predictor):
    """The point predictor over the supernet, run as the subnet in `.subnet` (set between subnets)."""

    subnet: dict = {}

    def run(self, batch: dict):
        return jax.device_get(self.network(self.variables, {**batch, **self.subnet}))


class PointSubnetScorer:
    """score(list of genes) -> [{headline and scalar protocol scores}] with inherited, recalibrated weights;
    `progress`: score_inherited's bar and compile line on stderr."""

    warm = False  # set once a subnet was scored: the compiled functions are cached

    def __init__(self, det: PointSupernet, validator: PointSupernet, subnet_inputs: PointSubnetInputs, state: dict,
                 stream: BatchStream, val_frames, calibration: int, progress: bool = False):
        self.progress = progress
        self.family = zoo.family_of(det.config)
        self.subnet_inputs, self.val, self.params = subnet_inputs, val_frames, state["params"]
        self.batches = [b["inputs"] for b in calibration_batches(stream, PillarSpec.of(det.config))[:calibration]]
        self.recalibrate = recalibrator(det, self.family.supernet.bn_momentum)
        self.start_stats = state["batch_stats"]
        self.predictor = SubnetPointPredictor(validator, {"params": self.params, "batch_stats": self.start_stats})

    def evaluate(self) -> dict:
        scores, _ = protocol(self.family.metric.name).validate(self.predictor, self.val)
        return {k: float(v) for k, v in scores.items() if k in self.family.metric.keep and np.isscalar(v)}

    __call__ = score_inherited
