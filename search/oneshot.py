"""The one-shot strategy: train one weight-sharing supernet, then rank every candidate with the
weights it inherits.

The supernet has the most blocks any candidate has in each stage; a candidate (subnet) uses the
first k blocks of each stage, which in Flax means the subset of the supernet's top-level
parameter entries whose names it shares (`stage2_block0..k-1`). Each step trains one subnet
drawn uniformly from the candidates (each round of len(candidates) steps visits every
candidate once, in a seeded random order); only its parameters move. Before a
subnet is evaluated its batch-norm statistics are recalibrated on training batches, because the
supernet's running statistics mix every subnet's activations.
"""

from __future__ import annotations

import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax

from dsfec_jax import zoo
from dsfec_jax.data.batches import BatchStream, collate
from dsfec_jax.data.pillarize import PillarSpec
from dsfec_jax.data.sources import load_frames
from dsfec_jax.evaluate import evaluate
from dsfec_jax.models.dsfec import HEAD_NAMES
from dsfec_jax.predict import Predictor
from dsfec_jax.profile.environment import environment
from dsfec_jax.profile.records import profile
from dsfec_jax.train.losses import LossConfig, detection_loss
from dsfec_jax.train.schedules import optimizer
from dsfec_jax.train.step import init_state

from .journal import Journal
from .recipes import get_recipe
from .space import SearchSpaceError

CALIBRATION_BATCHES = 8
BN_MOMENTUM = 0.99  # dsfec_jax.layers.conv.batch_norm


def supernet_overrides(candidates: list[dict]) -> dict:
    """The supernet: per stage the most blocks of any candidate. Only depth may differ."""
    others = [{k: v for k, v in c["overrides"].items() if k != "stage_blocks"} for c in candidates]
    if any(o != others[0] for o in others) or not all("stage_blocks" in c["overrides"] for c in candidates):
        raise SearchSpaceError("--strategy oneshot shares weights across depths only: every candidate must "
                               "differ from the others in stage_blocks and nothing else")
    depth = np.max([c["overrides"]["stage_blocks"] for c in candidates], axis=0)
    return {**others[0], "stage_blocks": tuple(int(d) for d in depth)}


def subset(tree: dict, keys) -> dict:
    return {k: tree[k] for k in keys if k in tree}


def subnet_step(sub, keys, tx, loss_cfg: LossConfig):
    """A jitted step that trains the subnet `sub` inside the supernet state (state donated)."""
    def loss_fn(params, batch_stats, batch):
        outputs, updates = sub.apply({"params": params, "batch_stats": batch_stats}, batch["inputs"], train=True)
        return detection_loss(outputs, batch["targets"], loss_cfg)[0], updates["batch_stats"]

    def step(state, batch):
        grad_fn = jax.value_and_grad(loss_fn, has_aux=True)
        (loss, stats), g = grad_fn(subset(state["params"], keys), subset(state["batch_stats"], keys), batch)
        grads = {k: g[k] if k in g else jax.tree.map(jnp.zeros_like, v) for k, v in state["params"].items()}
        updates, opt_state = tx.update(grads, state["opt_state"], state["params"])
        moved = optax.apply_updates(state["params"], updates)
        params = {k: moved[k] if k in keys else v for k, v in state["params"].items()}  # idle blocks stay put
        return {"params": params, "batch_stats": {**state["batch_stats"], **stats}, "opt_state": opt_state,
                "step": state["step"] + 1}, loss

    return jax.jit(step, donate_argnums=0)


def module_keys(detector) -> tuple[str, ...]:
    return tuple(jax.eval_shape(detector.init, jax.random.key(0))["params"])


def recalibrate(sub, params: dict, batch_stats: dict, batches: list[dict]) -> dict:
    """BN running statistics of `sub` = the mean of its batch statistics over `batches`."""
    apply = jax.jit(lambda v, x: sub.apply(v, x, train=True)[1]["batch_stats"])
    means = []
    for batch in batches:
        new = apply({"params": params, "batch_stats": batch_stats}, batch["inputs"])
        # new = m * old + (1 - m) * batch  =>  batch = (new - m * old) / (1 - m)
        means.append(jax.tree.map(lambda n, o: (n - BN_MOMENTUM * o) / (1 - BN_MOMENTUM), new, batch_stats))
    return jax.tree.map(lambda *x: np.mean(np.stack(x), 0), *means)


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
    t0 = time.perf_counter()
    recipe, seed, data = get_recipe(trials[0]["recipe"]), trials[0]["seed"], trials[0]["data"]
    fixed = recipe.model_overrides()
    supernet = zoo.create(base, **supernet_overrides(trials), **fixed)
    subs = [zoo.create(base, **t["overrides"], **fixed) for t in trials]
    keys = [module_keys(s) for s in subs]
    frames = load_frames(data, "train", recipe.train_frames, seed=0)
    cfg = supernet.config
    heads = dict(zip(HEAD_NAMES, cfg.head_classes))
    stream = BatchStream(frames, PillarSpec.of(cfg), heads, cfg.output_stride, recipe.schedule.batch_size, seed)
    steps = recipe.schedule.total_steps(len(frames))
    tx = optimizer(recipe.schedule, steps)
    state = init_state(supernet, tx, jax.random.key(seed))
    fns = [subnet_step(s, set(k), tx, LossConfig()) for s, k in zip(subs, keys)]
    for step in range(steps):
        round_, pos = divmod(step, len(subs))
        i = int(np.random.default_rng([seed, 7, round_]).permutation(len(subs))[pos])
        batch = stream.batch(step)
        state, loss = fns[i](state, {"inputs": batch["inputs"], "targets": batch["targets"]})
        if not np.isfinite(float(loss)):
            raise FloatingPointError(f"supernet loss is {float(loss)} at step {step}")
    supernet_s = time.perf_counter() - t0
    log(f"supernet {cfg.stage_blocks}: {steps} steps in {supernet_s:.0f} s")
    calib = [collate([frames[j] for j in stream.indices(s)], PillarSpec.of(cfg), heads, cfg.output_stride)
             for s in range(CALIBRATION_BATCHES)]
    val = load_frames(data, "val", recipe.val_frames, seed=0)
    for trial, sub, k in zip(trials, subs, keys):
        if trial["key"] not in todo:
            continue
        t1 = time.perf_counter()
        params = subset(state["params"], k)
        stats = recalibrate(sub, params, subset(state["batch_stats"], k), calib)
        result = evaluate(Predictor(sub, {"params": params, "batch_stats": stats}), val)
        costs = profile([zoo.create(base, **trial["overrides"])], timing=True, repeats=recipe.latency_repeats, warmup=1)[0]
        metrics = {kk: result[kk] for kk in ("car_mAP", "car_AP4", "mAP")}
        metrics.update(class_mAP=result["metrics"]["class_mAP"], **{"AP@4": result["metrics"]["AP@4"]})
        journal.append({**trial, "status": "ok", "metrics": metrics,
                        "costs": {c: costs[c] for c in ("params", "gflops", "memory_mb", "latency_ms", "latency_p90_ms")},
                        "supernet": {"stage_blocks": list(cfg.stage_blocks), "steps": steps,
                                     "wall_s": round(supernet_s, 1)},
                        "wall_s": round(supernet_s / len(trials) + time.perf_counter() - t1, 1),
                        "environment": environment()})
        log(f"    {trial['label']}: car mAP {metrics['car_mAP']:.2f} (inherited weights)")
