"""The one-shot NAS engine's search side: spaces as data, the paper's evolution, NSGA-II."""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

from dsfec_jax import zoo
from search.nas.evolution import Evolution, EvolutionSettings, progress_table
from search.nas.space import Choice, SearchSpace, SpaceError, from_key, key
from search.nas.spaces import get_space


def toy_space() -> SearchSpace:
    return SearchSpace("toy", "yolov8n", (Choice("a", (1, 2, 3, 4)), Choice("b", (0.5, 1.0)), Choice("c", (1, 2, 3), "categorical"),
                                          Choice("d", (1, 2, 3, 4)), Choice("e", (0.25, 0.5, 0.75, 1.0))),
                       lambda c: dict(c))


def toy_score(genes) -> dict:
    """A deterministic landscape with one best subnet (all genes at their last option but 'c' at 0)."""
    g = np.asarray(genes, float)
    return {"mAP50": float(10 * g[0] + 3 * g[1] - 4 * g[2] + 2 * g[3] + g[4]), "aux": 1.0}


def toy_costs(genes) -> dict:
    return {"params": float(sum(genes))}


class Counter:
    def __init__(self, fail_after: int | None = None):
        self.scored, self.fail_after = [], fail_after

    def __call__(self, batch):
        out = []
        for g in batch:
            if self.fail_after is not None and len(self.scored) >= self.fail_after:
                raise KeyboardInterrupt("killed")
            self.scored.append(key(g))
            out.append(toy_score(g))
        return out


def test_table1_space_size_is_the_papers():
    assert get_space("yolov8n_adapter").size() == 2 ** 20 * 3 ** 7
    assert get_space("dsfec").size() == 4 * 3 ** 4 * 3 ** 4


def test_space_operators_are_seeded_and_stay_in_range():
    s = toy_space()
    draws = [s.sample(np.random.default_rng(7)) for _ in range(2)]
    assert draws[0] == draws[1] and s.check(draws[0]) == draws[0]
    rng = np.random.default_rng(0)
    parent = s.largest()
    assert s.mutate(parent, rng, 0.0) == parent
    mutants = [s.mutate(parent, rng, 1.0) for _ in range(400)]
    for i, c in enumerate(s.choices):  # with prob 1 every gene is redrawn uniformly: every option appears
        assert {m[i] for m in mutants} == set(range(len(c.options)))
    changed = np.mean([m != p for m in (s.mutate(parent, rng, 0.1) for _ in range(2000)) for m, p in zip(m, parent)])
    assert 0.05 < changed < 0.1  # p 0.1 per gene, a redraw keeps the option 1/len(options) of the time
    a, b = s.smallest(), s.largest()
    kids = [s.crossover(a, b, rng) for _ in range(200)]
    assert all(k[i] in (a[i], b[i]) for k in kids for i in range(len(a)))
    assert len(set(kids)) > 10


def test_space_encode_decode_and_errors():
    s = toy_space()
    g = (2, 1, 0, 3, 1)
    assert s.encode(s.decode(g)) == g and from_key(key(g)) == g
    with pytest.raises(SpaceError, match="'a'"):
        s.check((4, 0, 0, 0, 0))
    with pytest.raises(SpaceError, match="expected 5 genes"):
        s.check((0, 0))
    with pytest.raises(SpaceError, match="c=7"):
        s.encode({**s.decode(g), "c": 7})
    with pytest.raises(SpaceError, match="repeat"):
        Choice("x", (1, 1))


def _params(model: str, **overrides) -> int:
    det = zoo.create(model, **overrides)
    shapes = jax.eval_shape(lambda: det.init(jax.random.key(0)))
    return int(sum(np.prod(x.shape) for x in jax.tree.leaves(shapes["params"])))


def test_table1_subnets_are_zoo_configs():
    s = get_space("yolov8n_adapter")
    assert _params(s.base, **s.overrides(s.largest())) == 3_248_056  # the largest subnet is the model itself
    small = _params(s.base, **s.overrides(s.smallest()))
    mid = _params(s.base, **s.overrides(s.sample(np.random.default_rng(3))))
    assert small < mid < 3_248_056
    d = get_space("dsfec")
    cfg = zoo.config(d.base, **d.overrides(d.largest()))
    assert cfg.stage_widths == zoo.config(d.base).stage_widths and cfg.stage_blocks == (3, 3, 3, 3)
    assert cfg.stem_filters == 32 and cfg.fec_filters[-1] == 32


def _evolution(tmp_path, scores, limits=None, **settings):
    st = EvolutionSettings(**{"population": 12, "generations": 5, "top_k": 4, **settings})
    return Evolution(toy_space(), scores, toy_costs, tmp_path, st, limits or {}, log=lambda *_: None)


def test_evolution_follows_the_rules(tmp_path):
    counter = Counter()
    state = _evolution(tmp_path, counter, limits={"params": 9.0}).run()
    gens = state["generations"]
    assert len(gens) == 5 and all(len(g["top"]) == 4 for g in gens)
    proposed = [k for g in gens for k in g["proposed"]]
    assert len(proposed) == len(set(proposed)) == len(counter.scored)  # visited subnets never come back
    assert all(sum(from_key(k)) <= 9 for k in proposed)  # constraints reject before scoring
    assert sum(len(g["rejected"]) for g in gens) > 0
    assert not set(k for g in gens for k in g["rejected"]) & set(proposed)
    bests = [g["best"] for g in gens]
    assert bests == sorted(bests)  # the top k only improves
    records = {r["key"]: r for r in map(json.loads, (tmp_path / "journal.jsonl").read_text().splitlines())}
    scored = sorted(records, key=lambda k: (-records[k]["mAP50"], k))
    assert gens[-1]["top"] == scored[:4]
    assert "| 4 |" in progress_table(state)


def test_evolution_is_seeded(tmp_path):
    a = _evolution(tmp_path / "a", Counter()).run()
    b = _evolution(tmp_path / "b", Counter()).run()
    c = _evolution(tmp_path / "c", Counter(), seed=1).run()
    assert a["generations"] == b["generations"] and a["generations"] != c["generations"]


def test_killed_evolution_resumes_to_the_same_population(tmp_path):
    whole = _evolution(tmp_path / "whole", Counter()).run()
    with pytest.raises(KeyboardInterrupt):
        _evolution(tmp_path / "cut", Counter(fail_after=30)).run()  # killed inside generation 2
    again = Counter()
    resumed = _evolution(tmp_path / "cut", again).run()
    assert resumed["generations"] == whole["generations"]
    # generations 0 and 1 (24 subnets) were journalled; the batch in flight when killed is scored again
    assert len(again.scored) == sum(len(g["proposed"]) for g in whole["generations"]) - 24


def test_evolution_refuses_another_searchs_directory(tmp_path):
    _evolution(tmp_path, Counter(), generations=1).run()
    with pytest.raises(ValueError, match="settings"):
        _evolution(tmp_path, Counter(), generations=1, top_k=3).run()


def test_nsga2_front_is_feasible_and_resumes(tmp_path):
    pytest.importorskip("optuna")
    from search.nas.nsga import pareto_front, run_nsga2

    counter = Counter()
    kwargs = dict(cost="params", limits={"params": 8.0}, population=8, metric="mAP50", seed=0, log=lambda *_: None)
    study = run_nsga2(toy_space(), counter, toy_costs, tmp_path, generations=3, **kwargs)
    front = pareto_front(study)
    assert front and all(r["costs"]["params"] <= 8 for r in front)
    assert all(sum(from_key(k)) <= 8 for k in counter.scored) and len(counter.scored) == len(set(counter.scored))
    for a in front:  # non-dominated among the front
        assert not any(b["score"] >= a["score"] and b["cost"] <= a["cost"] and b != a and
                       (b["score"] > a["score"] or b["cost"] < a["cost"]) for b in front)
    more = Counter()
    study = run_nsga2(toy_space(), more, toy_costs, tmp_path, generations=4, **kwargs)  # resume: one more generation
    assert sum(t.state.name == "COMPLETE" for t in study.trials) == 32
    assert not set(more.scored) & set(counter.scored)


def test_a_registered_subnet_is_a_zoo_config(tmp_path):
    from dsfec_jax.models.yolo_rd.variants import searched_variants
    from search.nas.register import register

    space, path = get_space("yolov8n_adapter"), tmp_path / "searched.json"
    genes = space.sample(np.random.default_rng(4))
    register(space, genes, "yolov8n_adapter_search", {"command": "python -m search.nas ...", "seed": 0}, path)
    cfg = searched_variants(path)["yolov8n_adapter_search"]
    assert cfg == zoo.config(space.base, name="yolov8n_adapter_search", notes=cfg.notes, **space.overrides(genes))
    path.write_text('{"x": {"base": "yolov8n_adapter"}}')
    with pytest.raises(ValueError, match="searched.json.*'overrides'"):
        searched_variants(path)


def test_latency_table_adds_block_changes_and_reports_its_error(tmp_path):
    from search.nas.latency import LatencyTable, build, check, one_at_a_time

    space = toy_space()
    weights = [np.linspace(0, 3, len(c.options)) for c in space.choices]
    additive = lambda subnets: [5.0 + sum(w[g] for w, g in zip(weights, s)) for s in subnets]  # noqa: E731
    assert len(one_at_a_time(space)) == 1 + sum(len(c.options) - 1 for c in space.choices)
    table = build(space, additive)
    genes = space.sample(np.random.default_rng(0))
    assert table.predict(genes) == pytest.approx(additive([genes])[0])  # exact on an additive latency
    assert check(table, space, additive, count=5)["max_abs_error_pct"] < 1e-9
    interacting = lambda subnets: [5.0 + 0.5 * s[0] * s[1] + s[3] for s in subnets]  # noqa: E731
    report = check(build(space, interacting), space, interacting, count=8)
    assert report["max_abs_error_pct"] > 1 and len(report["rows"]) >= 5  # the interaction shows as error
    table.save(tmp_path / "t.json")
    assert LatencyTable.load(tmp_path / "t.json", space).predict(genes) == table.predict(genes)
    with pytest.raises(ValueError, match="not of 'yolov8n_adapter'"):
        LatencyTable.load(tmp_path / "t.json", get_space("yolov8n_adapter"))


def test_a_fitted_latency_table_absorbs_a_fixed_cost():
    from search.nas.latency import build, check

    space = toy_space()
    # a fixed cost the widths cannot remove: latency = max(floor, additive)
    floored = lambda subnets: [max(6.0, 2.0 + 1.5 * s[0] + s[3] + s[4]) for s in subnets]  # noqa: E731
    plain = check(build(space, floored), space, floored, count=12, seed=5)
    fitted = check(build(space, floored, fit=60), space, floored, count=12, seed=5)
    assert fitted["mean_abs_error_pct"] < plain["mean_abs_error_pct"]


def test_standalone_choice_takes_the_top_and_a_spread_and_the_study_pairs_them():
    from search.nas.standalone import choose, markdown, ranking_study

    records = [{"key": f"k{i:02d}", "status": "ok", "mAP50": float(20 - i)} for i in range(20)]
    records.append({"key": "bad", "status": "failed"})
    chosen = choose(records, "mAP50", 3, 3)
    assert [r["key"] for r in chosen] == ["k00", "k01", "k02", "k03", "k11", "k19"]  # top 3, then rest's ends and middle
    assert [r["key"] for r in choose(records, "mAP50", 2, 0)] == ["k00", "k01"]
    # over the constraint's range: params 1.0 ... 2.9 M in an order unrelated to the score
    for i, r in enumerate(records[:-1]):
        r["costs"] = {"params": 1e6 + ((i * 7) % 20) * 1e5}
    by_params = choose(records, "mAP50", 3, 3, "params")[3:]
    rest_params = [r["costs"]["params"] for r in records[3:-1]]
    assert [r["costs"]["params"] for r in by_params] == [min(rest_params), 2.0e6, max(rest_params)]
    with pytest.raises(ValueError, match="--spread-by 'gflops'"):
        choose(records, "mAP50", 3, 3, "gflops")
    # stand-alone scores: the inherited order reversed except one swap -> tau strongly negative
    alone = {"k00": 1.0, "k01": 2.0, "k02": 3.0, "k03": 4.0, "k11": 6.0, "k19": 5.0}
    trained = [{"label": k, "status": "ok", "metrics": {"mAP50": v}, "costs": {"params": 1e6}, "wall_s": 100.0}
               for k, v in alone.items()]
    study = ranking_study(chosen, trained, "mAP50", oneshot_s=600.0, scored=60)
    assert study["cost"] == {"standalone_s_per_subnet": 100.0, "oneshot_s_per_subnet": 10.0, "ratio": 10.0}
    assert study["n"] == 6 and study["best_standalone"] == "k11" and study["best_inherited"] == "k00"
    assert study["tau"] == pytest.approx(-13 / 15, abs=1e-4)  # rounded to 4 places; 15 pairs: 1 concordant, 14 discordant
    assert study["p_value"] == pytest.approx(1.0, abs=0.01)  # one-sided: no evidence of agreement
    assert "Kendall tau between inherited and stand-alone mAP50 over 6 subnets: -0.87" in markdown(study)
    assert "100 s per subnet stand-alone against 10 s one-shot" in markdown(study)
    assert "too few" in markdown(ranking_study(chosen[:1], trained, "mAP50"))


def test_a_checked_table_is_scored_on_subnets_its_fit_never_saw():
    from search.nas.latency import build_checked

    space = toy_space()
    seen = []

    def interacting(subnets):
        seen.append(list(subnets))
        return [5.0 + 0.5 * s[0] * s[1] + s[3] for s in subnets]

    table = build_checked(space, interacting, {"runtime": "toy"}, fit=20, count=6)
    assert len(seen) == 1  # one interleaved run
    held_out = [r["subnet"] for r in table.setup["check"]["rows"]]
    assert held_out and table.setup["fitted_on"] + len(held_out) == len(seen[0])
    assert table.setup["check"]["max_abs_error_pct"] > 0 and table.setup["runtime"] == "toy"


def test_each_space_names_its_engine_and_export_form():
    """The run, the Ray actors, the remedies and the ONNX latency table ask the space's engine
    (search.nas.engines) what differs between RD and point spaces, never the modality's name."""
    from search.nas.engines import RD_ENGINE, engine_for, point_engine, rd_engine

    rd, points = get_space("yolov8n_adapter"), get_space("dsfec")
    assert engine_for(rd) is rd_engine and engine_for(points) is point_engine
    det = zoo.create("dsfec_s")
    grouped, matmul = points.engine.onnx_form(det)
    assert (grouped.config.depthwise_impl, grouped.config.kernels, matmul) == ("grouped", "plain", False)
    assert RD_ENGINE.onnx_form(det) == (det, True)
    bare = SearchSpace("toy", "dsfec_s", (Choice("a", (1, 2)),), lambda c: {})
    with pytest.raises(ValueError, match="'toy' names no NAS engine"):
        engine_for(bare)


def test_remedies_rescore_only_the_rd_engines_runs(tmp_path):
    from search.nas import remedies

    (tmp_path / "ranking.json").write_text("{}")
    with pytest.raises(SystemExit, match="re-score RD runs only \\(dsfec is not\\)"):
        remedies.main([str(tmp_path), "--space", "dsfec"])
