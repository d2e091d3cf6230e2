"""The fleet load test (edge/loadtest.py): its database check catches a lost, an extra and an
altered batch, and a short kill test end to end (server SIGKILLed mid-load, restarted; write
tokens on, one per device) loses and duplicates nothing: on SQLite, and on PostgreSQL with two
server workers killed together."""

from __future__ import annotations

import copy
import json

import pytest

from dsfec_jax.edge import loadtest
from dsfec_jax.service.schema import FrameBatch
from dsfec_jax.service.store import open_store
from stores import STORES, db, postgres_url  # noqa: F401 (db: a pytest fixture)


def _stored(db, batches):
    store = open_store(db)
    for b in batches:
        store.put(FrameBatch.model_validate(b))
    store.close()
    return db


def test_the_database_check_catches_lost_extra_and_altered_batches(db):
    device = loadtest.Device(0, seed=3, objects_per_frame=3)
    batches = [device.next_batch(0.1) for _ in range(6)]
    assert sum(len(b["objects"]) for b in batches) > 0
    generated = {b["batch_id"]: b for b in batches}
    db = _stored(db, batches)
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
    store = open_store(db)
    with store.transaction() as tx:  # a counter that drifted from the rows
        tx.execute("UPDATE devices SET objects = objects + 1")
    store.close()
    drifted = loadtest.check_database(db, generated)
    assert not drifted["exactly_once"] and drifted["device_counter_mismatches"] == 1


@pytest.mark.parametrize("store", STORES)
def test_a_short_kill_test_loses_and_duplicates_nothing(tmp_path, store):
    out = tmp_path / "out"
    postgres = ["--db", postgres_url(), "--workers", "2"] if store == "postgres" else []
    status = loadtest.main(["--devices", "3", "--seconds", "3", "--kill-at", "1", "--pause", "0.3", "--rate", "20",
                            "--out", str(out), "--workdir", str(tmp_path / "work"), *postgres])
    record = json.loads((out / "loadtest_kill.json").read_text())
    assert record["figures"]["store"] == ("postgresql" if postgres else "sqlite")
    assert status == 0 and record["checks"]["passed"] and record["checks"]["exactly_once"]
    assert record["checks"]["post_without_token_status"] == 401  # the devices posted with their tokens
    figures = record["figures"]
    assert figures["kill"]["outage_s"] >= 0.3 and figures["failed_attempts"] >= 1       # the devices saw the outage
    assert record["checks"]["batches_stored"] == record["checks"]["batches_generated"] > 40
    assert figures["uplink_counts"]["rejected"] == figures["uplink_counts"]["conflicts"] == 0
    assert record["versions"]["fastapi"] and record["command"].startswith("python -m dsfec_jax.edge.loadtest")
