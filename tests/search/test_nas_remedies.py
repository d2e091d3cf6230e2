"""The SPOS-side ranking remedies (search/nas/spos.py, spos_points.py, remedies.py): the sandwich
rule's subnets as a pure function of (seed, step), its accumulation over the cycle, an exact
resume, a supernet directory refusing the other rule, and the extra-supernet remedies entry."""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.core import atomic
from dsfec_jax.core.run_checkpoints import last_steps, read_extra
from dsfec_jax.train.loop import RunMismatch
from search.nas.space import key
from search.nas.spaces import get_space
from search.nas.spos import SALT, SANDWICH_CYCLE, SPOSStream, sampling_info, subnet_of_step
from search.recipes import get_recipe


@pytest.fixture(scope="module")
def setting():
    from dsfec_jax.data.points.sources import load_frames

    space = get_space("dsfec")
    recipe = get_recipe("smoke", space.base)
    family = zoo.family_of(space.base)
    frames = load_frames(recipe.data, "train", 8, seed=0, features=family.points.input_columns)
    return space, recipe, frames


def test_sandwich_cycle_is_largest_smallest_then_two_uniform_draws():
    space = get_space("dsfec")
    largest, smallest = space.largest(), space.smallest()
    assert largest != smallest
    draws = set()
    for seed in (0, 1):
        for step in range(4 * SANDWICH_CYCLE):
            genes = subnet_of_step(space, seed, step, "sandwich")
            assert genes == subnet_of_step(space, seed, step, "sandwich")  # pure: the same again
            phase = step % SANDWICH_CYCLE
            if phase == 0:
                assert genes == largest
            elif phase == 1:
                assert genes == smallest
            else:  # the uniform rule's draw for that (seed, step)
                assert genes == subnet_of_step(space, seed, step, "uniform")
                assert genes == space.sample(np.random.default_rng([seed, SALT, step]))
                draws.add(genes)
    assert len(draws) > 8  # not one fixed subnet: 16 draws over 26,244 subnets
    stream = SPOSStream(None, space, None, 3, "sandwich")
    assert [stream.genes(s) for s in range(6)] == [subnet_of_step(space, 3, s, "sandwich") for s in range(6)]
    with pytest.raises(ValueError):
        subnet_of_step(space, 0, 0, "greedy")


def _train(setting, run_dir, steps, sampling, stop_at=None):
    from search.nas.spos_points import train_point_supernet

    space, recipe, frames = setting
    return train_point_supernet(space, recipe, frames, run_dir, steps, seed=0, progress=False, stop_at=stop_at,
                                sampling=sampling)[3]


def _same(a, b) -> bool:
    return all(np.array_equal(x, y) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))


def test_resumed_sandwich_run_equals_an_uninterrupted_one_and_updates_once_a_cycle(setting, tmp_path, uncompiled_init):
    from search.nas.spos_points import base_init, supernet_detectors
    from dsfec_jax.train.step import init_state

    space, recipe, frames = setting
    det, _ = supernet_detectors(space, recipe, frames, "sandwich")
    start = init_state(det, det.optimizer(recipe.schedule, 8), jax.random.key(0), base_init(space.base))
    whole = _train(setting, tmp_path / "whole", 8, "sandwich")
    run = tmp_path / "killed"
    part = _train(setting, run, 8, "sandwich", stop_at=3)  # mid-cycle: no optimizer update yet
    assert _same(jax.device_get(part["params"]), jax.device_get(start["params"]))
    assert not _same(jax.device_get(part["batch_stats"]), jax.device_get(start["batch_stats"]))
    _train(setting, run, 8, "sandwich", stop_at=6)  # resumes mid-cycle: the accumulated gradient is state
    resumed = _train(setting, run, 8, "sandwich")
    assert read_extra(last_steps(run)[-1])["step"] == 8
    assert not _same(jax.device_get(whole["params"]), jax.device_get(start["params"]))  # 2 updates happened
    assert _same(jax.device_get(resumed["params"]), jax.device_get(whole["params"]))
    assert _same(jax.device_get(resumed["batch_stats"]), jax.device_get(whole["batch_stats"]))
    assert json.loads((run / "run.json").read_text())["sampling"] == "sandwich"
    # the directory refuses the other rule, before anything trains
    with pytest.raises(RunMismatch, match="sampling sandwich"):
        _train(setting, run, 8, "uniform")
    assert read_extra(last_steps(run)[-1])["step"] == 8


def test_a_supernet_dir_refuses_the_other_rule(tmp_path):
    assert sampling_info(tmp_path / "new", "sandwich") == {"sampling": "sandwich"}
    atomic.write_json(tmp_path / "uniform" / "run.json", {"sampling": "uniform", "steps": 4})
    assert sampling_info(tmp_path / "uniform", "uniform") == {"sampling": "uniform"}
    with pytest.raises(RunMismatch, match="sampling uniform"):
        sampling_info(tmp_path / "uniform", "sandwich")
    # a run started before the option existed trained uniformly and has no record
    atomic.write_json(tmp_path / "legacy" / "run.json", {"steps": 600})
    assert sampling_info(tmp_path / "legacy", "uniform") == {}
    with pytest.raises(RunMismatch):
        sampling_info(tmp_path / "legacy", "sandwich")


def test_remedies_entry_trains_another_supernet_and_writes_its_row(tmp_path, uncompiled_init):
    from search.nas import remedies

    space = get_space("dsfec")
    subnets = [space.largest(), space.base_genes(), space.smallest()]
    run_dir = tmp_path / "run"
    atomic.write_json(run_dir / "supernet" / "run.json", {"space": "dsfec", "steps": 6})
    pairs = [{"key": key(g), "inherited": 3.0 - i, "standalone": 1.0 + i, "params": 1} for i, g in enumerate(subnets)]
    atomic.write_json(run_dir / "ranking.json", {"metric": "car_mAP", "n": 3, "tau": -1.0, "p_value": 1.0,
                                                 "pairs": pairs})
    argv = [str(run_dir), "--profile", "smoke", "--supernet-steps", "4", "--sampling", "sandwich"]
    assert remedies.main(argv) == 0
    here = run_dir / "remedies" / "sandwich_4"
    assert read_extra(last_steps(here / "supernet")[-1])["step"] == 4
    data = json.loads((run_dir / "remedies.json").read_text())
    (row,) = data["supernets"]
    assert row["name"] == "sandwich_4" and row["sampling"] == "sandwich" and row["supernet_steps"] == 4
    assert row["subnets"] == [p["key"] for p in pairs] and row["standalone"] == [1.0, 2.0, 3.0]
    assert len(row["inherited"]) == 3 and all(np.isfinite(row["inherited"]))
    assert row["tau"] == pytest.approx(remedies.kendall_tau(row["inherited"], row["standalone"]), abs=1e-4)
    assert row["supernet_s"] > 0 and "--sampling sandwich" in row["command"] and row["environment"]
    md = (run_dir / "remedies.md").read_text()
    assert "sandwich_4: sandwich sampling | 4 |" in md and "the run's supernet (uniform) | 6 |" in md
    # again: the finished supernet is reused (no training, its time kept) and the row replaced, not added
    timing = (here / "timing.json").read_text()
    assert remedies.main(argv) == 0
    again = json.loads((run_dir / "remedies.json").read_text())["supernets"]
    assert len(again) == 1 and again[0]["inherited"] == row["inherited"] and (here / "timing.json").read_text() == timing
    # the same directory under the other rule is refused
    with pytest.raises(RunMismatch):
        remedies.main([*argv[:-1], "uniform", "--name", "sandwich_4"])
