"""RD training batches: a pure function of (seed, step), fixed-size padded targets, boxes that
follow the augmentation, class indices, and the evaluation inputs' way back to map pixels."""

import jax
import numpy as np
import pytest
from builders import assert_rows_are_the_batch_rows

from dsfec_jax.boxes.boxes2d import Boxes2D
from dsfec_jax.data.prefetch import Prefetcher
from dsfec_jax.data.rd.augment import RDAugment, flip_doppler
from dsfec_jax.data.rd.batches import RDBatchStream, boxes_to_map, rd_eval_inputs
from dsfec_jax.data.rd.representations import RDRepresentation, representations
from dsfec_jax.data.rd.sample import RDAxes, RDSample
from dsfec_jax.data.rd.sensor import FMCWSensor
from dsfec_jax.data.rd.synthetic import RDSyntheticConfig, RDSyntheticDataset

SENSOR = FMCWSensor(num_samples=64, num_chirps=16)   # 64 range rows x 16 Doppler columns
SYNTHETIC = RDSyntheticDataset(RDSyntheticConfig(sensor=SENSOR), "train", seed=3, num_samples=8)
WITH_NOISE = RDAugment(doppler_flip=0.5, noise_rise_db=3.0)


def hand_made(rows, names, seed=0):
    power = np.random.default_rng(seed).gamma(8, 1.0, (64, 16)).astype(np.float32)
    boxes = Boxes2D(np.asarray(rows, np.float32).reshape(-1, 4), np.array(names, "<U16"))
    return RDSample(power, RDAxes.of_sensor(SENSOR), boxes, SENSOR, sample_id=f"hand-{seed}")


def assert_batches_equal(a, b):
    jax.tree.map(np.testing.assert_array_equal, a, b)


def test_a_batch_is_a_pure_function_of_seed_and_step():
    a = RDBatchStream(SYNTHETIC, 2, seed=5, augment=WITH_NOISE, max_boxes=16)
    b = RDBatchStream(SYNTHETIC, 2, seed=5, augment=WITH_NOISE, max_boxes=16)
    assert_batches_equal(a.batch(3), b.batch(3))
    assert not np.array_equal(a.batch(3)["inputs"]["heat"], a.batch(4)["inputs"]["heat"])
    other_seed = RDBatchStream(SYNTHETIC, 2, seed=6, augment=WITH_NOISE, max_boxes=16)
    assert not np.array_equal(a.batch(3)["inputs"]["gray"], other_seed.batch(3)["inputs"]["gray"])


def test_a_stream_made_at_step_s_gives_the_uninterrupted_step_s_batch():
    running = RDBatchStream(SYNTHETIC, 3, seed=1, augment=WITH_NOISE, max_boxes=16)
    uninterrupted = [running.batch(s) for s in range(6)]          # crosses epochs (2 batches each)
    resumed = RDBatchStream(SYNTHETIC, 3, seed=1, augment=WITH_NOISE, max_boxes=16)
    for s in (5, 2):
        assert_batches_equal(resumed.batch(s), uninterrupted[s])


def test_a_slice_of_rows_is_those_rows_of_the_batch():
    assert_rows_are_the_batch_rows(RDBatchStream(SYNTHETIC, 3, seed=1, augment=WITH_NOISE, max_boxes=16), 4, slice(1, 3))


def test_an_epoch_visits_distinct_samples_and_epochs_reshuffle():
    stream = RDBatchStream(SYNTHETIC, 2, seed=0, augment=None)
    epoch0 = np.concatenate([stream.indices(s) for s in range(4)])
    epoch1 = np.concatenate([stream.indices(s) for s in range(4, 8)])
    assert sorted(epoch0.tolist()) == sorted(epoch1.tolist()) == list(range(8))
    assert not np.array_equal(epoch0, epoch1)


def test_shapes_dtypes_and_padding_mask():
    samples = [hand_made([[1, 2, 5, 9], [3, 30, 7, 40]], ["car", "person"], 0),
               hand_made([[0, 10, 16, 20]], ["truck"], 1)]
    stream = RDBatchStream(samples, 2, seed=0, augment=None, max_boxes=5)
    arrays = stream.arrays(0)
    assert arrays["heat"].shape == (2, 64, 32, 3) and arrays["heat"].dtype == np.float32   # 16 cols pad to 32
    assert arrays["gray"].shape == (2, 64, 32, 1) and arrays["gray"].dtype == np.float32
    assert arrays["gt_boxes"].shape == (2, 5, 4) and arrays["gt_boxes"].dtype == np.float32
    assert arrays["gt_labels"].dtype == np.int32 and arrays["gt_mask"].dtype == bool
    for b, i in enumerate(stream.indices(0)):
        k = len(samples[i].boxes)
        assert arrays["gt_mask"][b].tolist() == [True] * k + [False] * (5 - k)
        np.testing.assert_array_equal(arrays["gt_boxes"][b, :k], samples[i].boxes.xyxy)
        assert not arrays["gt_boxes"][b, k:].any() and not arrays["gt_labels"][b, k:].any()


def test_labels_are_indices_into_the_classes():
    sample = hand_made([[0, 0, 1, 1], [1, 1, 2, 2], [2, 2, 3, 3]], ["truck", "person", "car"])
    assert rd_eval_inputs(sample)["gt_labels"][0, :3].tolist() == [5, 0, 2]     # RD_CLASSES order
    assert rd_eval_inputs(sample, classes=("car", "truck", "person"))["gt_labels"][0, :3].tolist() == [1, 2, 0]
    with pytest.raises(ValueError, match="bus"):
        rd_eval_inputs(hand_made([[0, 0, 1, 1]], ["bus"]), classes=("car",))


def test_an_empty_frame_has_an_all_false_mask():
    stream = RDBatchStream([hand_made([], [], 0), hand_made([], [], 1)], 2, seed=0, max_boxes=4)
    batch = stream.batch(0)
    assert batch["targets"]["gt_mask"].shape == (2, 4) and not batch["targets"]["gt_mask"].any()
    assert not batch["targets"]["gt_boxes"].any() and batch["stats"]["boxes"] == 0


def test_boxes_and_maps_follow_a_doppler_flip():
    # the first box touches Doppler column 0, which is its own mirror: the flip splits it in two
    sample = hand_made([[0, 4, 3, 6], [11, 10, 12, 11]], ["car", "person"])
    flipped = RDBatchStream([sample], 1, seed=0, augment=RDAugment(doppler_flip=1.0)).arrays(0)
    plain = RDBatchStream([sample], 1, seed=0, augment=None).arrays(0)
    want = flip_doppler(sample)
    assert flipped["gt_mask"][0].sum() == 3 and plain["gt_mask"][0].sum() == 2
    np.testing.assert_array_equal(flipped["gt_boxes"][0, :3], want.boxes.xyxy)
    assert flipped["gt_labels"][0, :3].tolist() == [2, 2, 0]
    np.testing.assert_array_equal(flipped["heat"][0], representations(want)["heat"])
    assert not np.array_equal(flipped["heat"], plain["heat"])


def test_a_crowded_frame_keeps_its_largest_boxes_in_order():
    rows = [[0, 0, 1, 1], [0, 0, 4, 4], [0, 0, 2, 2], [0, 0, 3, 3], [0, 0, 1, 2]]
    sample = hand_made(rows, ["car", "truck", "bus", "person", "bicycle"])
    batch = RDBatchStream([sample], 1, seed=0, augment=None, max_boxes=3).batch(0)
    np.testing.assert_array_equal(batch["targets"]["gt_boxes"][0], [rows[1], rows[2], rows[3]])
    assert batch["targets"]["gt_labels"][0].tolist() == [5, 4, 0] and batch["stats"]["dropped_boxes"] == 2


def test_resize_scales_boxes_and_eval_inputs_map_them_back():
    sample = hand_made([[2, 8, 6, 20], [10, 40, 16, 64]], ["car", "person"])
    rep = RDRepresentation(fit="resize", input_hw=(128, 32))
    inputs = rd_eval_inputs(sample, rep, max_boxes=4)
    assert inputs["heat"].shape == (1, 128, 32, 3) and inputs["gray"].shape == (1, 128, 32, 1)
    np.testing.assert_array_equal(inputs["gt_boxes"][0, :2], sample.boxes.xyxy * 2)
    np.testing.assert_array_equal(inputs["to_map_scale"], [[0.5, 0.5, 0.5, 0.5]])
    np.testing.assert_array_equal(boxes_to_map(inputs["gt_boxes"][0, :2], inputs["to_map_scale"], inputs["map_hw"]),
                                  sample.boxes.xyxy)
    padded = rd_eval_inputs(sample)                                  # fit='pad': 64 x 16 -> 64 x 32
    np.testing.assert_array_equal(padded["to_map_scale"], [[1, 1, 1, 1]])
    assert padded["map_hw"].tolist() == [[64, 16]]
    # a prediction reaching into the zero padding is clipped to the map
    np.testing.assert_array_equal(boxes_to_map([[12, 50, 30, 70]], padded["to_map_scale"], padded["map_hw"]),
                                  [[12, 50, 16, 64]])


def test_samples_of_different_fitted_sizes_are_refused():
    small = RDSample(np.ones((32, 16), np.float32), RDAxes(np.arange(32.0), np.arange(16.0) - 8), Boxes2D.empty())
    stream = RDBatchStream([hand_made([], []), small], 2, seed=0, augment=None)
    with pytest.raises(ValueError, match="different input sizes"):
        stream.batch(0)
    with pytest.raises(ValueError, match="cannot fill"):
        RDBatchStream([small], 2, seed=0)


def test_prefetched_batches_are_the_direct_ones():
    stream = RDBatchStream(SYNTHETIC, 2, seed=9, augment=WITH_NOISE, max_boxes=16)
    with Prefetcher(stream.batch, range(2, 6), depth=2) as batches:
        got = list(batches)
    assert [step for step, _ in got] == [2, 3, 4, 5]
    for step, batch in got:
        assert_batches_equal(batch, stream.batch(step))
        assert batch["window"] == 0 and set(batch["inputs"]) == {"heat", "gray"}
