"""Scoring subnets with inherited weights on Ray actors: `--backend ray` for the search itself.

`RayScorer(factory, workers)` is a score function like the in-process ones (a list of genes ->
a list of score dicts, in the same order), backed by `workers` Ray actors. Each actor
- reserves `cpus_per_worker` Ray CPUs and pins every thread of its process to that many CPUs of
  its node, disjoint from the other actors' on the same node, before XLA starts (as
  dsfec_jax.core.threads does for --threads: XLA sizes its CPU pool from the process's affinity);
- then calls `factory()` once to build its scorer. For a NAS run the factory is
  `engine_scorer(space, profile, ...)`: the engine's own scorer (engines.rd_engine / point_engine)
  over the finished supernet, read from RUN_DIR/supernet's last checkpoint (spos.finished_supernet).
  The driver trains the supernet before any actor starts; an actor trains and writes nothing;
- then scores one subnet per call. The driver hands subnets out as actors come free (ray.util's
  ActorPool, results in submission order), so the slower subnets of a batch do not hold up a
  fixed share.

Scores equal the in-process scorer's to float32 rounding, not always bit for bit: XLA splits its
CPU reductions by thread count, so an actor on 1 thread and a driver on 2 sum in different orders
(measured on the smoke profile: BN statistics within 3e-7 relative, mAPs equal; with the driver
on 1 thread too, every float equal). A run is reproducible for a given CPUs-per-actor count.

Journalling stays in the driver (evolution.score_missing): a batch's scores come back together
and are journalled one by one, so a kill loses at most the batch in flight and a resumed run
rescores nothing it journalled, as with the local scorer. Ray is imported only here, and only
when a RayScorer is made. On a multi-node cluster the run directory must be on a filesystem the
nodes share, and the project importable on every node (as for the stand-alone trials on Ray).
"""

from __future__ import annotations

import contextlib
import functools
import os
from collections import Counter
from pathlib import Path
from typing import Callable, Sequence

from dsfec_jax.core.threads import available_cpus, eigen_threads, pin

from ..ray_session import ray_session

DEFAULT_WORKERS = 2  # where the cluster reports no CPUs


def engine_scorer(space_name: str, p, profile: str, run_dir: str, seed: int):
    """The NAS engine's scorer over the finished supernet in run_dir: what each actor builds once
    (imports here, after the actor pinned its threads; nothing trains)."""
    from .engines import engine_for
    from .spaces import get_space

    space = get_space(space_name)
    return engine_for(space)(space, p, profile, Path(run_dir), seed, False, load_only=True).scorer


def nas_factory(space_name: str, p, profile: str, run_dir: str | Path, seed: int) -> Callable:
    """A picklable zero-argument factory of engine_scorer for the actors."""
    return functools.partial(engine_scorer, space_name, p, profile, str(Path(run_dir).resolve()), seed)


def assign_cpus(placements: Sequence[tuple[str, Sequence[int]]], per_worker: int) -> list[list[int]]:
    """Each actor's CPUs from (node id, CPUs the actor's process may use) per actor: the actors
    of a node take consecutive disjoint slices of its CPUs in actor order (wrapping round only
    when a node holds more actors than it has CPUs for)."""
    rank: Counter = Counter()
    out = []
    for node, cpus in placements:
        cpus = sorted(cpus)
        if not 1 <= per_worker <= len(cpus):
            raise ValueError(f"{per_worker} CPUs per scoring worker; its node {node} lets it use {cpus}")
        r = rank[node]
        rank[node] += 1
        out.append([cpus[(r * per_worker + j) % len(cpus)] for j in range(per_worker)])
    return out


def pin_to(cpus: Sequence[int]) -> list[int] | None:
    """Pin every thread of this process to `cpus` before XLA starts (core.threads.pin with a chosen
    set rather than the first N) -> the process's CPUs; None where the OS has no CPU affinity (the
    actor then runs unpinned)."""
    if not hasattr(os, "sched_setaffinity"):
        return None
    pin(len(cpus), list(cpus))
    return available_cpus()


class ScoringWorker:
    """One actor's side (ray.remote wraps it in RayScorer): placement, pin, build, then score."""

    def __init__(self):
        self.scorer = None

    def placement(self) -> tuple[str, list[int]]:
        import ray

        return ray.get_runtime_context().get_node_id(), available_cpus()

    def pin(self, cpus: list[int]) -> list[int] | None:
        return pin_to(cpus)

    def build(self, factory: Callable) -> None:
        self.scorer = factory()

    def score(self, genes: list[int]) -> dict:
        return self.scorer([tuple(genes)])[0]

    def info(self) -> dict:
        import ray

        return {"pid": os.getpid(), "node": ray.get_runtime_context().get_node_id(), "cpus": available_cpus(),
                "xla_threads": eigen_threads()}


class RayScorer:
    """list of genes -> list of score dicts (the candidates' order) from `workers` Ray actors, each
    with `cpus_per_worker` CPUs and its own scorer from `factory()`. Ray: a private local one
    started here, or the cluster at `address`, or the one this process already runs (left
    running on close). `workers` None: the cluster's CPUs / cpus_per_worker (DEFAULT_WORKERS
    where it reports none), at most `max_workers`. Ray and the actors start at the first
    non-empty batch (a resumed search with nothing left to score starts none). A context
    manager; close() kills the actors (and shuts down the Ray it started)."""

    def __init__(self, factory: Callable, workers: int | None = None, address: str | None = None,
                 cpus_per_worker: int = 1, max_workers: int | None = None, log: Callable[[str], None] = print):
        try:
            import ray
        except ImportError as err:
            raise SystemExit("--backend ray needs Ray: pip install 'dsfec_jax[ray]'") from err
        if (workers is not None and workers < 1) or cpus_per_worker < 1:
            raise ValueError(f"workers {workers}, cpus_per_worker {cpus_per_worker}: both must be >= 1")
        self.ray, self.factory, self.workers, self.address = ray, factory, workers, address
        self.cpus_per_worker, self.max_workers, self.log = cpus_per_worker, max_workers, log
        self.actors, self.pool, self.closed = [], None, False
        self._session = contextlib.ExitStack()

    def _start(self) -> None:
        from ray.util import ActorPool

        ray, address, per = self.ray, self.address, self.cpus_per_worker
        try:
            if not ray.is_initialized():
                # a local Ray with as many CPUs as this process may use (a `taskset` limit holds for the actors too)
                self._session.enter_context(ray_session(address, len(available_cpus())))
            cluster = int(ray.cluster_resources().get("CPU", 0))
            n = self.workers or (max(1, cluster // per) if cluster else DEFAULT_WORKERS)
            n = min(n, self.max_workers) if self.max_workers else n
            if address is None and n * per > cluster:
                raise ValueError(f"{n} scoring workers x {per} CPUs: this Ray has {cluster} CPUs "
                                 "(the actors would wait for them forever)")
            actor = ray.remote(num_cpus=per)(ScoringWorker)
            self.actors = [actor.remote() for _ in range(n)]
            cpus = assign_cpus(ray.get([a.placement.remote() for a in self.actors]), per)
            ray.get([a.pin.remote(c) for a, c in zip(self.actors, cpus)])
            ray.get([a.build.remote(self.factory) for a in self.actors])
            self.pool = ActorPool(self.actors)
            self.log(f"scoring on Ray: {n} actors x {per} CPU(s) of {cluster}")
        except BaseException:
            self.close()
            raise

    def _ready(self) -> None:
        if self.closed:
            raise RuntimeError("RayScorer is closed")
        if self.pool is None:
            self._start()

    def __call__(self, batch: Sequence) -> list[dict]:
        if not batch:
            return []
        self._ready()
        genes = [[int(x) for x in g] for g in batch]
        return list(self.pool.map(lambda actor, g: actor.score.remote(g), genes))

    def info(self) -> list[dict]:
        """Each actor's pid, node, CPUs and XLA CPU pool size (0 until its first computation)."""
        self._ready()
        return self.ray.get([a.info.remote() for a in self.actors])

    def close(self) -> None:
        for a in self.actors:
            self.ray.kill(a)
        self.actors, self.pool, self.closed = [], None, True
        self._session.close()  # shuts down the Ray started here, if any

    def __enter__(self) -> "RayScorer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
