"""Camera images -> training batches (data/camera: letterbox, augment, batches, sources): the input
shapes of the resize policy, boxes that follow a flip and an affine exactly (checked against the
pixels of a drawn rectangle), HSV jitter that keeps boxes, batches and multi-scale sizes as pure
functions of (seed, step), and the sources' classes. No network is compiled here."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from builders import assert_rows_are_the_batch_rows
from conftest import shared_data_dir

from dsfec_jax.boxes.boxes2d import Boxes2D
from dsfec_jax.data.camera import voc
from dsfec_jax.data.camera.augment import CameraAugment, augment
from dsfec_jax.data.camera.batches import DARKNET_SIZES, CameraBatchStream, MultiScale, eval_input
from dsfec_jax.data.camera.images import CameraImage
from dsfec_jax.data.camera.letterbox import letterbox, network_shape, training_aspect, warp
from dsfec_jax.data.camera.sources import NoImages, class_map, load_camera_images, source_classes
from dsfec_jax.models.camera.config import VOC_CLASSES
from dsfec_jax.models.camera.targets import pad_batch

STREET = ("car", "truck", "bus", "pedestrian", "cyclist")
RED = (230, 20, 20)
BOX = (100.0, 50.0, 160.0, 90.0)  # the red rectangle: columns 100..159, rows 50..89 (pixel edges)
NO_COLOUR = dict(hue=0.0, saturation=1.0, exposure=1.0)


def drawn(hw=(234, 416), box=BOX, name="car") -> CameraImage:
    """A grey image with one red rectangle exactly covering `box`."""
    image = np.full((*hw, 3), 90, np.uint8)
    x1, y1, x2, y2 = (int(v) for v in box)
    image[y1:y2, x1:x2] = RED
    return CameraImage("drawn", image, Boxes2D(np.array([box], np.float32), np.array([name]), None, np.array([False])))


def red_extent(image: np.ndarray) -> np.ndarray:
    """The pixel-edge box of the pixels that are more red than grey (bilinear edges cut at half way)."""
    red = (image[..., 0].astype(int) - image[..., 1].astype(int)) > (RED[0] - RED[1]) / 2
    rows, cols = np.flatnonzero(red.any(1)), np.flatnonzero(red.any(0))
    return np.array([cols[0], rows[0], cols[-1] + 1, rows[-1] + 1], float)


def test_resize_policy_shapes():
    assert network_shape(416, 234 / 416) == (256, 416)  # the street frames: 416 x 256, not 416 x 416
    assert network_shape(608, 234 / 416) == (352, 608) and network_shape(320, 234 / 416) == (192, 320)
    assert network_shape(416, 500 / 375) == (416, 320)  # a portrait VOC image
    assert network_shape(416, 1.0) == (416, 416)
    assert training_aspect([(234, 416)] * 3) == pytest.approx(234 / 416)
    assert training_aspect([(375, 500), (500, 375)]) == 1.0  # mixed shapes train on squares
    with pytest.raises(ValueError, match="multiple of 32"):
        network_shape(400, 1.0)


def test_letterbox_keeps_the_aspect_and_centres():
    a = letterbox((234, 416), (256, 416))
    assert (a.sx, a.sy, a.ox, a.oy) == (1.0, 1.0, 0.0, 11.0)
    image, affine = eval_input(drawn(), (256, 416))
    assert image.shape == (256, 416, 3) and image.dtype == np.float32 and image.max() <= 1.0
    np.testing.assert_allclose(red_extent(np.rint(image * 255).astype(np.uint8)), affine.boxes([BOX])[0])
    assert np.all(image[:11] == 127 / 255) and np.all(image[-11:] == 127 / 255)  # grey bars


@pytest.mark.parametrize("flip", [0.0, 1.0])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_boxes_follow_the_flip_and_the_affine_exactly(flip, seed):
    """Random scale, shift (and a forced flip or none): the moved box is where the red pixels went."""
    cfg = CameraAugment(flip=flip, scale=0.25, translate=0.1, **NO_COLOUR)
    image, boxes = augment(drawn(), (256, 416), np.random.default_rng(seed), cfg)
    assert image.shape == (256, 416, 3) and len(boxes) == 1 and boxes.names[0] == "car"
    np.testing.assert_allclose(boxes.xyxy[0], red_extent(image), atol=0.75)  # pixel extents: +-0.5 px
    straight, _ = augment(drawn(), (256, 416), np.random.default_rng(seed), CameraAugment(flip=0.0, **NO_COLOUR))
    if flip:  # the same draws mirrored: x -> W - x
        np.testing.assert_allclose(straight[:, ::-1], image, atol=1)


def test_boxes_leaving_the_input_are_clipped_or_dropped():
    near_edge = drawn(box=(0.0, 100.0, 30.0, 140.0))
    rng = np.random.default_rng(0)
    cfg = CameraAugment(flip=0.0, scale=0.0, translate=0.0, **NO_COLOUR)
    kept = augment(near_edge, (256, 416), rng, cfg)[1]
    assert len(kept) == 1
    shifted = CameraAugment(flip=0.0, scale=0.0, translate=0.09, **NO_COLOUR, min_kept=0.9)
    outcomes = {len(augment(near_edge, (256, 416), np.random.default_rng(s), shifted)[1]) for s in range(20)}
    assert outcomes == {0, 1}  # shifted left it is cut to under 90 % and dropped, else kept
    for s in range(20):
        boxes = augment(near_edge, (256, 416), np.random.default_rng(s), shifted)[1]
        assert np.all(boxes.xyxy >= 0) and np.all(boxes.xyxy[:, [0, 2]] <= 416)


def test_hsv_jitter_moves_colours_not_boxes():
    item = drawn()
    cfg = CameraAugment(flip=0.0, scale=0.0, translate=0.0)  # darknet's hue .1, saturation and exposure 1.5
    plain = warp(item.image, letterbox(item.hw, (256, 416)), (256, 416))
    changed = 0
    for seed in range(4):
        image, boxes = augment(item, (256, 416), np.random.default_rng(seed), cfg)
        np.testing.assert_array_equal(boxes.xyxy, letterbox(item.hw, (256, 416)).boxes(item.boxes.xyxy))
        changed += not np.array_equal(image, plain)
    assert changed == 4


def random_images(n: int, seed: int = 0) -> list[CameraImage]:
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        xy = rng.uniform(0, 300, (3, 2))
        boxes = np.column_stack([xy, xy + rng.uniform(10, 80, (3, 2))]).astype(np.float32)
        out.append(CameraImage(f"im{i}", rng.integers(0, 255, (234, 416, 3), dtype=np.uint8),
                               Boxes2D(boxes, np.array(["car", "pedestrian", "bus"]), None,
                                       np.array([False, False, True]))))
    return out


def stream(seed=0, images=None, sizes=MultiScale((64, 96), every=2)):
    targets = functools.partial(pad_batch, class_names=STREET, max_boxes=8)
    return CameraBatchStream(images or random_images(4), 2, seed, targets, CameraAugment(), sizes)


def test_batches_are_shaped_and_a_pure_function_of_seed_and_step():
    s = stream()
    b = s.batch(3)
    h, w = s.input_hw(3)
    assert b["inputs"]["image"].shape == (2, h, w, 3) and b["inputs"]["image"].dtype == np.float32
    assert 0 <= b["inputs"]["image"].min() and b["inputs"]["image"].max() <= 1
    assert {k: v.shape for k, v in b["targets"].items()} == {"gt_boxes": (2, 8, 4), "gt_labels": (2, 8),
                                                             "gt_mask": (2, 8)}
    # the difficult bus is left out of the targets; car 0, pedestrian 3
    assert set(b["targets"]["gt_labels"][b["targets"]["gt_mask"]]) <= {0, 3} and b["window"] == 0
    again = stream().batch(3)
    for k in ("gt_boxes", "gt_mask"):
        np.testing.assert_array_equal(b["targets"][k], again["targets"][k])
    np.testing.assert_array_equal(b["inputs"]["image"], again["inputs"]["image"])
    other = stream(seed=1).batch(3)
    assert not np.array_equal(other["inputs"]["image"], b["inputs"]["image"][:, :other["inputs"]["image"].shape[1]]
                              ) or other["inputs"]["image"].shape != b["inputs"]["image"].shape
    assert sorted(np.concatenate([s.indices(k) for k in range(2)]).tolist()) == [0, 1, 2, 3]  # an epoch


def test_a_slice_of_rows_is_those_rows_of_the_batch():
    assert_rows_are_the_batch_rows(stream(), 3, slice(1, 2))


def test_multi_scale_sizes_are_darknets_and_drawn_per_block():
    assert DARKNET_SIZES == (320, 352, 384, 416, 448, 480, 512, 544, 576, 608)
    ms = MultiScale(DARKNET_SIZES, every=10)
    sizes = [ms.size(seed=0, step=k) for k in range(400)]
    assert all(len(set(sizes[b:b + 10])) == 1 for b in range(0, 400, 10))  # one size per 10 batches
    assert set(sizes) <= set(DARKNET_SIZES) and len(set(sizes)) >= 8
    assert sizes == [ms.size(seed=0, step=k) for k in range(400)] != [ms.size(seed=1, step=k) for k in range(400)]
    assert MultiScale.span(320, 416).sizes == (320, 352, 384, 416) and MultiScale((416,)).size(5, 7) == 416
    s = stream(sizes=MultiScale.span(64, 128, every=1))
    assert {s.input_hw(k) for k in range(40)} == {(64, 64), (64, 96), (96, 128)}  # 16:9 frames
    with pytest.raises(ValueError, match="multiples of 32"):
        MultiScale((100,))


def test_the_last_200_batches_run_at_608_as_darknets_detector_c():
    # a switch at block start b pins 608 when b + 200 > max_batches: blocks from 810 of 1000 on
    ms = MultiScale(DARKNET_SIZES, final_size=608, total_steps=1000)
    sizes = [ms.size(seed=0, step=k) for k in range(1000)]
    assert set(sizes[810:]) == {608} and sizes[:800] == [MultiScale(DARKNET_SIZES).size(0, k) for k in range(800)]
    assert set(sizes[800:810]) != {608} or MultiScale(DARKNET_SIZES).size(0, 800) == 608
    assert MultiScale(DARKNET_SIZES, final_size=608).size(0, 999) == MultiScale(DARKNET_SIZES).size(0, 999)  # no end
    assert ms.record() == {"sizes": list(DARKNET_SIZES), "every": 10, "final_size": 608, "final_steps": 200,
                           "total_steps": 1000}
    assert MultiScale((64,)).record() == {"sizes": [64], "every": 10}
    with pytest.raises(ValueError, match="multiples of 32"):
        MultiScale((416,), final_size=600)


def test_street_source_and_class_maps():
    images = load_camera_images("street", "val", 2, seed=0)
    assert len(images) == 2 and images[0].hw == (234, 416) and images[0].boxes.difficult is not None
    assert set(np.concatenate([im.boxes.names for im in images])) <= set(STREET)
    assert source_classes("street") == STREET
    assert voc.VOC_CLASSES == VOC_CLASSES  # data's copy of the models' list
    assert class_map(STREET, VOC_CLASSES) == {"car": "car", "bus": "bus", "pedestrian": "person", "cyclist": "bicycle"}
    assert class_map(VOC_CLASSES, STREET) == {"bicycle": "cyclist", "bus": "bus", "car": "car", "person": "pedestrian"}
    assert class_map(STREET, STREET) == dict(zip(STREET, STREET))
    with pytest.raises(ValueError, match="no class"):
        class_map(("dog",), STREET)
    with pytest.raises(NoImages, match="splits"):
        load_camera_images("street", "all", 2)


def test_voc_source_reads_the_real_images():
    root = shared_data_dir() / "voc_review_od_metrics" / "data" / "database"
    if not (root / "voc.names").is_file():
        pytest.fail(f"VOC sample data not found under {root}; set DSFEC_DATA")
    images = load_camera_images(f"voc:{root}", "all", 3)
    assert len(images) == 3 and images[0].image_id == "2007_000027" and images[0].hw == (500, 486)
    assert images.shapes()[0] == (500, 486) and source_classes(f"voc:{root}") == VOC_CLASSES
    assert len(load_camera_images(f"voc:{root}", "all")) == 100
    with pytest.raises(NoImages, match="--split all"):
        load_camera_images(f"voc:{root}", "val")
