"""search.rescore: a finished RD trial without match tables gains them from its final weights (nothing
trains), equal to the tables the trial would have recorded; a trial whose weights no longer give the
recorded headline is refused."""

import pytest

from search import rescore as rescore_cmd
from search import trial
from search.journal import Journal
from search.recipes import get_recipe


@pytest.fixture(scope="module")
def finished_rd_trial(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("rd_search")
    spec = trial.make_trial("yolov8n", {"label": "yolov8n", "overrides": {}}, "smoke",
                            get_recipe("smoke", "yolov8n").data, 0)
    record = trial.run_trial(spec, run_dir)
    assert record["status"] == "ok", record.get("traceback")
    Journal(run_dir).append(record)
    return run_dir, record


def test_rd_trials_keep_every_class_and_rescore_restores_them(finished_rd_trial):
    run_dir, record = finished_rd_trial
    classes = set(record["matches"])
    assert len(classes) == 6  # the six RADDet classes: the RD statistic averages every class
    Journal(run_dir).update({k: v for k, v in record.items() if k != "matches"})
    steps_before = (run_dir / "trials" / record["key"] / "metrics.jsonl").read_text()
    assert rescore_cmd.main([str(run_dir)]) == 0
    back = Journal(run_dir).records()[0]
    assert back["matches"] == record["matches"]  # the same weights and frames: the same tables, bit for bit
    assert (run_dir / "trials" / record["key"] / "metrics.jsonl").read_text().count('"loss"') == \
        steps_before.count('"loss"')  # nothing trained
    assert rescore_cmd.pending(Journal(run_dir).records(), None) == []


def test_a_changed_headline_is_refused(finished_rd_trial):
    run_dir, record = finished_rd_trial
    changed = {**{k: v for k, v in record.items() if k != "matches"},
               "metrics": {**record["metrics"], "mAP50": record["metrics"]["mAP50"] + 1.0}}
    with pytest.raises(ValueError, match="not adding match tables that describe other weights"):
        trial.rescore(changed, run_dir)
    with pytest.raises(ValueError, match="keeps no weights of its own"):
        trial.rescore({**changed, "strategy": "oneshot"}, run_dir)


def test_held_out_scores_the_final_weights_as_the_trial_did_and_keeps_them(finished_rd_trial):
    """On the trial's own validation samples the held-out scorer gives the recorded headline and match
    tables bit for bit (the same weights, the weight average included); on other samples it writes its
    answer once and reads it back."""
    run_dir, record = finished_rd_trial
    recipe = get_recipe(record["recipe"], record["base"])
    again = trial.held_out(record, run_dir, "val", recipe.val_frames)
    assert again["metrics"]["mAP50"] == record["metrics"]["mAP50"] and again["matches"] == record["matches"]
    test = trial.held_out(record, run_dir, "test", 3)
    cached = run_dir / "held_out" / f"{record['key']}-test-3.json"
    assert cached.is_file() and trial.held_out(record, run_dir, "test", 3) == test
    assert test["metrics"]["samples"] == 3 and set(test["matches"]) == set(record["matches"])
    with pytest.raises(ValueError, match="no finished weights"):
        trial.held_out({**record, "status": "failed", "key": "0" * 12}, run_dir, "test", 3)
