import jax
import numpy as np
import pytest

from dsfec_jax import api, zoo
from conftest import random_variables, tiny

# Pinned parameter counts (params collection; BN moving statistics excluded). A change here
# changes the published size table: update dsfec_jax/profile/records/zoo.json with it.
PINNED_PARAMS = {"baseline": 2_679_894, "dsfec_l": 2_397_486, "dsfec_m": 585_182, "dsfec_s": 296_942}


def n_params(detector):
    shapes = jax.eval_shape(detector.init, jax.random.key(0))
    return sum(int(np.prod(x.shape)) for x in jax.tree.leaves(shapes["params"]))


PAPER_DSFEC = ("baseline", "dsfec_l", "dsfec_m", "dsfec_s")


def test_available_lists_the_paper_variants():
    # the paper's four and the NAS-searched subnet registered in dsfec/searched.json
    assert zoo.available("dsfec") == ["baseline", "dsfec_l", "dsfec_m", "dsfec_s", "dsfec_search"]
    radarnext = [f"radarnext_{n}{d}" for n in ("fpn", "mdfen", "pan") for d in ("", "_dense", "_tj4d")]
    assert zoo.available("radarnext") == radarnext
    assert zoo.available(modality="points") == sorted(zoo.available("dsfec") + radarnext)
    assert zoo.available("camera") == zoo.available(modality="image") == ["shuffle_yolov3", "yolov3_darknet53"]
    assert zoo.available() == sorted(zoo.available("dsfec") + radarnext + zoo.available("yolo_rd")
                                     + zoo.available("camera"))
    assert zoo.available(modality="rd") == zoo.available("yolo_rd")


def test_the_camera_family_is_a_zoo_family():
    det = zoo.create("shuffle_yolov3")
    family = zoo.family_of("shuffle_yolov3")
    assert family.name == "camera" and family.modality == "image" and family.benchmark == "street"
    assert family.metric.name == "camera_voc" and family.metric.headline == "mAP50"
    assert family.schedules == {"quick": "yolo3_quick", "paper": "yolo3_paper"}
    assert len(det.config.classes) == 20 and det.config.classes[14] == "person"  # VOC by default
    shapes = jax.eval_shape(det.init, jax.random.key(0))
    assert n_params(det) == 1_660_353 and set(shapes["params"]) == {"backbone", "head"}
    outputs = jax.eval_shape(det.apply, shapes, det.dummy_inputs(1))
    assert [o.shape for o in outputs] == [(1, 416 // s, 416 // s, 3, 25) for s in (8, 16, 32)]
    street = zoo.create("shuffle_yolov3", num_classes=5, class_names=("car", "truck", "bus", "pedestrian", "cyclist"))
    assert street.config.classes[3] == "pedestrian" and family.head_classes(street.config)["detect"][4] == "cyclist"
    with pytest.raises(ValueError, match="class_names"):
        zoo.create("shuffle_yolov3", class_names=("car", "bus"))  # 2 names for 20 classes
    with pytest.raises(FileNotFoundError, match="ships no weights"):
        api.load("yolov3_darknet53")  # too costly to train on this CPU (README); Shuffle-YOLOv3's are shipped


def test_the_depth_network_is_an_auxiliary_model_of_the_zoo():
    from dsfec_jax.models.depth import TINY, MonodepthConfig, count_params

    assert zoo.available_auxiliary() == zoo.available_auxiliary("depth") == ["monodepth_street", "monodepth_tiny"]
    assert not set(zoo.available_auxiliary()) & set(zoo.available())  # one namespace: no name is both
    assert zoo.config("monodepth_street") == MonodepthConfig() and zoo.config("monodepth_tiny", width=96).width == 96
    assert zoo.auxiliary_of("monodepth_tiny").name == "depth"
    net = zoo.create_auxiliary("monodepth_tiny")
    assert net.config == TINY and net.collections == ("params",)
    shapes = net.variable_shapes()
    assert set(shapes) == {"params"} and count_params(shapes) == count_params(net.init(jax.random.key(0)))
    with pytest.raises(KeyError, match="create_auxiliary"):
        zoo.create("monodepth_street")
    with pytest.raises(KeyError, match="monodepth_street"):
        zoo.create_auxiliary("monodepth_xl")
    # its shipped weights load through the detectors' loader
    path = zoo.shipped_weights("monodepth_street")
    assert path == zoo.WEIGHTS_DIR / "depth" / "monodepth_street.msgpack" and path.is_file()
    street = zoo.create_auxiliary("monodepth_street")
    assert zoo.auxiliary_config(path, "depth") == street.config
    variables = zoo.model_variables(street, path)
    assert set(variables) == {"params"} and count_params(variables) == 2_004_264
    with pytest.raises(ValueError, match="batch_stats"):  # a detector does not load it
        zoo.load_variables(zoo.create("dsfec_s"), path)


@pytest.mark.parametrize("name", sorted(PINNED_PARAMS))
def test_pinned_param_counts(name):
    assert n_params(zoo.create(name)) == PINNED_PARAMS[name]


def test_stage_blocks_follow_the_paper():
    blocks = {n: zoo.config(n).stage_blocks for n in PAPER_DSFEC}
    assert blocks == {"baseline": (3, 6, 6, 3), "dsfec_l": (3, 6, 6, 3), "dsfec_m": (3, 3, 2, 3), "dsfec_s": (1, 1, 3, 2)}
    s = zoo.config("dsfec_s")
    assert (s.act_fec, s.act_stem, s.act_backbone, s.act_car_head, s.act_truck_head, s.act_vru_head) == (
        "relu", "leaky_relu", "leaky_relu", "swish", "swish", "relu")


def test_overrides_are_applied_and_change_the_network():
    d = zoo.create("dsfec_s", stem_filters=16, stage_blocks=[1, 3, 3, 2])
    assert d.config.stem_filters == 16 and d.config.stage_blocks == (1, 3, 3, 2)
    assert n_params(d) > PINNED_PARAMS["dsfec_s"]
    assert zoo.config("dsfec_s").stem_filters == 12  # the registry is untouched


def test_unknown_name_and_field_list_the_valid_ones():
    with pytest.raises(KeyError, match="dsfec_l"):
        zoo.create("dsfec_xl")
    with pytest.raises(TypeError, match="stem_filters"):
        zoo.create("dsfec_s", stem_filter=16)


@pytest.mark.parametrize("override,field", [
    ({"fec_filters": (32, 16, 12)}, "f1 < f2"), ({"stage_blocks": (1, 0, 3, 2)}, "stage_blocks"),
    ({"act_stem": "elu"}, "act_stem"), ({"block": "mbconv"}, "block"), ({"stage_widths": (8, 8, 8)}, "stage_widths"),
])
def test_invalid_configs_fail_naming_the_field(override, field):
    with pytest.raises(ValueError, match=field):
        zoo.create("dsfec_l", **override)


@pytest.mark.parametrize("name", ["baseline", "dsfec_l", "dsfec_m", "dsfec_s"])
def test_outputs_finite_for_random_empty_and_full_inputs(name):
    det = tiny(name)
    # random weights and running statistics in init's tree (eval_shape): `init` would compile the
    # network once more (~10 s a variant); init itself runs for every family in other tests
    variables = random_variables(det, 0)
    infer = jax.jit(det.apply)
    nx, ny = det.config.grid.shape
    stride = det.config.output_stride
    for occupancy in (0.0, 0.3, 1.0):
        out = infer(variables, det.dummy_inputs(2, seed=3, occupancy=occupancy))
        assert set(out) == {"car", "truck", "vru"}
        assert out["vru"]["cls"].shape == (2, nx // stride, ny // stride, 2)
        assert out["car"]["box"].shape[-1] == 6
        assert all(np.isfinite(np.asarray(x)).all() for x in jax.tree.leaves(out)), occupancy


def test_jit_and_no_jit_agree():
    det = tiny("dsfec_s")
    variables = random_variables(det, 1)  # from eval_shape: no compile of `init`
    x = det.dummy_inputs(1, seed=5)
    a = jax.jit(det.apply)(variables, x)
    with jax.disable_jit():
        b = det.apply(variables, x)
    jax.tree.map(lambda u, v: np.testing.assert_allclose(u, v, atol=1e-4, rtol=1e-4), a, b)


@pytest.mark.parametrize("name", ["dsfec_m", "baseline"])
def test_grouped_and_shifted_depthwise_networks_agree(name):
    shifted = tiny(name)
    grouped = tiny(name, depthwise_impl="grouped")
    variables = random_variables(shifted, 2)  # non-trivial BN statistics too; no compile of `init`
    x = shifted.dummy_inputs(1, seed=7)
    a, b = jax.jit(shifted.apply)(variables, x), jax.jit(grouped.apply)(variables, x)
    jax.tree.map(lambda u, v: np.testing.assert_allclose(u, v, atol=1e-5, rtol=1e-5), a, b)


def test_train_mode_updates_batch_stats():
    det = tiny("dsfec_s")
    variables = det.init(jax.random.key(0))
    out, updates = jax.jit(lambda v, x: det.apply(v, x, train=True))(variables, det.dummy_inputs(2))
    assert set(updates) == {"batch_stats"}
    before, after = jax.tree.leaves(variables["batch_stats"]), jax.tree.leaves(updates["batch_stats"])
    assert any(not np.allclose(a, b) for a, b in zip(before, after))


@pytest.mark.parametrize("path", sorted(zoo.WEIGHTS_DIR.glob("*.msgpack")), ids=lambda p: p.stem)
def test_every_shipped_weights_file_loads_and_records_how_it_was_made(path):
    import json

    from conftest import TINY_GRID

    manifest = json.loads(path.with_name(path.name + ".json").read_text())
    family = zoo.family_of(path.stem)
    assert manifest["model"] == path.stem and manifest["training"]["command"].startswith("dsfec train")
    assert manifest["training"]["seed"] == 0 and manifest["versions"]["jax"]
    assert 0 < manifest["measured"]["test"][family.metric.headline] <= 100
    if family.modality == "rd":  # a map in, 2D boxes in map pixels out (a small input: a cheap compile)
        from dsfec_jax.data.rd.representations import RDRepresentation
        from dsfec_jax.data.rd.sources import load_rd_samples

        sample = load_rd_samples("synthetic", "val", 1)[0]
        tiny = RDRepresentation(fit="resize", input_hw=(64, 32))
        out = api.load(path.stem, predictor_options={"representation": tiny})(sample)
        assert len(out) and np.isfinite(out.scores).all() and out.xyxy.max() <= max(sample.shape)
        return
    if family.modality == "image":  # an image in, 2D boxes in its pixels out (letterboxed small: a cheap compile)
        from dsfec_jax.data.camera.sources import load_camera_images

        image = load_camera_images("street", "val", 1)[0]
        out = api.load(path.stem, predictor_options={"size": 96, "score_threshold": 0.0})(image)
        h, w = image.hw
        assert len(out) and np.isfinite(out.scores).all() and (out.xyxy[:, 2] <= w).all() and (out.xyxy[:, 3] <= h).all()
        assert set(out.names) <= set(manifest["training"]["overrides"]["class_names"])
        return
    predictor = api.load(path.stem, grid=TINY_GRID, max_pillars=96)  # weights fit any grid
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(0, 16, 50), rng.uniform(-8, 8, 50), rng.normal(0, 1, (50, 5))])
    out = predictor(points.astype(np.float32))
    assert len(out.boxes) == len(out.scores) and np.isfinite(out.scores).all()


def deployed_params(name: str, **overrides) -> int:
    """Parameters of the inference (fused) form, as README's RadarNeXt table counts them."""
    det = zoo.create(name, **overrides)
    shapes = jax.eval_shape(det.init, jax.random.key(0))
    _, fused = zoo.deploy(det, jax.tree.map(lambda s: np.zeros(s.shape, s.dtype), shapes), fold_batch_norm=False)
    return sum(int(np.prod(x.shape)) for x in jax.tree.leaves(fused["params"]))


# README's RadarNeXt rows that tests/models/test_radarnext.py does not pin exactly: the Dense FPN
# (4,856,716, 131 k above the paper) and DCNv3 at position 3 (1.547 M where the paper says 1.630 M).
@pytest.mark.parametrize("name,overrides,expected", [("radarnext_fpn_dense", {}, 4_856_716),
                                                     ("radarnext_mdfen", {"dcn_positions": (3,)}, 1_547_448)])
def test_radarnext_sizes_printed_in_the_readme(name, overrides, expected):
    assert deployed_params(name, **overrides) == expected
