"""Split-half seed agreement under a search table: the splits, the statistic, the report line."""

import math

import numpy as np
import pytest

from search import report, seed_agreement


def rec(label, seed, value, status="ok"):
    return {"key": f"{label}-{seed}", "base": "dsfec_l", "label": label, "seed": seed, "status": status,
            "metrics": {"car_mAP": value, "car_AP4": 0.0, "mAP": 0.0},
            "costs": {"params": 1e6, "gflops": 1.0, "memory_mb": 1.0, "latency_ms": 1.0}}


@pytest.mark.parametrize("seeds, k, count", [(2, 1, 1), (4, 1, 6), (4, 2, 3), (6, 1, 15), (6, 2, 45), (6, 3, 10)])
def test_every_unordered_pair_of_disjoint_groups_once(seeds, k, count):
    pairs = seed_agreement.splits(seeds, k)
    assert len(pairs) == count == math.comb(seeds, k) * math.comb(seeds - k, k) // 2
    assert all(len(a) == len(b) == k and not set(a) & set(b) for a, b in pairs)
    assert len({frozenset((a, b)) for a, b in pairs}) == count


def test_many_splits_are_sampled_with_a_fixed_seed(monkeypatch):
    monkeypatch.setattr(seed_agreement, "MAX_SPLITS", 7)
    assert seed_agreement.splits(6, 2) == seed_agreement.splits(6, 2) and len(seed_agreement.splits(6, 2)) == 7


def test_seeds_that_agree_give_tau_one_and_seeds_that_reverse_give_minus_one():
    steady = np.array([[3.0, 3.1, 2.9, 3.0], [2.0, 2.1, 1.9, 2.0], [1.0, 1.1, 0.9, 1.0]])
    out = seed_agreement.split_half(steady, 2)
    assert out == {"k": 2, "splits": 3, "tau_mean": 1.0, "tau_min": 1.0, "tau_max": 1.0, "same_top": 1.0}
    flipped = np.array([[3.0, 1.0], [2.0, 2.0], [1.0, 3.0]])
    out = seed_agreement.split_half(flipped, 1)
    assert out["tau_mean"] == -1.0 and out["same_top"] == 0.0


def test_averaging_seeds_steadies_a_noisy_ranking():
    """Candidates 0.5 apart, seed noise sd 1: one seed ranks them poorly, the mean of four better."""
    rng = np.random.default_rng(0)
    values = np.arange(6)[:, None] * 0.5 + rng.standard_normal((6, 8))
    one, four = seed_agreement.split_half(values, 1), seed_agreement.split_half(values, 4)
    assert four["tau_mean"] > one["tau_mean"] + 0.2


def test_only_seeds_every_candidate_finished_count():
    records = [rec("a", 0, 3.0), rec("a", 1, 2.0), rec("a", 2, 1.0),
               rec("b", 0, 2.0), rec("b", 1, 3.0), rec("b", 2, 0.0, status="failed"),
               rec("c", 0, 1.0), rec("c", 1, 1.0), rec("c", 2, 2.0)]
    labels, seeds, values = seed_agreement.seed_scores(records, "car_mAP")
    assert labels == ["a", "b", "c"] and seeds == [0, 1] and values.tolist() == [[3, 2], [2, 3], [1, 1]]
    out = seed_agreement.agreement(records, "car_mAP")
    assert out["seeds"] == [0, 1] and [r["k"] for r in out["by_k"]] == [1]
    assert seed_agreement.agreement([r for r in records if r["seed"] == 0], "car_mAP") is None  # one seed
    assert seed_agreement.agreement([r for r in records if r["label"] != "c"], "car_mAP") is None  # two candidates


def test_report_prints_and_saves_the_agreement_with_two_seeds_or_more(tmp_path):
    from search.journal import Journal

    for seed in range(4):
        for label, value in (("a", 3.0), ("b", 2.0), ("c", 1.0)):
            Journal(tmp_path).append(rec(label, seed, value + 0.01 * seed))
    (tmp_path / "search.json").write_text('{"base_label": "a", "title": "t"}')
    out = report.write_reports(tmp_path)
    md = (tmp_path / "report.md").read_text()
    assert "Seed agreement (Car mAP; seeds 0, 1, 2, 3 split into two disjoint groups" in md
    assert "1 vs 1 seed: tau 1.00 (1.00 to 1.00 over 6 splits), same top candidate in 100 %" in md
    assert "2 vs 2 seeds: tau 1.00" in md and "seed_agreement.json" in out["files"]
    assert "How well this 4-seed table itself would reproduce takes 8 seeds to measure" in md
    assert out["seed_agreement"]["by_k"][1]["splits"] == 3
    # one seed: no line, and a stale file from an earlier report goes
    single = tmp_path / "single"
    for label, value in (("a", 3.0), ("b", 2.0), ("c", 1.0)):
        Journal(single).append(rec(label, 0, value))
    (tmp_path / "seed_agreement.json").rename(single / "seed_agreement.json")
    out = report.write_reports(single)
    assert out["seed_agreement"] is None and not (single / "seed_agreement.json").exists()
    assert "Seed agreement" not in (single / "report.md").read_text()


def test_a_one_shot_search_defaults_to_its_profiles_seeds():
    from search import blocks, cli, recipes

    quick = recipes.get_recipe("quick", "dsfec_l")
    assert quick.oneshot_seeds == 3  # the main job: three supernets (README, "What the quick stage-2 sweep measures")
    assert cli.seed_count(None, "oneshot", quick) == 3 and cli.seed_count(None, "train", quick) == 1
    assert cli.seed_count(2, "oneshot", quick) == 2
    assert cli.seed_count(None, "oneshot", recipes.get_recipe("smoke", "dsfec_l")) == 1
    with pytest.raises(SystemExit, match="--seeds 0: expected a seed count >= 1"):
        blocks.main(["--stage", "2", "--seeds", "0"])
