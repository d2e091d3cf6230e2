"""The fleet load test (edge/loadtest.py): its database check catches a lost, an extra and an
altered batch, and a short kill test end to end (server SIGKILLed mid-load, restarted; write
tokens on, one per device) loses and duplicates nothing."""

from __future__ import annotations

import copy
import json

from dsfec_jax.edge import loadtest
from dsfec_jax.service.schema import FrameBatch
from dsfec_jax.service.store import Store


def _stored(tmp_path, batches):
    store = Store(tmp_path / "map.sqlite")
    for b in batches:
        store.put(FrameBatch.model_validate(b))
    store.close()
    return tmp_path / "map.sqlite"


def test_the_database_check_catches_lost_extra_and_altered_batches(tmp_path):
    device = loadtest.Device(0, seed=3, objects_per_frame=3)
    batches = [device.next_batch(0.1) for _ in range(6)]
    assert sum(len(b["objects"]) for b in batches) > 0
    generated = {b["batch_id"]: b for b in batches}
    db = _stored(tmp_path, batches)
    assert loadtest.check_database(db, generated)["exactly_once"]

    lost = loadtest.check_database(db, {**generated, "dev-00:9999999": batches[0] | {"batch_id": "dev-00:9999999"}})
    assert not lost["exactly_once"] and lost["missing"] == 1
    fewer = dict(list(generated.items())[1:])
    assert loadtest.check_database(db, fewer)["extra"] == 1
    altered = copy.deepcopy(generated)
    victim = next(b for b in altered.values() if b["objects"])
    victim["objects"][0]["lat"] += 1e-9
    result = loadtest.check_database(db, altered)
    assert not result["exactly_once"] and result["object_mismatches"] == 1 and result["examples"]["objects"] == [victim["batch_id"]]


def test_a_short_kill_test_loses_and_duplicates_nothing(tmp_path):
    out = tmp_path / "out"
    status = loadtest.main(["--devices", "3", "--seconds", "3", "--kill-at", "1", "--pause", "0.3", "--rate", "20",
                            "--out", str(out), "--workdir", str(tmp_path / "work")])
    record = json.loads((out / "loadtest_kill.json").read_text())
    assert status == 0 and record["checks"]["passed"] and record["checks"]["exactly_once"]
    assert record["checks"]["post_without_token_status"] == 401  # the devices posted with their tokens
    figures = record["figures"]
    assert figures["kill"]["outage_s"] >= 0.3 and figures["failed_attempts"] >= 1       # the devices saw the outage
    assert record["checks"]["batches_stored"] == record["checks"]["batches_generated"] > 40
    assert figures["uplink_counts"]["rejected"] == figures["uplink_counts"]["conflicts"] == 0
    assert record["versions"]["fastapi"] and record["command"].startswith("python -m dsfec_jax.edge.loadtest")
