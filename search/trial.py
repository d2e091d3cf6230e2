"""One trial: config -> zoo.create -> train -> evaluate -> profile -> record (never raises)."""

from __future__ import annotations

import hashlib
import json
import time
import traceback
from pathlib import Path

from dsfec_jax import api, zoo
from dsfec_jax.core import atomic
from dsfec_jax.core.environment import environment
from dsfec_jax.core.progress import stage
from dsfec_jax.profile.records import profile
from dsfec_jax.core.provenance import jsonable
from dsfec_jax.core.run_checkpoints import last_steps
from dsfec_jax.modalities.registry import modality_of

from . import significance
from .inherit import describe, initial_variables, source_weights
from .recipes import get_recipe

TRIAL_FIELDS = ("base", "label", "overrides", "recipe", "data", "seed", "strategy", "init", "supernet_steps",
                "key")  # what make_trial writes; a record adds the measurements
COST_COLUMNS = ("params", "gflops", "memory_mb", "latency_ms", "latency_p90_ms")  # what a record keeps of a profile
# ...and, where the profile has them, the latency's spread over the repeats and the machine's verdict
# while it was timed (core/machine_load.py); journals from before them lack both
TIMING_COLUMNS = ("latency_p10_ms", "machine_load")


def trial_key(spec: dict) -> str:
    """Stable identity of a trial (base, overrides, recipe, data, seed)."""
    ident = {k: spec[k] for k in ("base", "overrides", "recipe", "data", "seed")}
    if spec.get("strategy", "train") != "train":  # keeps the keys of earlier train-strategy journals
        ident["strategy"] = spec["strategy"]
    if spec.get("init", "scratch") != "scratch":
        ident["init"] = spec["init"]
    if spec.get("supernet_steps") is not None:  # a one-shot supernet of another length is another trial
        ident["supernet_steps"] = spec["supernet_steps"]
    return hashlib.sha1(json.dumps(jsonable(ident), sort_keys=True).encode()).hexdigest()[:12]


def make_trial(base: str, candidate: dict, recipe: str, data: str, seed: int, strategy: str = "train",
               supernet_steps: int | None = None, init: str | None = None) -> dict:
    """`supernet_steps` (one-shot only): train the supernet this long instead of the recipe's length.
    `init`: the weights it starts from (search.inherit.describe), else the recipe's choice."""
    init = init or describe(source_weights(base, candidate["overrides"], recipe))
    spec = {"base": base, "label": candidate["label"], "overrides": candidate["overrides"], "recipe": recipe,
            "data": data, "seed": seed, "strategy": strategy, "init": init}
    if supernet_steps is not None:
        spec["supernet_steps"] = supernet_steps
    return {**spec, "key": trial_key(spec)}


def run_trial(trial: dict, run_dir: str | Path, progress: bool = False) -> dict:
    """Train and measure one candidate; a failure (NaN loss, OOM, ...) becomes a 'failed' record.
    `progress`: the training bar and the compile / profile stage lines on stderr (a trial run here;
    a Ray worker's stderr is a log, not a terminal)."""
    t0, c0 = time.perf_counter(), time.process_time()
    record = {k: jsonable(v) for k, v in trial.items()}
    try:
        record.update(measure(trial, Path(run_dir) / "trials" / trial["key"], progress))
        record["status"] = "ok"
    except Exception as err:  # a trial must never stop the sweep
        record.update(status="failed", error=f"{type(err).__name__}: {err}",
                      traceback=traceback.format_exc(limit=4)[-2000:])
    record["wall_s"] = round(time.perf_counter() - t0, 1)
    record["cpu_s"] = round(time.process_time() - c0, 1)  # the cost to quote on a shared machine
    record["environment"] = environment()
    return record


def rescore(record: dict, run_dir: str | Path) -> dict:
    """The "matches" field of a finished trial that has none (a journal from before its protocol
    kept match tables): its run resumes at the last step, so nothing trains, and validates the final
    weights. The recomputed headline must equal the recorded one, or the tables would describe
    other weights (ValueError)."""
    trial_dir = Path(run_dir) / "trials" / record["key"]
    if record.get("strategy", "train") != "train":
        raise ValueError(f"trial {record['key']}: a {record['strategy']!r} trial keeps no weights of its own to rescore")
    if record.get("status") != "ok" or not (trial_dir / "checkpoints").is_dir():
        raise ValueError(f"trial {record['key']} ({record.get('label')}): not a finished trial with checkpoints "
                         f"under {trial_dir}")
    scores = _fit_trial({k: v for k, v in record.items() if k in TRIAL_FIELDS}, trial_dir)
    headline = zoo.family_of(record["base"]).metric.headline
    was, now = record["metrics"].get(headline), scores.get(headline)
    if was is None or now is None or abs(was - now) > 1e-6 * max(1.0, abs(was)):
        raise ValueError(f"trial {record['key']} ({record.get('label')}): its final weights score {headline} {now}, "
                         f"the journal says {was}; not adding match tables that describe other weights")
    tables = scores.get("match_tables", {})
    if not tables:
        raise ValueError(f"trial {record['key']}: the {zoo.family_of(record['base']).metric.name} protocol keeps "
                         "no match tables")
    return significance.matches_entry(tables)


def held_out(record: dict, run_dir: str | Path, split: str, count: int) -> dict:
    """A finished trial's final weights (what its headline scored; a run's weight average where it
    kept one) scored by its family's protocol on `count` samples of `split` of the trial's data ->
    {"metrics", "matches"}: the protocol's figures and every match class's table, for intervals
    narrower than the recipe's validation samples allow. Written once to RUN_DIR/held_out/ (a
    rerun reads it back); ValueError for a trial without finished weights."""
    cache = Path(run_dir) / "held_out" / f"{record['key']}-{split}-{count}.json"
    if cache.is_file():
        return json.loads(cache.read_text())
    trial_dir = Path(run_dir) / "trials" / record["key"]
    steps = last_steps(trial_dir) if record.get("status") == "ok" else []
    if record.get("strategy", "train") != "train" or not steps:
        raise ValueError(f"trial {record['key']} ({record.get('label')}): no finished weights under {trial_dir} "
                         "(a failed, unfinished or weight-sharing trial)")
    recipe = get_recipe(record["recipe"], record["base"])
    cfg = zoo.config(record["base"], **{**record["overrides"], **recipe.model_overrides()})
    family = zoo.family_of(cfg)
    samples = load_data(cfg, record["data"], split, count)
    scores, tables = modality_of(cfg).protocols[family.metric.name].validate(
        api.load(cfg, weights=steps[-1]), samples, match_classes(family))
    out = {"key": record["key"], "split": split, "count": count, "weights": str(steps[-1]),
           "metrics": jsonable(scores), "matches": significance.matches_entry(tables)}
    atomic.write_json(cache, out)
    return out


def flat_metrics(scores: dict) -> dict:
    """Per-class APs of the VoD and RD protocols as top-level keys (AP_car, AP_corridor_car, AP50_car, ...), so a
    report column reads them like the headline figures; DSFEC's scores pass through."""
    out = dict(scores)
    for group in ("AP", "AP_corridor", "AP50"):
        if isinstance(scores.get(group), dict):
            out.update({f"{group}_{cls}": v for cls, v in scores[group].items()})
    return out


def match_classes(family) -> tuple[str, ...]:
    """The classes whose per-frame matches a trial keeps for the report's bootstrap intervals
    (the protocol's `match_class`: Car for DSFEC's nuScenes tables, "*" (every class) for the RD
    tables; none for VoD)."""
    return (family.metric.match_class,) if family.metric.match_class else ()


def measured(scores: dict, tables: dict, costs: dict) -> dict:
    """The measured part of a trial record, whichever strategy (train, oneshot) produced it:
    metrics (per-class groups flattened), the profile's cost columns (and, when an earlier
    seed's profile was reused, the key it came from), and the match tables for intervals."""
    out = {"metrics": flat_metrics(scores), "costs": {k: costs[k] for k in COST_COLUMNS}
           | {k: costs[k] for k in TIMING_COLUMNS if k in costs}}
    if "from" in costs:
        out["costs_from"] = costs["from"]
    if tables:
        out["matches"] = significance.matches_entry(tables)
    return out


def load_data(model, data: str, split: str, count: int):
    """The samples a trial of `model` (a config or a registered name) trains or validates on, as
    its modality loads them (point frames, RD samples, camera images)."""
    return modality_of(model).load_samples(zoo.family_of(model), data, split, count, 0)


def _fit_trial(trial: dict, trial_dir: Path, progress: bool = False) -> dict:
    """Train (or resume) the trial's run -> its final validation scores, match tables included:
    the samples and the fit of the config's modality (whatever it reads)."""
    recipe = get_recipe(trial["recipe"], trial["base"])
    overrides = {**trial["overrides"], **recipe.model_overrides()}
    cfg = zoo.config(trial["base"], **overrides)
    frames, val = (load_data(cfg, trial["data"], split, n) for split, n in
                   (("train", recipe.train_frames), ("val", recipe.val_frames)))
    return modality_of(cfg).fit(cfg, frames, val, recipe.schedule, trial_dir, trial["seed"],
                        run_info={"trial": jsonable(trial)}, progress=progress,
                        init_variables=initial_variables(trial.get("init", "scratch")), overrides=overrides,
                        match_classes=match_classes(zoo.family_of(cfg)), **recipe.fit_options())[2]


def measure(trial: dict, trial_dir: Path, progress: bool = False) -> dict:
    recipe = get_recipe(trial["recipe"], trial["base"])
    scores = _fit_trial(trial, trial_dir, progress)
    tables = scores.pop("match_tables", {})
    # sizes and latency of the inference form (RadarNeXt: MobileOne branches fused), as the paper counts
    deployed = zoo.Detector(zoo.deploy_config(zoo.config(trial["base"], **trial["overrides"])))
    with stage(f"profiling {trial['label']}: compiling its inference network, timing "
               f"{recipe.latency_repeats} runs", enabled=progress):
        costs = profile([deployed], timing=True, repeats=recipe.latency_repeats, warmup=1,
                        light=recipe.light_profile, modality_of=modality_of)[0]
    return measured(scores, tables, costs)
