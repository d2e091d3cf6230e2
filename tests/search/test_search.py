import json
import textwrap

import pytest

from dsfec_jax import zoo
from dsfec_jax.core.grid import Grid
from search import blocks, grid, recipes, report, stem, trial
from search.activations import activation_candidates
from search.journal import Journal
from search.space import SearchSpaceError, candidates, parse_axis
from dsfec_jax.train.schedules import get_schedule
from builders import QUICK_INIT
from conftest import tiny


def tiny_l(**overrides):
    """DSFEC-L on the tiny grid with one conv per head: this file's searches and supernets vary
    stage depths only, fewer layers compile faster, and every test here building the same depths
    compiles the same programs (compile-cache hits between tests)."""
    return tiny("dsfec_l", head_convs=1, **overrides)


@pytest.fixture
def tiny_search(monkeypatch):
    """A tiny registered base and a tiny recipe, so a sweep trains in seconds."""
    monkeypatch.setitem(zoo.REGISTRY, "tiny_l", tiny_l(name="tiny_l", stage_blocks=(1, 2, 1, 1)).config)
    tiny_recipe = recipes.Recipe("quick", get_schedule("quick", steps=2, batch_size=2, warmup_steps=1), 4, 2,
                                 Grid((0.0, 8.0), (-4.0, 4.0), (-2.5, 2.5), 0.5), 64, None, 1,
                                 supernet_steps=2, light_profile=True)
    monkeypatch.setitem(recipes.RECIPES["dsfec"], "quick", tiny_recipe)
    return "tiny_l"


def test_axes_expand_and_validate_before_training():
    axis = parse_axis("stage2_blocks=1,3", "dsfec_l")
    assert [c["overrides"]["stage_blocks"] for c in candidates("dsfec_l", [axis])] == [(3, 1, 6, 3), (3, 3, 6, 3)]
    tied = candidates("dsfec_l", [parse_axis("stem_filters=16", "dsfec_l")])[0]["overrides"]
    assert tied == {"stem_filters": 16, "fec_filters": (32, 128, 16)}
    tuples = parse_axis("stage_blocks=1,1,3,2|3,3,2,3", "dsfec_s")
    assert tuples.values == ((1, 1, 3, 2), (3, 3, 2, 3))
    with pytest.raises(SearchSpaceError, match="unknown field 'stem_filterz'"):
        parse_axis("stem_filterz=3", "dsfec_l")
    with pytest.raises(SearchSpaceError, match="stage_blocks"):
        candidates("dsfec_l", [parse_axis("stage2_blocks=0,3", "dsfec_l")])
    with pytest.raises(SearchSpaceError, match="f1 >= f3"):
        candidates("dsfec_l", [parse_axis("stem_filters=64", "dsfec_l")])


def test_invalid_axis_fails_before_any_training(tmp_path, monkeypatch):
    monkeypatch.setattr(trial, "measure", lambda *a: pytest.fail("trained an invalid search"))
    with pytest.raises(SystemExit, match="stage_blocks"):
        blocks.main(["--stage", "2", "--values", "0,3", "--out", str(tmp_path / "bad")])
    with pytest.raises(SystemExit, match="unknown field"):
        grid.main(["--axis", "nope=1,2", "--out", str(tmp_path / "bad2")])
    assert not (tmp_path / "bad" / "journal.jsonl").exists()


def test_activation_candidates_one_component_at_a_time():
    cands = activation_candidates("dsfec_m", ("relu", "mish"))
    labels = [c["label"] for c in cands]
    assert labels[0] == "paper mix" and "fec=relu" not in labels and "fec=mish" in labels
    assert {"act_car_head": "relu", "act_truck_head": "relu"} in [c["overrides"] for c in cands]


def test_real_sweep_trains_measures_and_reports(tiny_search, tmp_path, capsys, uncompiled_init):
    out = tmp_path / "run"
    assert blocks.main(["--stage", "2", "--values", "1,2", "--base", tiny_search, "--strategy", "train",
                        "--out", str(out)]) == 0
    err = capsys.readouterr().err  # each trial says what it waits on: its training bar, compile and profile
    assert err.count(f"compiling {tiny_search}'s training step...") == 2 and f"{tiny_search}: 100%" in err
    assert "profiling stage2_blocks=1: compiling its inference network" in err
    records = Journal(out).records()
    assert [r["status"] for r in records] == ["ok", "ok"], [r.get("error") for r in records]
    g = [r["costs"]["gflops"] for r in records]
    p = [r["costs"]["params"] for r in records]
    assert g[0] < g[1] and p[0] < p[1]  # more blocks cost more
    assert all(0 <= r["metrics"]["car_mAP"] <= 100 and r["costs"]["latency_ms"] > 0 for r in records)
    assert records[0]["environment"]["versions"]["jax"] and records[0]["wall_s"] > 0
    for f in ("report.md", "report.csv", "records.json", "map_vs_gflops.png", "map_vs_latency.png"):
        assert (out / f).exists(), f
    md = (out / "report.md").read_text()
    assert "stage2_blocks=2 (base)" in md and "(-" in md  # the other row shows its change against the base
    assert (out / "map_vs_gflops.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert json.loads((out / "search.json").read_text())["command"].startswith("python -m search.blocks")
    sig = json.loads((out / "significance.json").read_text())  # the bootstrap re-scores the recorded matches
    assert sig["frames"] == 2 and set(sig["delta"]) == {"stage2_blocks=1"}
    for r in records:
        assert sig["point"][r["label"]] == pytest.approx(r["metrics"]["car_mAP"], abs=1e-3)


def fake_measure(calls, fail_label=None):
    def measure(t, trial_dir, progress=False):
        calls.append(t["label"])
        if t["label"] == fail_label:
            raise FloatingPointError("loss is nan at step 3")
        n = t["overrides"].get("stem_filters", 1)
        return {"metrics": {"car_mAP": 10.0 + n, "car_AP4": 20.0, "mAP": 5.0},
                "costs": {"params": 1000 * n, "gflops": 0.1 * n, "memory_mb": 1.0, "latency_ms": 2.0 * n,
                          "latency_p90_ms": 2.5 * n}}
    return measure


def test_kill_and_resume_skips_finished_trials(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(trial, "measure", fake_measure(calls))
    out = tmp_path / "run"
    real_append = Journal.append

    def killed_after_two(self, record):
        real_append(self, record)
        if len(self.records()) == 2:
            raise KeyboardInterrupt  # the sweep is killed between trials
    monkeypatch.setattr(Journal, "append", killed_after_two)
    with pytest.raises(KeyboardInterrupt):
        stem.main(["--values", "32,16,12,8", "--out", str(out)])
    assert len(Journal(out).records()) == 2
    monkeypatch.setattr(Journal, "append", real_append)
    assert stem.main(["--values", "32,16,12,8", "--out", str(out)]) == 0
    assert calls == ["stem_filters=32", "stem_filters=16", "stem_filters=12", "stem_filters=8"]
    assert len(Journal(out).records()) == 4


def test_a_failed_trial_is_recorded_and_the_sweep_goes_on(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(trial, "measure", fake_measure(calls, fail_label="stem_filters=16"))
    out = tmp_path / "run"
    assert stem.main(["--values", "32,16,12", "--seeds", "2", "--out", str(out)]) == 0
    records = Journal(out).records()
    assert [r["status"] for r in records].count("failed") == 2 and len(records) == 6
    failed = [r for r in records if r["status"] == "failed"][0]
    assert "FloatingPointError: loss is nan" in failed["error"]
    md = (out / "report.md").read_text()
    assert "Failed: stem_filters=16" in md and "± 0.00" in md
    assert stem.main(["--values", "32,16,12", "--seeds", "2", "--out", str(out)]) == 0  # finished: nothing reruns
    assert calls.count("stem_filters=16") == 2
    monkeypatch.setattr(trial, "measure", fake_measure(calls))
    assert stem.main(["--values", "32,16,12", "--seeds", "2", "--out", str(out), "--retry-failed"]) == 0
    assert calls.count("stem_filters=16") == 4 and len(calls) == 8
    assert all(r["status"] == "ok" for r in Journal(out).records())


def test_pareto_front():
    assert report.pareto([(1, 10), (2, 12), (3, 11), (2, 9)]) == [0, 1]


def test_experiment_tables_print_the_paper_beside_ours(tmp_path, monkeypatch, capsys):
    from experiments import table1, table2, table3

    monkeypatch.setattr(trial, "measure", fake_measure([]))
    assert table2.main(["--out", str(tmp_path / "t2")]) == 0
    out = capsys.readouterr().out
    assert "| 12 | 22.00 (26.5) |" in out and "(4.32)" in out
    assert table3.main(["--out", str(tmp_path / "t3")]) == 0
    out = capsys.readouterr().out
    assert "| 3 | 11.00 (26.17) |" in out and "1027" in out
    assert table1.main([]) == 0
    assert "| dsfec_s |" in capsys.readouterr().out


# Imported at start-up by every Python process that sees it on PYTHONPATH; only Ray's trial
# workers act on it: they register tiny_search's base (the trials name it) and build their
# variables from init's shapes instead of compiling `init` (~12 s of each ~40 s trial, and not
# what the Ray backend test is about). Training, validation, profiling and the journal are the
# real ones.
RAY_WORKER_SITE = """
import sys

if sys.argv and sys.argv[0].endswith("default_worker.py"):
""" + textwrap.indent(QUICK_INIT + """
zoo.REGISTRY["tiny_l"] = zoo.create(
    "dsfec_l", name="tiny_l", stage_blocks=(1, 2, 1, 1), head_convs=1, max_pillars=96, max_points=4,
    grid=Grid(x_range=(0.0, 16.0), y_range=(-8.0, 8.0), z_range=(-2.5, 2.5), cell=0.5)).config
""", "    ")


def test_ray_backend_runs_a_two_trial_sweep(tiny_search, tmp_path, monkeypatch):
    """Two trials of the tiny base (registered in Ray's workers too, by RAY_WORKER_SITE) on the
    smoke recipe, which the workers resolve by name."""
    import os

    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(RAY_WORKER_SITE)
    inherited = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(site), *inherited]))  # Ray's workers inherit it
    out = tmp_path / "ray_run"
    assert blocks.main(["--stage", "4", "--values", "1,2", "--base", tiny_search, "--profile", "smoke",
                        "--strategy", "train", "--backend", "ray", "--out", str(out)]) == 0
    records = Journal(out).records()
    assert sorted(r["label"] for r in records) == ["stage4_blocks=1", "stage4_blocks=2"]
    assert all(r["status"] == "ok" for r in records), [r.get("error") for r in records]
    assert (out / "report.md").exists()


def test_oneshot_trains_one_supernet_and_ranks_every_depth(tiny_search, tmp_path, monkeypatch, capsys, uncompiled_init):
    from search import oneshot

    out = tmp_path / "oneshot"
    assert blocks.main(["--stage", "2", "--values", "1,2", "--base", tiny_search, "--strategy", "oneshot",
                        "--seeds", "2", "--supernet-steps", "4", "--out", str(out)]) == 0
    err = capsys.readouterr().err  # the supernet's bar and compile, then a bar over the candidates
    assert err.count("compiling the supernet's training step... (usually") == 2
    assert "supernet (1, 2, 1, 1): 100%" in err and "| 4/4 [" in err
    assert "candidates (seed 0): 100%" in err and "candidates (seed 1): 100%" in err
    assert "scoring stage2_blocks=2: recalibrating batch norm, validating on 2 frames, profiling" in err
    records = Journal(out).records()
    assert [r["status"] for r in records] == ["ok"] * 4, [r.get("error") for r in records]
    assert [r["seed"] for r in records] == [0, 0, 1, 1] and len(list(out.glob("supernet_*.msgpack"))) == 2
    # a candidate's costs belong to its architecture: the second seed reuses the first seed's profile
    assert [r.get("costs_from") for r in records] == [None, None, records[0]["key"], records[1]["key"]]
    assert records[2]["costs"] == records[0]["costs"] and records[3]["costs"] == records[1]["costs"]
    records = records[:2]
    assert {tuple(r["supernet"]["stage_blocks"]) for r in records} == {(1, 2, 1, 1)}
    assert records[0]["costs"]["gflops"] < records[1]["costs"]["gflops"]
    assert all(r["strategy"] == "oneshot" for r in records)
    assert all(r["supernet"]["steps"] == 4 for r in records)  # --supernet-steps: two rounds, not the recipe's 2
    assert all(set(r["phases_s"]) == {"recalibrate", "validate", "profile"} for r in records)
    assert all("car" in r["matches"] for r in records) and (out / "significance.json").exists()
    assert "supernet (1, 2, 1, 1) trained 4 steps in" in (out / "report.md").read_text()
    assert "(seeds 0, 1)" in (out / "report.md").read_text()  # one supernet per seed, in seed order
    # subnets are prefixes of the supernet: their parameter entries are a subset of its entries
    sub = oneshot.module_keys(zoo.create(tiny_search, stage_blocks=(1, 1, 1, 1)))
    sup = oneshot.module_keys(zoo.create(tiny_search, stage_blocks=(1, 2, 1, 1)))
    assert set(sub) < set(sup) and "stage2_block1" in set(sup) - set(sub)


def test_supernet_at_a_depth_is_the_subnet_and_trains_only_its_blocks():
    import jax
    import jax.numpy as jnp
    import numpy as np
    from search import oneshot
    from dsfec_jax.train.schedules import optimizer
    from dsfec_jax.train.step import init_state

    sup, sub = tiny_l(stage_blocks=(1, 3, 1, 1)), tiny_l(stage_blocks=(1, 2, 1, 1))
    variables = sup.init(jax.random.key(1))
    keys = oneshot.module_keys(sub)
    sub_vars = {c: {k: variables[c][k] for k in keys if k in variables[c]} for c in variables}
    inputs = sup.dummy_inputs(2, seed=3)
    depth = jnp.array([1, 2, 1, 1])
    # jitted, as the one-shot search runs them: one compile serves every depth (a traced input);
    # op by op, the four forward passes below compiled ~280 small programs (~10 s)
    sup_apply, sub_apply = jax.jit(sup.apply), jax.jit(sub.apply)
    gated, plain = sup_apply(variables, {**inputs, "depth": depth}), sub_apply(sub_vars, inputs)
    for a, b in zip(jax.tree.leaves(gated), jax.tree.leaves(plain)):
        np.testing.assert_allclose(a, b, atol=1e-5)
    deeper = sup_apply(variables, {**inputs, "depth": jnp.array([1, 3, 1, 1])})
    assert not np.allclose(jax.tree.leaves(deeper)[0], jax.tree.leaves(plain)[0])
    # one step of the depth-2 subnet moves its blocks and leaves the idle third block as it was
    tx = optimizer(get_schedule("quick", steps=2, warmup_steps=1), 2)
    state = init_state(sup, tx, jax.random.key(1))
    before = jax.tree.map(np.array, state["params"])
    outputs = deeper  # the full depth's outputs, for their shapes: all-background targets still have focal gradients
    targets = {h: {"cls": jnp.zeros_like(o["cls"]), "box": jnp.zeros_like(o["box"]),
                   "reg_mask": jnp.zeros(o["cls"].shape[:-1])} for h, o in outputs.items()}
    state, _ = oneshot.supernet_step(sup, tx)(state, {"inputs": inputs, "targets": targets}, depth)
    moved = lambda k: any(not np.array_equal(a, b) for a, b in
                          zip(jax.tree.leaves(before[k]), jax.tree.leaves(state["params"][k])))
    assert moved("stage2_block1") and not moved("stage2_block2")


def test_recalibration_reads_distinct_frames_and_forgets_the_supernets_running_statistics(monkeypatch):
    import jax
    import numpy as np
    from search import oneshot
    from dsfec_jax.data.batches import BatchStream
    from dsfec_jax.data.points.pillarize import PillarSpec
    from dsfec_jax.data.points.sources import load_frames
    from dsfec_jax import zoo

    sup = tiny_l(stage_blocks=(1, 2, 1, 1))
    cfg, frames = sup.config, load_frames("synthetic", "train", 10, seed=0)
    stream = BatchStream(frames, PillarSpec.of(cfg), zoo.family_of(cfg).points.targets(cfg), 2, 0)
    batches = oneshot.calibration_batches(stream, PillarSpec.of(cfg))
    assert len(batches) == 5  # one epoch: 10 frames in batches of 2, none twice
    assert sorted(np.concatenate([stream.indices(s) for s in range(5)])) == list(range(10))
    monkeypatch.setattr(oneshot, "CALIBRATION_BATCHES", 3)
    assert len(oneshot.calibration_batches(stream, PillarSpec.of(cfg))) == 3
    # the recalibrated statistics are the subnet's own: whatever running statistics the supernet
    # carried in (they mix every subnet's activations) must not leak into them
    variables = sup.init(jax.random.key(0))
    garbage = jax.tree.map(lambda x: x + 5.0 * np.random.default_rng(1).standard_normal(x.shape), variables["batch_stats"])
    recalibrate, depth = oneshot.recalibrator(sup), np.array([1, 1, 1, 1], np.int32)
    a = recalibrate(variables, batches[:2], depth)
    b = recalibrate({**variables, "batch_stats": garbage}, batches[:2], depth)
    for x, y, g in zip(jax.tree.leaves(a), jax.tree.leaves(b), jax.tree.leaves(garbage)):
        np.testing.assert_allclose(x, y, rtol=1e-3, atol=1e-3)
        assert not np.allclose(x, g)


def test_oneshot_resume_reuses_the_saved_supernet(tiny_search, tmp_path):
    out = tmp_path / "oneshot"
    argv = ["--stage", "2", "--values", "1,2", "--base", tiny_search, "--strategy", "oneshot", "--out", str(out)]
    assert blocks.main(argv) == 0
    assert len(list(out.glob("supernet_*.msgpack"))) == 1
    journal = Journal(out)
    first = journal.records()
    journal.path.write_text(json.dumps(first[0]) + "\n")  # as if killed while ranking the second candidate
    lines = []
    from search.oneshot import run_oneshot
    from search.trial import make_trial
    trials = [make_trial(tiny_search, {"label": r["label"], "overrides": {"stage_blocks": tuple(r["overrides"]["stage_blocks"])}},
                         "quick", "synthetic", 0, "oneshot") for r in first]
    run_oneshot(tiny_search, trials, out, log=lines.append)
    assert any(line.startswith("supernet from") for line in lines), lines
    records = journal.records()
    assert [r["label"] for r in records] == [r["label"] for r in first]
    assert records[1]["metrics"] == first[1]["metrics"]  # same supernet, same ranking


def test_supernet_steps_make_other_trials_and_bad_values_are_refused(tiny_search, tmp_path):
    """A supernet of another length is another trial (its own key, so its own saved supernet): a
    RUN_DIR never resumes a supernet trained for a different number of steps."""
    candidate = {"label": "stage2_blocks=1", "overrides": {"stage_blocks": (1, 1, 1, 1)}}
    keys = {trial.make_trial(tiny_search, candidate, "quick", "synthetic", 0, "oneshot", steps)["key"]
            for steps in (None, 4, 8)}
    assert len(keys) == 3
    argv = ["--stage", "2", "--values", "1,2", "--base", tiny_search, "--out", str(tmp_path / "x")]
    with pytest.raises(SystemExit, match="supernet-steps 0"):
        blocks.main(argv + ["--strategy", "oneshot", "--supernet-steps", "0"])
    with pytest.raises(SystemExit, match="supernet-steps is for --strategy oneshot"):
        blocks.main(argv + ["--strategy", "train", "--supernet-steps", "4"])


def test_oneshot_refuses_non_depth_axes():
    from search.oneshot import supernet_overrides

    with pytest.raises(SearchSpaceError, match="stage_blocks and nothing else"):
        supernet_overrides([{"overrides": {"stem_filters": 8}}, {"overrides": {"stem_filters": 12}}], "stage_blocks")


def test_kendall_tau_and_compare(tmp_path, monkeypatch):
    from search.compare import compare
    from search.ranking import kendall_tau

    assert kendall_tau([1, 2, 3, 4], [10, 20, 30, 40]) == 1.0
    assert kendall_tau([1, 2, 3, 4], [4, 3, 2, 1]) == -1.0
    assert kendall_tau([1, 2, 3], [1, 3, 2]) == pytest.approx(1 / 3)
    from search.ranking import tau_p_value
    assert tau_p_value([1, 2, 3, 4, 5, 6], [1, 2, 3, 4, 5, 6]) == pytest.approx(1 / 720)  # one perfect order
    assert tau_p_value([1, 2, 3, 4, 5, 6], [1, 2, 3, 4, 6, 5]) == pytest.approx(6 / 720)  # tau 0.87: 1 + 5 swaps
    assert tau_p_value([1, 2, 3], [3, 2, 1]) == 1.0
    monkeypatch.setattr(trial, "measure", fake_measure([]))
    stem.main(["--values", "32,16,12", "--out", str(tmp_path / "a")])
    stem.main(["--values", "32,16,12", "--out", str(tmp_path / "b"), "--seeds", "1"])
    result = compare(str(tmp_path / "a"), str(tmp_path / "b"))
    assert result["kendall_tau"] == 1.0 and len(result["candidates"]) == 3
    assert result["p_value"] == pytest.approx(1 / 6)  # 3 candidates: 1 of 3! orders agrees fully


def test_warm_start_copies_matching_modules_and_keeps_deeper_blocks_fresh():
    import jax
    import numpy as np
    from dsfec_jax.train.warm_start import warm_start

    trained = tiny_l(stage_blocks=(1, 2, 1, 1)).init(jax.random.key(7))
    fresh = tiny_l(stage_blocks=(1, 3, 1, 1)).init(jax.random.key(1))
    merged, how = warm_start(fresh, trained)
    assert "stage2_block1" in how["copied"] and how["fresh"] == ["stage2_block2"]
    for k in ("stem0", "stage2_block1"):
        for a, b in zip(jax.tree.leaves(merged["params"][k]), jax.tree.leaves(trained["params"][k])):
            np.testing.assert_array_equal(a, b)
    for a, b in zip(jax.tree.leaves(merged["params"]["stage2_block2"]), jax.tree.leaves(fresh["params"]["stage2_block2"])):
        np.testing.assert_array_equal(a, b)
    # a module whose shapes changed (narrower stem) is not copied
    narrow = tiny_l(stage_blocks=(1, 2, 1, 1), stem_filters=16, fec_filters=(32, 128, 16)).init(jax.random.key(1))
    assert "stem0" in warm_start(narrow, trained)[1]["fresh"]


def test_quick_depth_sweep_starts_from_the_shipped_weights(tiny_search, tmp_path, monkeypatch):
    import dataclasses
    import jax
    from dsfec_jax.core import checkpoint

    weights = tmp_path / "weights"
    monkeypatch.setattr(zoo, "WEIGHTS_DIR", weights)
    checkpoint.save(weights / f"{tiny_search}.msgpack", zoo.create(tiny_search).init(jax.random.key(3)), {})
    quick = recipes.RECIPES["dsfec"]["quick"]
    monkeypatch.setitem(recipes.RECIPES["dsfec"], "quick", dataclasses.replace(quick, warm_start=True))
    depth = trial.make_trial(tiny_search, {"label": "a", "overrides": {"stage_blocks": (1, 1, 1, 1)}}, "quick", "synthetic", 0)
    stem_axis = trial.make_trial(tiny_search, {"label": "b", "overrides": {"stem_filters": 16}}, "quick", "synthetic", 0)
    assert depth["init"].startswith(f"{tiny_search}.msgpack@") and stem_axis["init"] == "scratch"
    out = tmp_path / "warm"
    assert blocks.main(["--stage", "2", "--values", "1,2", "--base", tiny_search, "--strategy", "oneshot",
                        "--out", str(out)]) == 0
    records = Journal(out).records()
    assert [r["status"] for r in records] == ["ok", "ok"] and all(r["init"] == depth["init"] for r in records)
    assert "started from the shipped" in (out / "report.md").read_text()
    # the weights changed after the sweep was planned: the trial fails with a clear error
    checkpoint.save(weights / f"{tiny_search}.msgpack", zoo.create(tiny_search).init(jax.random.key(4)), {})
    from search.inherit import initial_variables
    with pytest.raises(ValueError, match="planned from"):
        initial_variables(depth["init"])


@pytest.mark.parametrize("base,source,kind", [("shuffle_yolov3", "street", "CameraImage"), ("yolov8n", "synthetic", "RDSample"),
                                              ("dsfec_s", "synthetic", "Frame")])
def test_a_trial_loads_its_models_samples_through_its_modality(base, source, kind):
    """search.trial.load_data asks the model's Modality record: an image model gets camera images
    (it once fell through to point frames), an RD model RD samples, a point model frames."""
    samples = trial.load_data(base, source, "val", 1)
    assert len(samples) == 1 and type(samples[0]).__name__ == kind
