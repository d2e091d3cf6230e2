"""What each kind of search space brings to a NAS run (`SearchSpace.engine` names its kind): how
its supernet trains and its subnets score, on which data, and the network `dsfec export` writes
for it. The run itself (search -> reports) is run.py's; the Ray scoring actors build their
scorers here too (ray_scoring.py), so neither imports the other.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Callable

from dsfec_jax import zoo
from dsfec_jax.data.rd.sources import load_rd_samples
from dsfec_jax.train.schedules import get_schedule

from ..inherit import describe
from .space import SearchSpace
from .spos import SubnetScorer, train_supernet


@dataclasses.dataclass(frozen=True)
class NasProfile:
    """The budget of a run: data, supernet steps, search size."""

    train_samples: int
    val_samples: int
    supernet_steps: int | None  # None: the schedule's own length over the training samples
    batch_size: int
    population: int
    generations: int
    top_k: int
    calibration_batches: int
    schedule: str


PROFILES = {
    # a few minutes end to end: the command's wiring, not a result
    "smoke": NasProfile(32, 8, 6, 4, 6, 2, 3, 2, "yolo_quick"),
    # sized for a 2-core CPU: ~10 min of supernet, ~80 subnets scored
    "quick": NasProfile(600, 100, 600, 16, 16, 5, 5, 8, "yolo_quick"),
    # the paper's search (P 50, T 20, k 15) on a supernet trained with the paper's recipe: a GPU job
    "paper": NasProfile(1000, 200, None, 64, 50, 20, 15, 16, "yolo_paper"),
}


def rd_benchmark(space: SearchSpace) -> str:
    """The RD data a space's supernet trains and is scored on: its family's benchmark, the maps the
    shipped weights (the report's references) were trained and measured on."""
    return zoo.family_of(space.base).benchmark


def supernet(space: SearchSpace, p: NasProfile, run_dir: Path, seed: int = 0, progress: bool = True,
             load_only: bool = False):
    """The profile's training maps, SPOS step count and (detector, subnet inputs, state) of the run's
    supernet: trained, or resumed from RUN_DIR/supernet (nothing trains once it is finished);
    `load_only`: the finished supernet read from its last checkpoint, nothing trained or written."""
    train = load_rd_samples(rd_benchmark(space), "train", p.train_samples)
    schedule = get_schedule(p.schedule, batch_size=p.batch_size)
    steps = p.supernet_steps or schedule.total_steps(len(train))
    return train, steps, train_supernet(space, train, schedule, run_dir / "supernet", steps, seed, progress,
                                        load_only=load_only)


@dataclasses.dataclass
class Engine:
    """What a family brings to a run: its trained supernet's steps, the subnet scorer, the metric
    that ranks subnets, and how the report names its data."""

    steps: int
    scorer: Callable
    metric: str
    data: str
    calibration: str
    init: str | None = None  # what the supernet started from, given to the stand-alone retraining too
    # the zoo models whose shipped manifests were validated on the data `scorer` scores (the
    # report's hand-designed references)
    shipped: tuple[str, ...] = ()


# An engine function: (space, profile, profile name, run dir, seed, progress, load_only=False) -> Engine.
# load_only (Ray scoring actors, search.nas.ray_scoring): the same scorer over the supernet the
# driver finished, read from RUN_DIR/supernet's last checkpoint; nothing trains or writes.
def rd_engine(space: SearchSpace, p: NasProfile, profile: str, run_dir: Path, seed: int, progress: bool,
              load_only: bool = False, sampling: str = "uniform") -> Engine:
    if sampling != "uniform":
        raise ValueError(f"--sampling {sampling}: the RD supernet trains with uniform sampling only (sandwich: DSFEC-style spaces)")
    val = load_rd_samples(rd_benchmark(space), "val", p.val_samples)
    train, steps, (det, subnet_inputs, state) = supernet(space, p, run_dir, seed, progress, load_only)
    scorer = SubnetScorer(det, subnet_inputs, state, train, val, seed, p.calibration_batches, p.batch_size, progress)
    return Engine(steps, scorer, "mAP50", f"synthetic RD benchmark ({rd_benchmark(space)}), {len(val)} val maps",
                  f"{p.calibration_batches} batches of {p.batch_size} maps", shipped=("yolov8n", space.base))


def point_engine(space: SearchSpace, p: NasProfile, profile: str, run_dir: Path, seed: int, progress: bool,
                 load_only: bool = False, sampling: str = "uniform") -> Engine:
    """DSFEC-style families: the family's search recipe of the same name sets the data, grid and
    batch (search.recipes); the NAS profile the SPOS steps and the calibration frames (as many
    as the RD profile's)."""
    from dsfec_jax.data.points.sources import load_frames

    from ..recipes import get_recipe
    from .spos_points import PointSubnetScorer, train_point_supernet

    recipe, family = get_recipe(profile, space.base), zoo.family_of(space.base)
    frames = load_frames(recipe.data, "train", recipe.train_frames, seed=0, features=family.points.input_columns)
    val = load_frames(recipe.data, "val", recipe.val_frames, seed=0, features=family.points.input_columns)
    steps = p.supernet_steps or recipe.supernet_steps or recipe.schedule.total_steps(len(frames))
    det, validator, subnet_inputs, state, stream = train_point_supernet(space, recipe, frames, run_dir / "supernet",
                                                                       steps, seed, progress, load_only=load_only,
                                                                       sampling=sampling)
    batch = recipe.schedule.batch_size
    calibration = max(1, p.calibration_batches * p.batch_size // batch)
    scorer = PointSubnetScorer(det, validator, subnet_inputs, state, stream, val, calibration, progress)
    shipped = zoo.shipped_weights(space.base)
    return Engine(steps, scorer, family.metric.headline,
                  f"`{recipe.data}` point-cloud benchmark at the `{profile}` search recipe's grid, {len(val)} val frames",
                  f"{calibration} batches of {batch} frames", describe(shipped, leading=True) if shipped.is_file() else None)


@dataclasses.dataclass(frozen=True)
class EngineKind:
    """What NAS does differently for one kind of search space. `start(space, profile, profile
    name, run dir, seed, progress, load_only=False, sampling="uniform")` -> the run's Engine (an
    engine function above); `onnx_form(detector)` -> (the network as `dsfec export` writes it,
    without the decode; whether its matrix-product einsums become MatMul): what
    `search.nas.latency --runtime onnx` times."""

    start: Callable[..., Engine]
    onnx_form: Callable[[Any], tuple[Any, bool]]


def _grouped(detector) -> tuple[Any, bool]:
    """The point families' export form: grouped depthwise and textbook kernels (deploy.export.grouped);
    their einsums (the pillar net's linear layers) stay Einsum."""
    from dsfec_jax.deploy.export import grouped

    return grouped(detector), False


# the YOLO-RD spaces (elastic widths, search.nas.elastic): the RD export runs its 1x1 convs as MatMul
RD_ENGINE = EngineKind(rd_engine, lambda detector: (detector, True))
# the DSFEC-style spaces (sliced widths and depths, search.nas.slices)
POINT_ENGINE = EngineKind(point_engine, _grouped)


def engine_for(space: SearchSpace) -> Callable[..., Engine]:
    """The engine function of `space`'s kind (SearchSpace.engine)."""
    if space.engine is None:
        raise ValueError(f"search space {space.name!r} names no NAS engine (SearchSpace.engine: "
                         "search.nas.engines.RD_ENGINE or POINT_ENGINE)")
    return space.engine.start
