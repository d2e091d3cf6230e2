"""The one-shot strategy: train one weight-sharing supernet, then rank every candidate with the
weights it inherits.

Any family whose record has a `Supernet` (DSFEC: elastic stage_blocks) can be searched this way.
The supernet has the most blocks any candidate has in each stage; a candidate (subnet) uses the
first k blocks of each stage, which in Flax means the subset of the supernet's top-level
parameter entries that the family's `Supernet.blocks` maps below depth k (DSFEC:
`stage2_block0..k-1`). Each step trains one subnet drawn uniformly from the candidates (each
round of len(candidates) steps visits every candidate once, in a seeded random order); only its
parameters move. The subnet's depth is a traced input of the supernet (DSFEC:
`DSFECNet.backbone(depth=...)`), so one compiled step (train.step's, with the idle blocks kept)
trains every subnet and one compiled function recalibrates them: compiles, not steps, dominate
a 2-core budget. Before a subnet is evaluated its batch-norm statistics are recalibrated on
training batches, because the supernet's running statistics mix every subnet's activations.
"""

from __future__ import annotations

import contextlib
import hashlib
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from dsfec_jax.core import checkpoint, progress
from dsfec_jax import zoo
from dsfec_jax.core.environment import environment
from dsfec_jax.core.provenance import jsonable
from dsfec_jax.data.batches import BatchStream, collate
from dsfec_jax.data.prefetch import Prefetcher
from dsfec_jax.data.points.pillarize import PillarSpec, pillar_budget
from dsfec_jax.data.points.sources import load_frames
from dsfec_jax.modalities.registry import protocol
from dsfec_jax.modalities.points.predict import Predictor
from dsfec_jax.modalities.registry import modality_of
from dsfec_jax.profile.records import profile
from dsfec_jax.train.loop import COMPILE_USUAL
from dsfec_jax.train.loss_watch import LossWatch, NonFiniteLoss
from dsfec_jax.train.schedules import optimizer
from dsfec_jax.train.step import batch_on_device, init_state, train_step_fn

from .inherit import initial_variables
from .journal import Journal
from .recipes import get_recipe
from .space import SearchSpaceError
from .trial import match_classes, measured

# Batch-norm recalibration reads at most this many training batches (one pass over the frames at
# most): fewer let the draw of calibration frames reorder the candidates (docs/search.md,
# "Batch-norm recalibration", has the measurement on two saved quick stage-2 supernets).
CALIBRATION_BATCHES = 64
# The supernet's losses stay on the device (train.loss_watch) and are read every this many steps
# and before the supernet is saved: a non-finite one stops training within this many steps.
LOSS_CHECK_EVERY = 50


def hooks(base: str):
    """The supernet hooks of `base`'s family; a family without them cannot share weights."""
    family = zoo.family_of(base)
    if family.supernet is None:
        raise SearchSpaceError(f"--strategy oneshot: the {family.name} family has no weight-sharing supernet "
                               f"(its record's `supernet`); {base!r} needs --strategy train")
    return family.supernet


def supernet_overrides(candidates: list[dict], field: str) -> dict:
    """The supernet: per stage the most blocks of any candidate. Only depth (`field`) may differ."""
    others = [{k: v for k, v in c["overrides"].items() if k != field} for c in candidates]
    if any(o != others[0] for o in others) or not all(field in c["overrides"] for c in candidates):
        raise SearchSpaceError("--strategy oneshot shares weights across depths only: every candidate must "
                               f"differ from the others in {field} and nothing else")
    depth = np.max([c["overrides"][field] for c in candidates], axis=0)
    return {**others[0], field: tuple(int(d) for d in depth)}


def in_subnet(key: str, depth, blocks: dict):
    """Does the subnet of `depth` (traced ints, one per stage) use the supernet's top-level module
    `key`? `blocks`: module -> (stage, block) of the modules a subnet may leave idle."""
    if key not in blocks:
        return True
    stage, block = blocks[key]
    return block < depth[stage]


def keep_idle(new: dict, old: dict, depth, blocks: dict) -> dict:
    """`new` for the subnet's modules, `old` for the supernet's idle blocks."""
    return {k: jax.tree.map(lambda n, o, a=in_subnet(k, depth, blocks): jnp.where(a, n, o), new[k], old[k])
            for k in old}


def supernet_step(supernet, tx):
    """One jitted step (state, batch, depth) -> (state, loss) that trains the subnet of `depth`:
    train.step's step with the depth as a traced input, then the idle blocks put back (their
    gradients are 0, but weight decay and momentum must not move them either)."""
    net = zoo.family_of(supernet.config).supernet
    blocks = net.blocks(supernet.config)
    inner = train_step_fn(supernet, tx, (net.input,))

    def step(state, batch, depth):
        new, metrics = inner(state, batch, depth)
        return {**new, "params": keep_idle(new["params"], state["params"], depth, blocks),
                "batch_stats": keep_idle(new["batch_stats"], state["batch_stats"], depth, blocks)}, metrics["loss"]

    return jax.jit(step, donate_argnums=0)


class SubnetPredictor(Predictor):
    """The supernet's predictor run as the subnet of `depth` (a traced input, so one compile
    evaluates every candidate); set `.variables` and `.depth` between candidates."""

    def __init__(self, supernet, variables, depth, **options):
        super().__init__(supernet, variables, **options)
        self.depth, self.depth_input = depth, zoo.family_of(supernet.config).supernet.input

    def run(self, batch: dict):
        return jax.device_get(self.network(self.variables, {**batch, self.depth_input: self.depth}))


def module_keys(detector) -> tuple[str, ...]:
    return tuple(jax.eval_shape(detector.init, jax.random.key(0))["params"])


def recalibrator(supernet):
    """(variables, batches, depth) -> BN running statistics of the subnet of `depth` = the mean of
    its batch statistics over `batches` (one compiled function for every depth)."""
    net = zoo.family_of(supernet.config).supernet
    momentum = net.bn_momentum
    batch_stats = jax.jit(lambda v, x, d: supernet.apply(v, {**x, net.input: d}, train=True)[1]["batch_stats"])

    def recalibrate(variables: dict, batches: list[dict], depth) -> dict:
        means = []
        for batch in batches:
            new, old = batch_stats(variables, batch["inputs"], depth), variables["batch_stats"]
            # new = m * old + (1 - m) * batch  =>  batch = (new - m * old) / (1 - m)
            means.append(jax.tree.map(lambda n, o: (n - momentum * o) / (1 - momentum), new, old))
        return jax.tree.map(lambda *x: np.mean(np.stack(x), 0), *means)

    return recalibrate


def calibration_batches(stream: BatchStream, spec: PillarSpec) -> list[dict]:
    """The first min(CALIBRATION_BATCHES, one epoch) batches of the training order, unaugmented:
    distinct training frames, the same for every candidate (so candidates are compared on one draw)."""
    return [collate([stream.frames[j] for j in stream.indices(s)], spec, stream.targets_fn, stream.origin_input)
            for s in range(min(CALIBRATION_BATCHES, stream.per_epoch))]


def run_oneshot(base: str, trials: list[dict], run_dir: str | Path, retry_failed: bool = False,
                log=print) -> list[dict]:
    """Train the supernet for these trials (one seed, one recipe) and journal one record each;
    if the supernet fails, every pending candidate is journaled as failed with the error."""
    journal = Journal(run_dir)
    todo = [t for t in trials if t["key"] not in journal.done(retry_failed)]
    if not todo:
        log("all one-shot candidates already in the journal")
        return journal.records()
    try:
        _train_and_rank(base, trials, journal, {t["key"] for t in todo}, log)
    except Exception as err:  # the sweep goes on: the failure is a record, not a crash
        for t in trials:
            if t["key"] not in journal.done(retry_failed=True):
                journal.append({**t, "status": "failed", "error": f"{type(err).__name__}: {err}",
                                "environment": environment()})
    return journal.records()


def _train_and_rank(base: str, trials: list[dict], journal: Journal, todo: set[str], log) -> None:
    recipe, seed, data = get_recipe(trials[0]["recipe"], base), trials[0]["seed"], trials[0]["data"]
    family, net, fixed = zoo.family_of(base), hooks(base), recipe.model_overrides()
    overrides = {**supernet_overrides(trials, net.field), **fixed}
    supernet = zoo.create(base, **overrides)
    frames = load_frames(data, "train", recipe.train_frames, seed=0, features=family.points.input_columns)
    # trained and recalibrated with pillar slots sized to the training frames (pillar_budget: the
    # same inputs, less padding), validated with the recipe's slots
    trainee = zoo.create(base, **{**overrides, "max_pillars": pillar_budget(frames, supernet.config.max_pillars)})
    cfg = trainee.config
    stream = BatchStream(frames, PillarSpec.of(cfg), family.points.targets(cfg), recipe.schedule.batch_size, seed,
                         origin_input=family.points.origin_input)
    depths = [jnp.asarray(getattr(zoo.config(base, **t["overrides"], **fixed), net.field), jnp.int32) for t in trials]
    steps = trials[0].get("supernet_steps") or recipe.supernet_steps or recipe.schedule.total_steps(len(frames))
    state, supernet_s, supernet_cpu = _supernet(trainee, stream, depths, recipe, steps, seed,
                                                journal.path.parent / supernet_file(trials), log,
                                                initial_variables(trials[0].get("init", "scratch")))
    recalibrate = recalibrator(trainee)
    with progress.stage("pillarizing the batch-norm calibration batches and loading the validation frames"):
        calib = calibration_batches(stream, PillarSpec.of(cfg))
        val = load_frames(data, "val", recipe.val_frames, seed=0, features=family.points.input_columns)
    predictor = SubnetPredictor(supernet, None, depths[0])
    pending = [(trial, depth) for trial, depth in zip(trials, depths) if trial["key"] in todo]
    bar = tqdm(pending, desc=f"candidates (seed {seed})", unit="candidate")
    for n, (trial, depth) in enumerate(bar):
        t1, c1 = time.perf_counter(), time.process_time()
        phases = {}  # wall seconds of each part of a candidate's evaluation (what a sweep's time goes to)
        # the first candidate also compiles the recalibration and the predictor; every one compiles its own profile
        with progress.stage(f"scoring {trial['label']}: recalibrating batch norm, validating on {len(val)} frames, "
                            f"profiling" + (" (the first also compiles the predictor)" if n == 0 else "")):
            with _timed(phases, "recalibrate"):
                stats = recalibrate({"params": state["params"], "batch_stats": state["batch_stats"]}, calib, depth)
            predictor.variables, predictor.depth = {"params": state["params"], "batch_stats": stats}, depth
            with _timed(phases, "validate"):
                scores, tables = protocol(family.metric.name).validate(predictor, val, match_classes(family))
            with _timed(phases, "profile"):
                costs = measured_costs(journal, trial) or profile(
                    [zoo.create(base, **trial["overrides"])], timing=True, repeats=recipe.latency_repeats, warmup=1,
                    light=recipe.light_profile, modality_of=modality_of)[0]
        bar.set_postfix({family.metric.headline: f"{scores[family.metric.headline]:.2f}"})
        journal.append({**trial, "status": "ok", **measured(scores, tables, costs),
                        "supernet": {net.field: list(getattr(cfg, net.field)), "steps": steps,
                                     "wall_s": round(supernet_s, 1), "cpu_s": round(supernet_cpu, 1)},
                        "wall_s": round(supernet_s / len(trials) + time.perf_counter() - t1, 1),
                        "cpu_s": round(supernet_cpu / len(trials) + time.process_time() - c1, 1),
                        "phases_s": phases, "environment": environment()})
        log(f"    {trial['label']}: {family.metric.headline} {scores[family.metric.headline]:.2f} (inherited weights)")


@contextlib.contextmanager
def _timed(into: dict, phase: str):
    start = time.perf_counter()
    yield
    into[phase] = round(time.perf_counter() - start, 1)


def measured_costs(journal: Journal, trial: dict) -> dict | None:
    """The costs an earlier seed of the same candidate already measured (sizes and latency belong to
    the architecture, not to the weights: `--seeds N` profiles each candidate once), with "from": its key."""
    for r in journal.records():
        if (r["status"] == "ok" and r["key"] != trial["key"] and
                all(r.get(k) == jsonable(trial[k]) for k in ("base", "overrides", "recipe", "strategy"))):
            return {**r["costs"], "from": r["key"]}
    return None


def supernet_file(trials: list[dict]) -> str:
    """The saved supernet belongs to exactly this set of candidates, recipe, data and seed."""
    ident = hashlib.sha1(" ".join(sorted(t["key"] for t in trials)).encode()).hexdigest()[:12]
    return f"supernet_{ident}.msgpack"


def _check_supernet_losses(losses: LossWatch) -> float | None:
    """The latest loss; FloatingPointError naming the first non-finite step since the last check."""
    try:
        return losses.check()
    except NonFiniteLoss as err:
        raise FloatingPointError(f"supernet loss is {err.value} at step {err.step}") from err


def _supernet(supernet, stream, depths: list, recipe, steps: int, seed: int, path: Path, log, init=None):
    """Train the supernet (or read the one an interrupted run saved) -> (state, wall s, CPU s).
    `init`: trained variables to start from (search.inherit), else a fresh initialisation.
    A supernet saved only in part (killed while saving) is trained again, not failed on."""
    tx = optimizer(recipe.schedule, steps)
    if path.is_file():
        try:
            state = checkpoint.load(path, init_state(supernet, tx, jax.random.key(seed)))
        except checkpoint.CheckpointError as reason:
            log(f"{reason}: training the supernet again")
        else:
            manifest = checkpoint.read_manifest(path)
            log(f"supernet from {path} ({manifest['steps']} steps, trained in {manifest['wall_s']:.0f} s)")
            return state, manifest["wall_s"], manifest["cpu_s"]
    t0, c0 = time.perf_counter(), time.process_time()
    with progress.stage("initialising the supernet (compiling its initialisation)"):
        state = init_state(supernet, tx, jax.random.key(seed), init)
    step_fn = supernet_step(supernet, tx)
    losses = LossWatch()
    field = zoo.family_of(supernet.config).supernet.field
    with Prefetcher(lambda s: batch_on_device(stream.batch(s)), range(steps)) as batches:
        bar = tqdm(batches, total=steps, desc=f"supernet {tuple(getattr(supernet.config, field))}", unit="step")
        for step, batch in bar:
            round_, pos = divmod(step, len(depths))
            i = int(np.random.default_rng([seed, 7, round_]).permutation(len(depths))[pos])
            with progress.stage("compiling the supernet's training step", usual=COMPILE_USUAL, enabled=step == 0):
                state, loss = step_fn(state, {"inputs": batch["inputs"], "targets": batch["targets"]}, depths[i])
            losses.add(step, loss)
            if (step + 1) % LOSS_CHECK_EVERY == 0 or step + 1 == steps:  # always before the save below
                bar.set_postfix(loss=f"{_check_supernet_losses(losses):.3f}")
    wall_s, cpu_s = time.perf_counter() - t0, time.process_time() - c0
    log(f"supernet {getattr(supernet.config, field)}: {steps} steps in {wall_s:.0f} s")
    checkpoint.save(path, state, {"steps": steps, "seed": seed, "wall_s": round(wall_s, 1), "cpu_s": round(cpu_s, 1),
                                  field: list(getattr(supernet.config, field))})
    return state, wall_s, cpu_s
