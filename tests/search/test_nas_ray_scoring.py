"""Scoring a population with inherited weights on Ray actors (search.nas.ray_scoring): results in
the candidates' order, equal to the in-process scorer's, each actor pinned to its own CPU; and
`python -m search.nas --backend ray` routes the search's scoring through it."""

from __future__ import annotations

import functools
import os
import sys
import time

import jax
import numpy as np
import pytest

from dsfec_jax.core.threads import available_cpus
from search.nas.space import key
from search.nas.spaces import get_space

ray = pytest.importorskip("ray")
two_cpus = pytest.mark.skipif(len(available_cpus()) < 2, reason="two scoring actors need two CPUs")


@pytest.fixture
def local_ray_env(monkeypatch):
    """What the actors need to find this module's classes (pickled by value: Ray's workers do not
    import test modules), and the session's compilation cache: the actors inherit the
    environment of the private local Ray that RayScorer starts, so they load the executables
    this process compiled instead of compiling them again (same programs, a cache hit)."""
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    cache = jax.config.jax_compilation_cache_dir
    if cache:
        monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", cache)
    assert not ray.is_initialized()
    yield
    ray.cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    assert not ray.is_initialized()  # RayScorer shut down the Ray it started


class SlowFirst:
    """A toy scorer: the subnet whose first gene is 1 takes much longer than the rest, so with two
    actors the later subnets finish first; each result names its subnet and the process."""

    def __call__(self, batch):
        out = []
        for genes in batch:
            time.sleep(1.5 if genes[0] == 1 else 0.05)
            out.append({"key": key(genes), "pid": os.getpid()})
        return out


@two_cpus
def test_ray_scorer_keeps_the_candidates_order_and_pins_each_actor_to_its_own_cpu(local_ray_env):
    from search.nas.ray_scoring import RayScorer

    genes = [(1, 0, 2)] + [(0, i, 0) for i in range(5)]
    with RayScorer(SlowFirst, workers=2) as scorer:
        assert scorer([]) == [] and not ray.is_initialized()  # Ray starts at the first subnet to score
        out = scorer(genes)
        info = scorer.info()
    assert [r["key"] for r in out] == [key(g) for g in genes]  # not the order they finished in
    assert out[0]["pid"] != out[1]["pid"] and len({r["pid"] for r in out}) == 2  # both actors scored
    cpus = [i["cpus"] for i in info]
    assert all(len(c) == 1 and set(c) <= set(available_cpus()) for c in cpus) and cpus[0] != cpus[1]  # pinned, disjoint
    with pytest.raises(RuntimeError, match="closed"):
        scorer(genes)


def test_cpu_shares_are_disjoint_per_node():
    from search.nas.ray_scoring import assign_cpus

    placements = [("a", [0, 1, 2, 3]), ("b", [0, 1]), ("a", [3, 2, 1, 0]), ("b", [0, 1]), ("b", [0, 1])]
    assert assign_cpus(placements, 2) == [[0, 1], [0, 1], [2, 3], [0, 1], [0, 1]]  # b holds 3 x 2 CPUs of 2: wraps
    assert assign_cpus(placements[:2], 1) == [[0], [0]]
    with pytest.raises(ValueError, match="node b"):
        assign_cpus(placements, 3)


def test_an_unfinished_supernet_is_refused(tmp_path):
    from dsfec_jax.core.run_checkpoints import RunCheckpoints
    from search.nas.spos import finished_supernet

    with pytest.raises(RuntimeError, match="not finished .*step None, of 6"):
        finished_supernet(tmp_path, 6)
    tree = {"params": {"w": np.ones(2, np.float32)}, "batch_stats": {}, "step": np.int32(3)}
    with RunCheckpoints(tmp_path) as checkpoints:
        checkpoints.save(3, tree, {})
    with pytest.raises(RuntimeError, match="step 3, of 6"):
        finished_supernet(tmp_path, 6)
    with RunCheckpoints(tmp_path) as checkpoints:
        checkpoints.save(6, tree, {})
    assert finished_supernet(tmp_path, 6)["params"]["w"].tolist() == [1.0, 1.0]


class Fingerprinted:
    """The engine's scorer, each result with the recalibrated BN statistics' sum beside the mAPs:
    a continuous function of the loaded supernet, the subnet and its recalibration, where a
    barely trained supernet's mAPs are all 0 (equal whoever computes them)."""

    def __init__(self, scorer):
        self.scorer = scorer

    def __call__(self, batch):
        out = []
        for genes in batch:
            result = self.scorer([genes])[0]
            stats = self.scorer.predictor.variables["batch_stats"]
            result["bn_sum"] = float(sum(np.asarray(x, np.float64).sum() for x in jax.tree.leaves(stats)))
            out.append(result)
        return out


def fingerprinted(factory):
    return Fingerprinted(factory())


def finished_random_supernet(space, run_dir, steps: int) -> None:
    """RUN_DIR/supernet as a finished SPOS run leaves it, with random weights and BN statistics
    instead of `steps` trained steps (training is the command test's; this is about scoring)."""
    from conftest import random_variables
    from dsfec_jax.core.run_checkpoints import RunCheckpoints
    from search.nas.elastic import supernet_of
    from search.nas.spos import SupernetDetector

    variables = random_variables(SupernetDetector(supernet_of(space)), 0)
    with RunCheckpoints(run_dir / "supernet") as checkpoints:
        checkpoints.save(steps, {**variables, "step": np.int32(steps)}, {})


@two_cpus
def test_two_actors_score_a_batch_as_the_in_process_scorer_does(tmp_path, local_ray_env):
    """Smoke profile of the yolov8n_adapter space (8 val maps, BN recalibrated on 2 batches of 4
    maps): 2 actors each load the finished supernet from RUN_DIR/supernet and build the engine's
    scorer; 4 subnets scored there equal the in-process scorer's to float32 rounding, in order.
    Measured: the actors run XLA on 1 thread each, this process on all its CPUs, and the BN
    statistics' sums differ by up to 3e-7 relative (reductions split by thread count; with this
    process on 1 thread too they agree bit for bit); the mAPs (0 here) agreed exactly."""
    from search.nas.ray_scoring import RayScorer, nas_factory
    from search.nas.engines import PROFILES, rd_engine

    space, p = get_space("yolov8n_adapter"), PROFILES["smoke"]
    finished_random_supernet(space, tmp_path, p.supernet_steps)
    rng = np.random.default_rng(1)
    genes = [space.sample(rng) for _ in range(4)]
    local = Fingerprinted(rd_engine(space, p, "smoke", tmp_path, 0, False, load_only=True).scorer)(genes)
    factory = functools.partial(fingerprinted, nas_factory(space.name, p, "smoke", tmp_path, 0))
    with RayScorer(factory, workers=2) as scorer:
        remote = scorer(genes)
        info = scorer.info()
    assert all(np.isfinite(r["bn_sum"]) for r in local)
    sums = sorted(r["bn_sum"] for r in local)
    assert min(b - a for a, b in zip(sums, sums[1:])) > 1e-4 * max(map(abs, sums))  # far apart: a swap would show
    assert len(remote) == 4 and all(r == pytest.approx(l, rel=1e-6, abs=0) for r, l in zip(remote, local))
    cpus = [c for i in info for c in i["cpus"]]
    assert len(set(cpus)) == 2 == len(cpus) and [i["xla_threads"] for i in info] == [1, 1]  # 1 CPU each, its own
    assert not (tmp_path / "supernet" / "run.json").exists()  # the actors loaded the supernet: nothing trained


def test_the_command_scores_the_search_through_ray_actors(tmp_path, monkeypatch):
    """--backend ray --address --workers reach run_nas, which scores every generation through the
    RayScorer (made after the supernet, closed before the reports) and the one reference subnet
    in-process."""
    from search.journal import Journal
    from search.nas import __main__ as cli
    from search.nas import ray_scoring, run
    from search.nas.engines import Engine

    seen = {}
    monkeypatch.setattr(cli, "run_nas", lambda *a, **kw: seen.update(kw) or tmp_path / "report.md")
    assert cli.main(["--space", "yolov8n_adapter", "--profile", "smoke", "--backend", "ray", "--address", "ray://h:1",
                     "--workers", "3", "--run-dir", str(tmp_path)]) == 0
    assert (seen["backend"], seen["address"], seen["workers"]) == ("ray", "ray://h:1", 3)
    with pytest.raises(SystemExit):
        cli.main(["--space", "yolov8n_adapter", "--workers", "3"])  # --workers without --backend ray

    events = []

    def local_scorer(batch):
        events.append(("local", len(batch)))
        return [{"mAP50": 0.0} for _ in batch]

    class FakeRay:
        def __init__(self, factory, workers, address, max_workers, log):
            events.append(("open", factory.func.__name__, factory.args, workers, address, max_workers))

        def __call__(self, batch):
            events.append(("score", len(batch)))
            return [{"mAP50": float(sum(g))} for g in batch]

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            events.append(("close",))

    def fake_engine(space, p, profile, run_dir, seed, progress):
        events.append(("supernet",))
        return Engine(p.supernet_steps, local_scorer, "mAP50", "toy data", "none")

    monkeypatch.setattr(run, "engine_for", lambda space: fake_engine)
    monkeypatch.setattr(run, "subnet_costs", lambda space, genes: {"params": float(sum(genes)), "gflops": 1.0})
    monkeypatch.setattr(run, "shipped_reference", lambda model: None)
    monkeypatch.setattr(ray_scoring, "RayScorer", FakeRay)
    run.run_nas("yolov8n_adapter", tmp_path / "run", "smoke", backend="ray", address="ray://h:1", workers=2,
                progress=False, log=lambda _: None)
    p = run.PROFILES["smoke"]
    assert events[:2] == [("supernet",), ("open", "engine_scorer",
                                          ("yolov8n_adapter", p, "smoke", str((tmp_path / "run").resolve()), 0),
                                          2, "ray://h:1", p.population)]
    assert events[2:] == [("score", p.population)] * p.generations + [("close",), ("local", 1)]
    records = Journal(tmp_path / "run").records()  # journalled in the driver, as with the local scorer
    assert len(records) == p.population * p.generations and (tmp_path / "run" / "report.md").exists()
