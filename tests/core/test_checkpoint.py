"""Weights/manifest pairs written as one unit, and atomic writes that survive a power loss."""

import json
import os
from types import SimpleNamespace

import numpy as np
import pytest

from dsfec_jax.core import atomic, checkpoint
from dsfec_jax import zoo


def tree(value: float) -> dict:
    return {"params": {"w": np.full((2, 3), value, np.float32)}, "batch_stats": {}}


def killed_before_the_manifest(monkeypatch):
    """Make the next save die between its two writes (the msgpack lands, its manifest does not)."""
    def die(path, obj):
        raise KeyboardInterrupt(f"killed while writing {path}")
    monkeypatch.setattr(atomic, "write_json", die)


def test_save_records_the_checksum_and_load_checks_it(tmp_path):
    path = tmp_path / "w.msgpack"
    checkpoint.save(path, tree(1.0), {"step": 3})
    manifest = checkpoint.read_manifest(path)
    assert manifest["step"] == 3 and manifest["bytes"] == path.stat().st_size and len(manifest["sha256"]) == 64
    np.testing.assert_array_equal(checkpoint.load(path)["params"]["w"], tree(1.0)["params"]["w"])
    data = bytearray(path.read_bytes())
    data[-1] ^= 1  # same size, one bit changed
    path.write_bytes(bytes(data))
    with pytest.raises(checkpoint.CheckpointError, match="w.msgpack: does not match its manifest w.msgpack.json"):
        checkpoint.load(path)


def test_a_kill_between_weights_and_manifest_is_detected(tmp_path, monkeypatch):
    """Overwriting a pair (best.msgpack) and dying before the manifest: new weights, old manifest.
    A new pair killed the same way has no manifest. Neither may load as if it were whole."""
    best, fresh = tmp_path / "best.msgpack", tmp_path / "step_0000002.msgpack"
    checkpoint.save(best, tree(1.0), {"car_mAP": 10.0})
    with monkeypatch.context() as m:
        killed_before_the_manifest(m)
        for path in (best, fresh):
            with pytest.raises(KeyboardInterrupt):
                checkpoint.save(path, tree(2.0), {"car_mAP": 20.0})
    assert checkpoint.read_manifest(best)["car_mAP"] == 10.0  # describes the weights no longer there
    with pytest.raises(checkpoint.CheckpointError, match="best.msgpack: does not match its manifest"):
        checkpoint.load(best)
    with pytest.raises(checkpoint.CheckpointError, match="step_0000002.msgpack.json: manifest missing"):
        checkpoint.load(fresh)
    assert "killed while saving" in checkpoint.problem(fresh)


def test_legacy_manifests_without_a_checksum_still_load(tmp_path):
    path = tmp_path / "old.msgpack"
    checkpoint.save(path, tree(1.0), {"step": 1})
    manifest = checkpoint.read_manifest(path)
    del manifest["sha256"], manifest["bytes"]
    checkpoint.manifest_path(path).write_text(json.dumps(manifest))
    assert checkpoint.problem(path) is None
    with pytest.raises(ValueError, match="has shape"):  # shape checks remain
        checkpoint.load(path, {"params": {"w": np.zeros((3, 3), np.float32)}, "batch_stats": {}})


def test_shipped_weights_carry_a_matching_checksum():
    shipped = sorted(zoo.WEIGHTS_DIR.glob("*.msgpack"))
    assert shipped
    for path in shipped:
        assert "sha256" in checkpoint.read_manifest(path), path
        assert checkpoint.problem(path) is None, path


def test_a_half_written_supernet_is_trained_again(tmp_path, monkeypatch):
    """A one-shot search killed while saving its supernet must not fail every candidate after.
    What is saved and read back is under test, not the network: stand-ins for it and its step."""
    from dsfec_jax.train.schedules import get_schedule
    from search import oneshot

    state = {"params": {"w": np.ones((2, 2), np.float32)}, "batch_stats": {}, "opt_state": {}, "step": np.int32(0)}
    monkeypatch.setattr(oneshot, "init_state", lambda *a: state)
    monkeypatch.setattr(oneshot, "supernet_step", lambda *a: lambda s, batch, depth: (s, 0.0))
    from dsfec_jax import zoo

    supernet = SimpleNamespace(config=zoo.config("dsfec_s", stage_blocks=(1, 1, 1, 1)))
    stream = SimpleNamespace(batch=lambda step: {"inputs": None, "targets": None})
    recipe = SimpleNamespace(schedule=get_schedule("quick", steps=1, batch_size=2, warmup_steps=1))
    path = tmp_path / "supernet_x.msgpack"

    def supernet_state(log):
        return oneshot._supernet(supernet, stream, [np.ones(4, np.int32)], recipe, 1, 0, path, log)

    with monkeypatch.context() as m:
        killed_before_the_manifest(m)
        with pytest.raises(KeyboardInterrupt):
            supernet_state(print)
    assert path.is_file() and not checkpoint.manifest_path(path).exists()
    lines = []
    supernet_state(lines.append)
    assert any("manifest missing" in l and "training the supernet again" in l for l in lines), lines
    assert checkpoint.problem(path) is None
    lines.clear()
    supernet_state(lines.append)
    assert any(l.startswith("supernet from") for l in lines), lines


def test_atomic_write_syncs_the_directory_after_the_rename(tmp_path, monkeypatch):
    """The rename is an entry in the directory: without fsyncing the directory a power loss can
    undo it. Record what each fsync and replace touched, in order."""
    events = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd):
        events.append(("fsync", os.path.realpath(f"/proc/self/fd/{fd}")))
        real_fsync(fd)

    def replace(src, dst):
        events.append(("replace", os.path.realpath(dst)))
        real_replace(src, dst)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)
    target = tmp_path / "sub" / "out.json"
    atomic.write_json(target, {"a": 1})
    assert json.loads(target.read_text()) == {"a": 1}
    kinds = [kind for kind, _ in events]
    assert kinds == ["fsync", "replace", "fsync"], events
    assert events[0][1].endswith(".tmp") and events[1][1] == str(target.resolve())
    assert events[2][1] == str(target.parent.resolve())  # the directory, after the rename
