"""Self-supervised depth training: batches as a pure function of (seed, step), a few steps lower
the loss, runs repeat exactly, and a resumed run continues as if never stopped."""

import dataclasses
import json

import jax
import numpy as np
import pytest
from builders import assert_rows_are_the_batch_rows

from dsfec_jax.data.camera.street import StreetConfig
from dsfec_jax.models.depth import TINY
from dsfec_jax.modalities.image.depth import load_depth_predictor
from dsfec_jax.modalities.image.ship_depth import ship_depth_weights
from dsfec_jax.modalities.image.fit_depth import DepthAugment, DepthBatchStream, fit_depth, read_losses, render_pairs

STREET = StreetConfig(width=64)  # 64 x 36 frames, area-resized to the tiny net's 64 x 32
MEASURE = dict(frames=2, street_config=STREET)  # a shipped file's measured figures, on 2 tiny test frames
SETUP = dict(config=TINY, frames=6, steps=30, batch_size=2, seed=0, street_config=STREET, progress=False,
             learning_rate=1e-3, log_every=1, ckpt_every=10)


@pytest.fixture(scope="module")
def pairs():
    return render_pairs(STREET, 6, TINY)


def test_pairs_are_rectified_stereo(pairs):
    left, right = pairs
    assert left.shape == right.shape == (6, 32, 64, 3) and left.dtype == np.uint8
    assert np.abs(left.astype(int) - right).mean() > 1  # two different views


def test_batches_are_a_pure_function_of_seed_and_step(pairs):
    stream = DepthBatchStream(*pairs, batch_size=2, seed=0)
    a, b = stream.batch(7), DepthBatchStream(*pairs, batch_size=2, seed=0).batch(7)
    jax.tree.map(np.testing.assert_array_equal, a, b)
    assert not np.array_equal(a["inputs"]["left"], stream.batch(8)["inputs"]["left"])
    assert not np.array_equal(a["inputs"]["left"], DepthBatchStream(*pairs, 2, seed=1).batch(7)["inputs"]["left"])
    epoch = np.concatenate([stream.indices(s) for s in range(3)])
    assert sorted(epoch) == list(range(6))  # each frame once per epoch


def test_a_slice_of_rows_is_those_rows_of_the_batch(pairs):
    assert_rows_are_the_batch_rows(DepthBatchStream(*pairs, batch_size=2, seed=0), 7, slice(1, 2))


def test_flip_mirrors_and_swaps_the_pair(pairs):
    flip = DepthBatchStream(*pairs, batch_size=2, seed=0, augment=DepthAugment(flip_prob=1.0, augment_prob=0.0))
    batch, index = flip.batch(0), flip.indices(0)[0]
    np.testing.assert_array_equal(batch["inputs"]["left"][0], pairs[1][index][:, ::-1] / np.float32(255))
    np.testing.assert_array_equal(batch["inputs"]["right"][0], pairs[0][index][:, ::-1] / np.float32(255))
    shift = DepthBatchStream(*pairs, batch_size=2, seed=0, augment=DepthAugment(flip_prob=0.0, augment_prob=1.0))
    images = shift.batch(0)["inputs"]["left"]
    assert images.min() >= 0 and images.max() <= 1
    assert not np.allclose(images[0], pairs[0][shift.indices(0)[0]] / 255)


def test_training_lowers_the_loss_repeats_and_resumes_exactly(tmp_path):
    _, info = fit_depth(tmp_path / "a", **SETUP, command="dsfec depth train a")
    losses = [r["loss"] for r in info["losses"]]
    assert len(losses) == 30 and np.mean(losses[-5:]) < 0.9 * np.mean(losses[:5])
    assert info["weights"] and load_depth_predictor(info["weights"]).config == TINY

    _, part = fit_depth(tmp_path / "c", **SETUP, stop_at=10)  # a second run repeats the first's losses
    assert part["step"] == 10 and part["weights"] is None and [r["loss"] for r in part["losses"]] == losses[:10]
    variables, resumed = fit_depth(tmp_path / "c", **SETUP)  # and resumed, goes on as if never stopped
    assert [r["loss"] for r in read_losses(tmp_path / "c")] == losses
    assert json.loads((tmp_path / "c" / "run.json").read_text())["resumes"][0]["from_step"] == 10
    final = load_depth_predictor(info["weights"]).variables
    jax.tree.map(np.testing.assert_array_equal, variables, final)

    # --init: a new run starts from trained weights (recorded by hash), of the same config only
    start, _ = fit_depth(tmp_path / "d", **SETUP, init=info["weights"], stop_at=0, command="dsfec depth train d")
    jax.tree.map(np.testing.assert_array_equal, start, final)
    record = json.loads((tmp_path / "d" / "run.json").read_text())["init"]
    assert record["path"] == info["weights"] and record["step"] == 30 and len(record["sha256"]) == 64
    # or from a training checkpoint (an Orbax step directory, or checkpoints/last for its newest): path and step
    start, _ = fit_depth(tmp_path / "g", **SETUP, init=tmp_path / "c" / "checkpoints" / "last", stop_at=0)
    jax.tree.map(np.testing.assert_array_equal, start, final)
    assert json.loads((tmp_path / "g" / "run.json").read_text())["init"] == {
        "path": str(tmp_path / "c" / "checkpoints" / "last" / "step_0000030"), "sha256": None, "step": 30}
    with pytest.raises(ValueError, match="same --input"):
        fit_depth(tmp_path / "e", **{**SETUP, "config": dataclasses.replace(TINY, width=96)}, init=info["weights"])

    # dsfec depth ship: the weights with the detectors' manifest rules: the run's record (command, seed,
    # config, versions) with the commands of the runs it continued, and the measured figures
    fit_depth(tmp_path / "d", **SETUP, init=info["weights"], command="dsfec depth train d")
    manifest = ship_depth_weights(tmp_path / "d", tmp_path / "shipped.msgpack", "dsfec depth ship d", **MEASURE)
    training = manifest["training"]
    assert manifest["model"] == "monodepth_tiny" and manifest["step"] == 30 and manifest["ship_command"] == "dsfec depth ship d"
    assert training["command"] == "dsfec depth train d" and training["seed"] == 0 and manifest["versions"]["jax"]
    assert [(r["command"], r["step"]) for r in training["init_chain"]] == [("dsfec depth train a", 30)]
    measured = manifest["measured"]["test"]
    assert measured["frames"] == 2 and measured["images"] == 2 and np.isfinite([measured["abs_rel"], measured["rmse"]]).all()
    assert load_depth_predictor(tmp_path / "shipped.msgpack").config == TINY
    # a run continued from shipped weights (no run directory beside them): their manifest's command
    fit_depth(tmp_path / "f", **SETUP, init=tmp_path / "shipped.msgpack", command="dsfec depth train f")
    chain = ship_depth_weights(tmp_path / "f", tmp_path / "again.msgpack", "dsfec depth ship f", **MEASURE)["training"]["init_chain"]
    assert [(r["command"], r["step"]) for r in chain] == [("dsfec depth train d", 30)]
    assert [r["command"] for r in chain[0]["init_chain"]] == ["dsfec depth train a"]
    with pytest.raises(ValueError, match="finished"):
        ship_depth_weights(tmp_path / "e", tmp_path / "none.msgpack", "")


def test_depth_eval_command_shows_its_progress_and_prints_the_metrics(capsys):
    """`dsfec depth eval` compiles the network on its first frame: a bar on stderr says how far
    it is (issue 51: never silent), stdout stays the metrics' JSON."""
    from dsfec_jax import cli

    assert cli.main(["depth", "eval", "--frames", "2", "--json"]) == 0
    printed = capsys.readouterr()
    assert json.loads(printed.out)["images"] == 2
    assert "depth eval (street test frames)" in printed.err and "2/2" in printed.err
