"""Shuffle-YOLOv3 and Darknet53-YOLOv3: the output interface at several input sizes, pinned
parameter counts, darknet's BFLOPs, the footprint arithmetic against the profiler's counter, the
paper's numbers as data, config validation and jit determinism. Weights come from eval_shape +
random_fill (no `init` compile); only three small forward programs are compiled."""

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.models.camera import paper
from dsfec_jax.models.camera.config import VOC_CLASSES, CameraConfig
from dsfec_jax.models.camera.footprint import footprint as _footprint, paper_memory_mib, trace
from dsfec_jax.models.camera.net import ARCHITECTURES, CameraNet
from dsfec_jax.models.camera.variants import VARIANTS
from dsfec_jax.models.camera.yolo3_neck_head import output_bias
from dsfec_jax.profile.counting import layer_macs
from conftest import random_fill

SHUFFLE, DARKNET = VARIANTS["shuffle_yolov3"], VARIANTS["yolov3_darknet53"]
quick_jit = functools.partial(jax.jit, compiler_options={"xla_backend_optimization_level": 0})

# trainable parameters at 20 classes (conv weights, output biases, BN scale/offset), derived in
# footprint.py's trace; the darknet ones are darknet's own (paper.py)
PARAMS = {"shuffle_yolov3": 1_660_353, "yolov3_darknet53": 61_626_049}
MACS_416 = {"shuffle_yolov3": 1_820_192_192, "yolov3_darknet53": 32_713_987_072}


footprint = functools.lru_cache(maxsize=None)(_footprint)  # configs are frozen: one trace each


def shapes(cfg, hw, batch=1):
    """(output shapes, variable shapes) of `cfg` at `hw`, nothing computed."""
    x = jax.ShapeDtypeStruct((batch, *hw, 3), jnp.float32)
    return jax.eval_shape(cfg.build().init_with_output, jax.random.key(0), x)


def n_params(cfg) -> int:
    return sum(int(np.prod(a.shape)) for a in jax.tree_util.tree_leaves(shapes(cfg, (64, 64))[1]["params"]))


def expected_shapes(cfg, hw, batch=1):
    return [(batch, hw[0] // s, hw[1] // s, 3, 5 + cfg.num_classes) for s in (8, 16, 32)]


@functools.lru_cache(maxsize=None)
def forward(name: str, hw: tuple[int, int], batch: int = 1):
    """(variables, images, jitted eval apply, outputs) of variant `name` on random images."""
    cfg = VARIANTS[name]
    variables = random_fill(shapes(cfg, hw, batch)[1], seed=0)
    x = jnp.asarray(cfg.dummy_inputs(batch, seed=1, hw=hw)["image"])
    apply = quick_jit(cfg.build().apply)
    return variables, x, apply, apply(variables, x)


@pytest.mark.parametrize("name,hw", [("shuffle_yolov3", (64, 64)), ("shuffle_yolov3", (96, 128)),
                                     ("yolov3_darknet53", (64, 64))])
def test_forward_maps_follow_the_interface(name, hw):
    cfg = VARIANTS[name]
    *_, out = forward(name, hw)
    assert isinstance(out, tuple) and [o.shape for o in out] == expected_shapes(cfg, hw)
    assert all(o.dtype == jnp.float32 and bool(jnp.all(jnp.isfinite(o))) for o in out)


@pytest.mark.parametrize("name", sorted(VARIANTS))
@pytest.mark.parametrize("hw,batch", [((96, 128), 2), ((416, 416), 1), ((320, 608), 1)])
def test_output_shapes_by_eval_shape(name, hw, batch):
    out, _ = shapes(VARIANTS[name], hw, batch)
    assert [o.shape for o in out] == expected_shapes(VARIANTS[name], hw, batch)


def test_jit_is_deterministic():
    variables, x, apply, out = forward("shuffle_yolov3", (64, 64))
    again = apply(variables, x)
    for a, b in zip(out, again):
        np.testing.assert_array_equal(a, b)


def test_train_mode_updates_batch_stats():
    cfg = SHUFFLE
    _, variables = shapes(cfg, (64, 64), 2)
    x = jax.ShapeDtypeStruct((2, 64, 64, 3), jnp.float32)
    out, new = jax.eval_shape(lambda v, x: cfg.build().apply(v, x, train=True, mutable=["batch_stats"]), variables, x)
    assert [o.shape for o in out] == expected_shapes(cfg, (64, 64), 2)
    assert jax.tree.structure(new["batch_stats"]) == jax.tree.structure(variables["batch_stats"])


def test_input_must_be_nhwc_rgb_in_multiples_of_32():
    with pytest.raises(ValueError, match="multiple of 32"):
        shapes(SHUFFLE, (64, 80))
    with pytest.raises(ValueError, match="NHWC"):
        jax.eval_shape(SHUFFLE.build().init, jax.random.key(0), jax.ShapeDtypeStruct((1, 3, 64, 64), jnp.float32))


@pytest.mark.parametrize("name", sorted(PARAMS))
def test_params_are_pinned(name):
    assert n_params(VARIANTS[name]) == PARAMS[name]


def test_darknet_counts_are_darknets():
    """61,626,049 at 20 classes (within 1 % of the published 61.6 M); at 80 classes 61,949,149 and, with
    the BN moving statistics and the 20-byte header, exactly yolov3.weights' 248,007,048 bytes."""
    assert abs(PARAMS["yolov3_darknet53"] / 61.6e6 - 1) < 0.01
    assert paper.DARKNET_YOLOV3_VOC["params"] == PARAMS["yolov3_darknet53"]
    coco = footprint(dataclasses.replace(DARKNET, num_classes=80))
    assert coco["params"] == paper.DARKNET_YOLOV3_COCO["params"]
    assert coco["weights_file_bytes"] == paper.DARKNET_YOLOV3_COCO["weights_file_bytes"]
    # by hand from the cfg: convs (k^2 C_in C_out) + BN scale/offset + the three output convs with bias
    convs = [(3, 3, 32)]
    for cin, c, n in ((32, 64, 1), (64, 128, 2), (128, 256, 8), (256, 512, 8), (512, 1024, 4)):
        convs += [(3, cin, c)] + [(1, c, c // 2), (3, c // 2, c)] * n
    for cin, w in ((1024, 1024), (768, 512), (384, 256)):
        convs += [(1, cin, w // 2), (3, w // 2, w), (1, w, w // 2), (3, w // 2, w), (1, w, w // 2), (3, w // 2, w)]
    convs += [(1, 512, 256), (1, 256, 128)]  # the route laterals
    by_hand = sum(k * k * ci * co + 2 * co for k, ci, co in convs) + sum(w * 75 + 75 for w in (1024, 512, 256))
    assert by_hand == PARAMS["yolov3_darknet53"] and len(convs) + 3 == 75


def test_darknet_bflops_at_416():
    f = footprint(DARKNET)
    assert f["macs"] == MACS_416["yolov3_darknet53"]
    assert abs(f["gflops"] / paper.QUOTED_BFLOPS - 1) < 0.01  # 65.43 against the quoted 65.9
    assert round(f["gflops"], 3) == paper.DARKNET_YOLOV3_VOC["bflops"]
    coco = footprint(dataclasses.replace(DARKNET, num_classes=80))
    assert round(coco["gflops"], 3) == paper.DARKNET_YOLOV3_COCO["bflops"]


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_footprint_macs_match_the_profilers_counter(name):
    """footprint's trace and profile/counting.py's interceptor count the same convolutions."""
    cfg = VARIANTS[name]
    rows = layer_macs(zoo.Detector(cfg), 1)
    f = footprint(cfg)
    assert sum(m for *_, m in rows) == f["macs"] == MACS_416[name]
    assert len(rows) == f["conv_layers"]


def test_paper_memory_formula_by_hand_on_darknet():
    """params C_in C_out K^2 + C_out per conv + C_out H W per conv output, fp32: the 'conv' reading;
    'all' adds the shortcuts, upsamples and routes."""
    layers, _ = trace(DARKNET)
    convs = [lay for lay in layers if lay.is_conv]
    assert len(convs) == 75 and sum(lay.kind == "shortcut" for lay in layers) == 23
    assert sum(lay.kind == "route" for lay in layers) == 2 and sum(lay.kind == "upsample" for lay in layers) == 2
    f = footprint(DARKNET)
    stem = convs[0]
    assert stem.paper_params == 3 * 32 * 9 + 32 and stem.out_elems == 416 * 416 * 32
    # BN folded: the paper's parameter count is the trainable one minus one per BN channel
    assert f["paper_params"] == PARAMS["yolov3_darknet53"] - f["batch_stats"] // 2
    mem = f["paper_memory"]
    assert mem["conv_total_bytes"] == 4 * (f["paper_params"] + sum(lay.out_elems for lay in convs))
    assert paper_memory_mib(DARKNET) == pytest.approx(mem["all_total_bytes"] / 2**20)


def test_shuffle_layers_counted_in_the_formula():
    layers, _ = trace(SHUFFLE)
    units = [lay for lay in layers if lay.kind == "concat"]
    assert len(units) == sum(SHUFFLE.repeats[1:]) + 3 * SHUFFLE.head_units
    dw = [lay for lay in layers if lay.kind == "depthwise"]
    assert {lay.kernel for lay in dw} == {3, 5}
    assert all(lay.paper_params == lay.kernel**2 * lay.out_shape[-1] + lay.out_shape[-1] for lay in dw)


def test_ratios_against_the_paper_are_what_the_report_says():
    """Our layout is far lighter than the paper's printed figures (README): pinned so a change shows."""
    s, d = footprint(SHUFFLE), footprint(DARKNET)
    assert s["gflops"] / d["gflops"] == pytest.approx(0.0556, abs=1e-3)  # paper: 25 / 60
    assert s["size_mb"] / d["size_mb"] == pytest.approx(0.0269, abs=1e-3)  # paper: 18.7 %
    assert s["paper_memory_mb"]["all_total_bytes"] == pytest.approx(144.15, abs=0.01)  # paper: 220 MB
    assert d["paper_memory_mb"]["all_total_bytes"] == pytest.approx(467.07, abs=0.01)  # paper implies 450.8


def test_output_biases():
    b = output_bias(3, 20, 8, prior=True).reshape(3, 25)
    np.testing.assert_array_equal(b[:, :4], 0)
    np.testing.assert_allclose(b[:, 4], math.log(8 / 80**2), rtol=1e-6)
    np.testing.assert_allclose(b[:, 5:], math.log(0.6 / 19.01), rtol=1e-6)
    assert not output_bias(3, 20, 8, prior=False).any()
    _, variables = shapes(SHUFFLE, (64, 64))
    assert variables["params"]["head"]["out0"]["bias"].shape == (75,)


def test_config_fields_and_the_dispatch_table():
    assert set(ARCHITECTURES) == {"shuffle", "darknet53"}
    assert SHUFFLE.classes == VOC_CLASSES and SHUFFLE.num_classes == 20 and SHUFFLE.strides == (8, 16, 32)
    assert isinstance(SHUFFLE.build(), CameraNet)
    assert dataclasses.replace(SHUFFLE, num_classes=6).classes[-1] == "class5"
    for bad, match in ((dict(backbone="vgg"), "backbone"), (dict(repeats=(2, 2, 6, 6, 4)), "repeats"),
                       (dict(head_widths=(192, 256)), "head_widths"), (dict(split="odd"), "split"),
                       (dict(deep_stages=(True,)), "deep_stages"), (dict(fpn_merge="sum"), "fpn_merge")):
        with pytest.raises(ValueError, match=match):
            dataclasses.replace(SHUFFLE, **bad)


@pytest.mark.parametrize("changes", [dict(first_repeat="unit"), dict(fpn_merge="add"), dict(split="even_odd"),
                                     dict(deep_stages=(False,) * 5, deep_heads=(False,) * 3), dict(num_classes=6)])
def test_layout_alternatives_build(changes):
    cfg = dataclasses.replace(SHUFFLE, **changes)
    out, _ = shapes(cfg, (416, 416))
    assert [o.shape for o in out] == expected_shapes(cfg, (416, 416))
