"""SPOS on the elastic supernet: uniform single-path training, BN recalibration, subnet scores.

- `SupernetDetector` is the supernet as the training loop sees a detector: its inputs carry the
  subnet (`masks`, and `nas`: the Exchangers' fusion options), so train.loop's resumable loop,
  checkpoints and compiled step serve it unchanged (one compile for every subnet).
- `SPOSStream` draws batch s's subnet uniformly from `default_rng([seed, SALT, s])`: like the
  batch itself, a pure function of (seed, s), so a resumed supernet run trains what an
  uninterrupted one trains. `sampling="sandwich"` (BigNAS / US-Nets' sandwich rule): batch s
  trains SANDWICH[s % 4] (the largest subnet, the smallest, then each of the next two steps its own
  uniform draw), and the detector's optimizer (`accumulating_optimizer`, optax.MultiSteps) steps
  once a cycle on the 4 batches' mean gradient; the rule is kept in run.json (`sampling_info`),
  and a supernet directory refuses the other rule (search.nas.spos_points wires it for DSFEC).
- `SubnetScorer` scores subnets with the weights they inherit: the BN running statistics are
  recalibrated (reset to the mean of the subnet's batch statistics over fixed unaugmented
  training batches, as search.oneshot does for depth), then COCO mAP on validation maps through
  the RD predictor with the subnet's masks as inputs (one compile for every subnet).
- `subnet_costs`: params (BN-folded, the paper's convention) and GFLOPs (2 x MACs at the real
  input size) of the stand-alone subnet, from shapes only: cheap enough to check constraints
  before anything is scored.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from dsfec_jax import zoo
from dsfec_jax.core.run_checkpoints import last_steps, read_extra, read_state
from dsfec_jax.core.progress import stage
from dsfec_jax.core.provenance import jsonable, versions
from dsfec_jax.data.rd.augment import RDAugment
from dsfec_jax.data.rd.batches import DEFAULT_MAX_BOXES, RDBatchStream
from dsfec_jax.data.rd.representations import RDRepresentation
from dsfec_jax.modalities.rd.evaluate import evaluate_rd
from dsfec_jax.layers.yolo import BN_MOMENTUM
from dsfec_jax.modalities.rd.predict import RDPredictor
from dsfec_jax.profile import counting
from dsfec_jax.modalities.rd.profile import folded_params
from dsfec_jax.train.loop import RunMismatch, RunSpec, train
from dsfec_jax.train.parallel import PER_STEP_INPUTS
from dsfec_jax.train.schedules import Schedule, optimizer

from .elastic import MaskTable, masked_apply, supernet_of
from .space import Genes, SearchSpace

SALT = 23  # separates the subnet draws from the batch order's random streams
CALIBRATION_BATCHES = 16
# the first subnet a scorer scores compiles its recalibration and predictor: 56 s for the
# YOLOv8n-Adapter smoke run on the 2-core dev box at load 9, under half that at load 3
SCORER_COMPILE_USUAL = "up to a minute on 2 CPU cores"


class SupernetDetector:
    """The supernet with the subnet as an input: `apply(variables, {maps..., 'masks', 'nas'})`."""

    def __init__(self, supernet):
        self.supernet, self.config, self.module = supernet, supernet.config, supernet.module

    @property
    def name(self) -> str:
        return f"{self.config.name}_supernet"

    def init(self, rng) -> dict:
        variables = self.supernet.init(rng)
        return {"params": variables["params"], "batch_stats": variables["batch_stats"]}

    def apply(self, variables: dict, inputs: dict, train: bool = False):
        inputs = dict(inputs)
        nas, masks = inputs.pop("nas"), inputs.pop("masks")
        return masked_apply(self.supernet, {**variables, "nas": nas}, inputs, masks, train)


class SubnetInputs:
    """genes -> the subnet's inputs {'masks', 'nas'} (look-ups: MaskTable)."""

    def __init__(self, space: SearchSpace, supernet):
        self.space, self.table = space, MaskTable(space, supernet)
        self.nas = jax.eval_shape(lambda: supernet.init(jax.random.key(0))).get("nas", {})

    def __call__(self, genes: Genes) -> dict:
        fusions = self.space.overrides(genes).get("fusion")

        def put(tree):
            return {k: ({"fusion": np.int32(fusions[int(k.rsplit("_", 1)[1])])} if "fusion" in v else put(v))
                    for k, v in tree.items()}

        return {"masks": self.table.masks(genes), "nas": put(self.nas) if fusions is not None else {}}


SAMPLINGS = ("uniform", "sandwich")
# the sandwich rule (BigNAS, US-Nets): every cycle of batches trains the largest, the smallest and
# two uniform subnets, their gradients accumulated into one optimizer update (SANDWICH_CYCLE batches)
SANDWICH = ("largest", "smallest", "uniform", "uniform")
SANDWICH_CYCLE = len(SANDWICH)


def check_sampling(sampling: str) -> str:
    if sampling not in SAMPLINGS:
        raise ValueError(f"sampling {sampling!r}; expected one of {SAMPLINGS}")
    return sampling


def subnet_of_step(space: SearchSpace, seed: int, step: int, sampling: str = "uniform") -> Genes:
    """Batch `step`'s subnet, a pure function of (seed, step): uniform from default_rng([seed, SALT,
    step]); sandwich: SANDWICH[step % 4] (largest, smallest, then uniform draws from that rng)."""
    rule = SANDWICH[step % SANDWICH_CYCLE] if check_sampling(sampling) == "sandwich" else "uniform"
    if rule == "largest":
        return space.largest()
    if rule == "smallest":
        return space.smallest()
    return space.sample(np.random.default_rng([int(seed), SALT, int(step)]))


def sampling_info(run_dir: str | Path, sampling: str) -> dict:
    """run.json's record of the sampling rule ({'sampling': rule}); refuses a supernet directory
    trained with the other rule. A run started before the option existed trained uniformly and has
    no record: it resumes under uniform with none added (train.loop compares the setup)."""
    check_sampling(sampling)
    path = Path(run_dir) / "run.json"
    if not path.exists():
        return {"sampling": sampling}
    import json

    old = json.loads(path.read_text())
    if old.get("sampling", "uniform") != sampling:
        raise RunMismatch(f"{run_dir}: this supernet was trained with --sampling {old.get('sampling', 'uniform')}; "
                          f"the command asks --sampling {sampling}. Use another run directory for the other rule.")
    return {"sampling": sampling} if "sampling" in old else {}


def accumulating_optimizer(schedule: Schedule, total_steps: int, every: int):
    """The schedule's optimizer stepping once per `every` batches on their mean gradient
    (optax.MultiSteps); its learning-rate schedule counts optimizer updates (total_steps // every)."""
    import optax

    return optax.MultiSteps(optimizer(schedule, max(1, total_steps // every)), every).gradient_transformation()


class SPOSStream:
    """A batch stream whose batch s also carries its subnet (subnet_of_step: a pure function of (seed, s))."""

    def __init__(self, stream, space: SearchSpace, subnet_inputs: SubnetInputs, seed: int, sampling: str = "uniform"):
        self.stream, self.space, self.subnet_inputs, self.seed = stream, space, subnet_inputs, int(seed)
        self.sampling = check_sampling(sampling)

    def __getattr__(self, name):
        return getattr(self.stream, name)

    def genes(self, step: int) -> Genes:
        return subnet_of_step(self.space, self.seed, step, self.sampling)

    def batch(self, step: int, rows: slice = slice(None)) -> dict:
        """`rows`: only those rows of the inner stream's batch; the subnet's inputs are whole (one
        subnet a step), and named so that a mesh replicates them (train/parallel.py)."""
        batch = self.stream.batch(step, rows)
        subnet = self.subnet_inputs(self.genes(step))
        return {**batch, "inputs": {**batch["inputs"], **subnet}, PER_STEP_INPUTS: tuple(subnet)}


def train_supernet(space: SearchSpace, samples, schedule: Schedule, run_dir: str | Path, steps: int, seed: int = 0,
                   progress: bool = True, stop_at: int | None = None, load_only: bool = False):
    """Train (or resume) the space's supernet by SPOS in run_dir -> (SupernetDetector, SubnetInputs, state).
    `load_only`: nothing trains or writes; the state is the finished run's (finished_supernet)."""
    supernet = supernet_of(space)
    with stage(f"tracing the widths each of {space.name}'s choices sets (the subnet mask table)",
               enabled=progress and not load_only):
        det, subnet_inputs = SupernetDetector(supernet), SubnetInputs(space, supernet)
    if load_only:
        return det, subnet_inputs, finished_supernet(run_dir, steps)
    cfg = supernet.config
    stream = SPOSStream(RDBatchStream(samples, schedule.batch_size, seed, RDAugment(), RDRepresentation(), cfg.classes,
                                      DEFAULT_MAX_BOXES), space, subnet_inputs, seed)
    spec = RunSpec(Path(run_dir), schedule, seed, total_steps=steps, stop_at=stop_at, progress=progress)
    info = {"space": space.name, "base": space.base, "strategy": "spos", "config": jsonable(dataclasses.asdict(cfg)),
            "schedule": jsonable(dataclasses.asdict(schedule)), "seed": seed, "steps": steps,
            "train_samples": len(samples), "versions": versions()}
    state, _ = train(det, stream, spec, info)
    return det, subnet_inputs, state


def finished_supernet(run_dir: str | Path, steps: int) -> dict:
    """{'params', 'batch_stats'} of the supernet run in run_dir, read from its last checkpoint, which
    must be step `steps`'s: how a Ray scoring actor (search.nas.ray_scoring) loads what the driver
    trained, without train.loop's resume (which would append to run.json) and without training."""
    last = last_steps(run_dir)
    step = read_extra(last[-1]).get("step") if last else None
    if step != steps:
        raise RuntimeError(f"{run_dir}: the supernet is not finished (last checkpoint at step {step}, of {steps}); "
                           "train it first (search.nas.run trains it before any scoring worker starts)")
    raw = read_state(last[-1])
    return {"params": raw["params"], "batch_stats": raw["batch_stats"]}


class SubnetRDPredictor(RDPredictor):
    """The RD predictor over the supernet, run as the subnet in `.subnet` (set between subnets)."""

    subnet: dict = {}

    def decoded(self, inputs: dict):
        return super().decoded({**inputs, **self.subnet})


def recalibrator(det, momentum: float = BN_MOMENTUM):
    """(variables, batches, subnet inputs) -> BN running statistics of that subnet = the mean of its
    batch statistics over the batches (every BN of the network has `momentum`: YOLO's BN_MOMENTUM)."""
    batch_stats = jax.jit(lambda v, x: det.apply(v, x, train=True)[1]["batch_stats"])

    def recalibrate(variables: dict, batches: Sequence[dict], subnet: dict) -> dict:
        means = []
        for inputs in batches:
            new, old = batch_stats(variables, {**inputs, **subnet}), variables["batch_stats"]
            # new = m * old + (1 - m) * batch  =>  batch = (new - m * old) / (1 - m)
            means.append(jax.tree.map(lambda n, o: (n - momentum * o) / (1 - momentum), new, old))
        return jax.tree.map(lambda *x: jnp.mean(jnp.stack(x), 0), *means)

    return recalibrate


def score_inherited(scorer, batch: list[Genes]) -> list[dict]:
    """A scorer's loop over subnets (the RD and point scorers share it): recalibrate the subnet's BN
    statistics, put them and the subnet into the predictor, `scorer.evaluate()`. With
    `scorer.progress`, a bar over the subnets on stderr, and a stage line while the scorer's first
    subnet compiles the recalibration and the predictor (one compile serves every subnet)."""
    out = []
    for genes in tqdm(batch, desc="scoring subnets", unit="subnet", leave=False, disable=not scorer.progress):
        with stage("compiling the subnet scorer (batch-norm recalibration and the predictor)",
                   usual=SCORER_COMPILE_USUAL, enabled=scorer.progress and not scorer.warm):
            subnet = scorer.subnet_inputs(genes)
            stats = scorer.recalibrate({"params": scorer.params, "batch_stats": scorer.start_stats}, scorer.batches,
                                       subnet)
            scorer.predictor.variables = {"params": scorer.params, "batch_stats": stats}
            scorer.predictor.subnet = subnet
            out.append(scorer.evaluate())
        scorer.warm = True
    return out


class SubnetScorer:
    """score(list of genes) -> [{'mAP50', 'mAP50_95', 'mAP30'}] with inherited, recalibrated weights;
    `progress`: score_inherited's bar and compile line on stderr."""

    warm = False  # set once a subnet was scored: the compiled functions are cached

    def __init__(self, det: SupernetDetector, subnet_inputs: SubnetInputs, state: dict, train_samples, val_samples,
                 seed: int = 0, calibration_batches: int = CALIBRATION_BATCHES, batch_size: int = 16,
                 progress: bool = False):
        self.progress = progress
        self.det, self.subnet_inputs, self.val = det, subnet_inputs, val_samples
        self.params = state["params"]
        stream = RDBatchStream(train_samples, batch_size, seed, None, RDRepresentation(), det.config.classes,
                               DEFAULT_MAX_BOXES)
        self.batches = [stream.batch(s)["inputs"] for s in range(min(calibration_batches, stream.per_epoch))]
        self.recalibrate = recalibrator(det)
        self.start_stats = state["batch_stats"]
        self.predictor = SubnetRDPredictor(det, {"params": self.params, "batch_stats": self.start_stats})

    def evaluate(self) -> dict:
        scores = evaluate_rd(self.predictor, self.val)[0]
        return {k: float(scores[k]) for k in ("mAP50", "mAP50_95", "mAP30")}

    __call__ = score_inherited


def subnet_costs(space: SearchSpace, genes: Genes) -> dict:
    """{'params' (BN-folded), 'params_trainable', 'gflops'} of the stand-alone subnet, from shapes."""
    return model_costs(space.base, space.overrides(genes))


def model_costs(model: str, overrides: dict) -> dict:
    """subnet_costs of any zoo model and config overrides."""
    det = zoo.create(model, **overrides)
    shapes = jax.eval_shape(lambda: det.init(jax.random.key(0)))
    trainable = int(sum(np.prod(x.shape) for x in jax.tree.leaves(shapes["params"])))
    return {"params": folded_params(shapes["params"]), "params_trainable": trainable,
            "gflops": float(counting.count_gflops(det)["total"])}
