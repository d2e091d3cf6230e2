"""YOLOv8 on RD maps and the Adapter: exact parameter counts, Adapter-at-init == YOLOv8n, shapes,
the Table 5/6 configs, and the layers' facts (padding, DFL, Coordinate Attention)."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax.layers.coord_attention import CoordinateAttention
from dsfec_jax.boxes.dfl import dfl_expectation
from dsfec_jax.layers.yolo import PaddedConv
from dsfec_jax.models.yolo_rd.adapter import Exchanger, resize_to
from dsfec_jax.models.yolo_rd.config import YoloRDConfig
from dsfec_jax.models.yolo_rd.head import DetectHead, class_bias
from dsfec_jax.models.yolo_rd.net import SHARED_SUBTREES, with_base_weights
from dsfec_jax.models.yolo_rd.variants import (TABLE5_ROWS, TABLE6_OPTIONS, VARIANTS, fusion_variant,
                                               representation_variant)
from conftest import random_fill

TINY_HW = (64, 32)
# LLVM's optimisation level changes compile time (4x here), not what a graph computes
quick_jit = functools.partial(jax.jit, compiler_options={"xla_backend_optimization_level": 0})
COCO80 = tuple(f"class{i}" for i in range(80))


@functools.lru_cache(maxsize=None)
def shapes(cfg: YoloRDConfig, hw=TINY_HW, batch: int = 1):
    """(output shapes, variable shapes) without compiling anything."""
    x = {k: jnp.asarray(v) for k, v in cfg.dummy_inputs(batch, 0, hw=hw).items()}
    return jax.eval_shape(cfg.build().init_with_output, jax.random.key(0), x)


def n_params(cfg: YoloRDConfig) -> int:
    return sum(int(np.prod(a.shape)) for a in jax.tree_util.tree_leaves(shapes(cfg)[1]["params"]))


def n_bn_channels(cfg: YoloRDConfig) -> int:
    """What folding every BN into its conv removes (scale and shift become one bias)."""
    leaves = jax.tree_util.tree_leaves_with_path(shapes(cfg)[1]["params"])
    return sum(int(np.prod(a.shape)) for p, a in leaves if p[-1].key == "scale")


# Trainable parameters at nc = 6 (RADDet), derived from the architecture: the nc = 80 counts below
# reproduce ultralytics' published ones exactly, so these are ultralytics' own at nc = 6.
NC6 = {"n": 3_012_002, "s": 11_137_906, "m": 25_859_778, "l": 43_634_450}
# ultralytics cfg/models/v8/yolov8.yaml comments at nc = 80: parameters minus the 16 frozen DFL
# weights (n 3,157,200; s 11,166,560; m 25,902,640; l 43,691,520; x 68,229,648 parameters)
NC80 = {"n": 3_157_184, "s": 11_166_544, "m": 25_902_624, "l": 43_691_504, "x": 68_229_632}
ADAPTER_PARAMS = 3_248_056  # ours; the paper's 3.24 M


@pytest.mark.parametrize("scale", sorted(NC6))
def test_yolov8_counts_at_nc6_are_exact(scale):
    assert n_params(VARIANTS[f"yolov8{scale}"]) == NC6[scale]


@pytest.mark.parametrize("scale", sorted(NC80))
def test_yolov8_counts_at_nc80_match_ultralytics(scale):
    assert n_params(YoloRDConfig(name=f"yolov8{scale}_coco", scale=scale, classes=COCO80)) == NC80[scale]


def test_paper_counts_s_and_m_are_the_bn_folded_ones():
    """Table 3 prints s 11.13 and m 25.84 (BN folded: 11,127,890 and 25,843,218), l 43.63 (unfolded)."""
    folded = {s: NC6[s] - n_bn_channels(VARIANTS[f"yolov8{s}"]) for s in "nsml"}
    assert folded == {"n": 3_006_802, "s": 11_127_890, "m": 25_843_218, "l": 43_611_218}


def test_adapter_count_within_5_percent_of_the_paper():
    count = n_params(VARIANTS["yolov8n_adapter"])
    assert count == ADAPTER_PARAMS
    assert abs(count / 3.24e6 - 1) < 0.05


def test_adapter_parts_follow_table7_steps():
    """Stem ~0.09 M, four mode-1 Exchangers ~0.08 M, three mode-2 ~0.06 M (Table 7's steps)."""
    tree = shapes(VARIANTS["yolov8n_adapter"])[1]["params"]["adapter"]
    size = lambda t: sum(int(np.prod(a.shape)) for a in jax.tree_util.tree_leaves(t))
    ex = [size(tree[f"exchangers_{k}"]) for k in range(7)]
    assert size(tree["stem"]) == 92_896
    assert sum(ex[0::2]) == 74_984 and sum(ex[1::2]) == 68_174
    assert NC6["n"] + size(tree) == ADAPTER_PARAMS


def test_output_shapes_for_a_256x64_map():
    cfg = VARIANTS["yolov8n_adapter"]
    outs, _ = shapes(cfg, hw=(256, 64), batch=2)
    no = 4 * 16 + 6
    assert [o.shape for o in outs] == [(2, 32, 8, no), (2, 16, 4, no), (2, 8, 2, no)]
    assert cfg.input_names == ("heat", "gray")


@pytest.mark.parametrize("backbone_input,adapter_input", TABLE5_ROWS)
def test_table5_representation_configs_build(backbone_input, adapter_input):
    cfg = representation_variant(backbone_input, adapter_input)
    outs, variables = shapes(cfg)
    assert [o.shape[1:3] for o in outs] == [(8, 4), (4, 2), (2, 1)]
    assert set(variables["params"]) == set(SHARED_SUBTREES) | ({"adapter"} if adapter_input else set())
    assert set(cfg.input_names) == {backbone_input, adapter_input} - {None}
    # the representations change only what the first convs read: 3 channels (heat) or 1 (gray)
    want = NC6["n"] - (2 * 9 * 16 if backbone_input == "gray" else 0)
    if adapter_input:
        want += ADAPTER_PARAMS - NC6["n"] + (2 * 9 * 32 if adapter_input == "heat" else 0)
    assert n_params(cfg) == want


@pytest.mark.parametrize("option", TABLE6_OPTIONS)
def test_table6_fusion_configs_build(option):
    tree = shapes(fusion_variant(option))[1]["params"]["adapter"]["exchangers_0"]
    assert ("gamma" in tree) == (option == 1) and ("fusion_weight" in tree) == (option == 3)


def test_adapter_backbone_neck_head_have_yolov8n_names_and_shapes():
    base, adapter = shapes(VARIANTS["yolov8n"])[1], shapes(VARIANTS["yolov8n_adapter"])[1]
    for collection in ("params", "batch_stats"):
        for name in SHARED_SUBTREES:
            assert jax.tree.map(lambda a: a.shape, base[collection][name]) == \
                jax.tree.map(lambda a: a.shape, adapter[collection][name])


def random_variables(cfg: YoloRDConfig, seed: int) -> dict:
    """Random weights and BN statistics from the shapes (no compiled init); the Adapter's alpha,
    gamma at their initial 0 (test_exchanger_starts_as_identity checks that init gives 0)."""
    return random_fill(shapes(cfg)[1], seed, scale_range=(0.5, 1.5), zeros=("alpha", "gamma"))


def test_adapter_at_init_equals_yolov8n_with_the_same_weights():
    base_cfg, adapter_cfg = VARIANTS["yolov8n"], VARIANTS["yolov8n_adapter"]
    base_vars = random_variables(base_cfg, 1)
    adapter_vars = with_base_weights(random_variables(adapter_cfg, 2), base_vars)
    x = {k: jnp.asarray(v) for k, v in adapter_cfg.dummy_inputs(2, 3, hw=TINY_HW).items()}
    run_base, run_adapter = quick_jit(base_cfg.build().apply), quick_jit(adapter_cfg.build().apply)
    want = run_base(base_vars, x)
    assert all(np.isfinite(np.asarray(o)).all() for o in want)
    assert all(np.array_equal(a, b) for a, b in zip(run_adapter(adapter_vars, x), want))
    # the check can fail: a non-zero alpha in the first (mode-1) Exchanger changes the detector
    adapter = dict(adapter_vars["params"]["adapter"])
    adapter["exchangers_0"] = {**adapter["exchangers_0"], "alpha": jnp.float32(0.5)}
    moved = run_adapter({**adapter_vars, "params": {**adapter_vars["params"], "adapter": adapter}}, x)
    assert not any(np.allclose(a, b) for a, b in zip(moved, want))


@pytest.mark.parametrize("fusion", (1, 2, 3))
def test_exchanger_starts_as_identity(fusion):
    rng = np.random.default_rng(0)
    primary = jnp.asarray(rng.normal(size=(2, 4, 2, 16)), jnp.float32)
    aux = jnp.asarray(rng.normal(size=(2, 16, 8, 24)), jnp.float32)
    ex = Exchanger(fusion)
    variables = quick_jit(ex.init)(jax.random.key(0), primary, aux)
    assert float(variables["params"]["alpha"]) == 0.0
    assert fusion != 1 or float(variables["params"]["gamma"]) == 0.0
    run = quick_jit(functools.partial(ex.apply, mutable=["batch_stats"]), static_argnums=3)
    for train in (False, True):
        assert np.array_equal(run(variables, primary, aux, train)[0], primary)
    variables["params"]["alpha"] = jnp.float32(1.0)
    assert not np.allclose(run(variables, primary, aux, False)[0], primary)


def test_yolov8_head_bias_init():
    """Box bins 1.0; class logits log(5 / nc / (640 / stride)^2) per level (ultralytics bias_init)."""
    want = [np.log(5 / 6 / (640 / s) ** 2) for s in (8, 16, 32)]
    assert [class_bias(6, s) for s in (8, 16, 32)] == pytest.approx(want)
    head = DetectHead(6, strides=(32,))  # one level, so that only six convs are initialised
    params = quick_jit(head.init)(jax.random.key(0), [jnp.zeros((1, 1, 1, 8))])["params"]
    np.testing.assert_allclose(params["box0_out"]["bias"], np.ones(64))
    np.testing.assert_allclose(params["cls0_out"]["bias"], np.full(6, np.log(5 / 6 / 20**2)), rtol=1e-6)


def test_stride2_conv_pads_like_pytorch():
    """autopad k // 2 on both sides: output (i, j) of a 3x3 stride-2 conv is centred on input (2i, 2j)
    (TF 'SAME' on an even size would centre it on (2i + 1, 2j + 1))."""
    x = jnp.arange(1.0, 1 + 8 * 8).reshape(1, 8, 8, 1)
    kernel = jnp.zeros((3, 3, 1, 1)).at[1, 1, 0, 0].set(1.0)  # the centre tap
    y = PaddedConv(1, 3, 2).apply({"params": {"kernel": kernel}}, x)
    np.testing.assert_array_equal(y[0, :, :, 0], x[0, ::2, ::2, 0])


def test_dfl_is_the_expected_bin():
    logits = jnp.full((4, 16), -1e4).at[jnp.arange(4), jnp.array([0, 3, 9, 15])].set(0.0).reshape(1, 64)
    np.testing.assert_allclose(dfl_expectation(logits), [[0.0, 3.0, 9.0, 15.0]], atol=1e-6)
    np.testing.assert_allclose(dfl_expectation(jnp.zeros((2, 64))), np.full((2, 4), 7.5), rtol=1e-6)
    with pytest.raises(ValueError, match="4 \\* reg_max"):
        dfl_expectation(jnp.zeros((1, 60)))


def test_coordinate_attention_matches_a_reference():
    """houqb coordatt.py in numpy: pool along each axis, shared 1x1 + BN + h-swish, two 1x1 + sigmoid."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=(2, 5, 3, 40)).astype(np.float32)
    ca = CoordinateAttention()
    variables = quick_jit(ca.init)(jax.random.key(1), jnp.asarray(x))
    p, s = variables["params"], variables["batch_stats"]["bn1"]
    mip = max(8, 40 // 32)
    assert p["conv1"]["kernel"].shape == (1, 1, 40, mip)
    assert sum(a.size for a in jax.tree_util.tree_leaves(p)) == 3 * 40 * mip + 3 * mip + 2 * 40

    def conv(name, v):
        return v @ np.asarray(p[name]["kernel"][0, 0]) + np.asarray(p[name]["bias"])

    y = conv("conv1", np.concatenate([x.mean(2), x.mean(1)], axis=1))  # (B, H + W, mip)
    y = (y - np.asarray(s["mean"])) / np.sqrt(np.asarray(s["var"]) + 1e-5) * np.asarray(p["bn1"]["scale"]) \
        + np.asarray(p["bn1"]["bias"])
    y = y * np.clip(y + 3, 0, 6) / 6
    sigmoid = lambda v: 1 / (1 + np.exp(-v))
    a_h, a_w = sigmoid(conv("conv_h", y[:, :5])), sigmoid(conv("conv_w", y[:, 5:]))
    want = x * a_h[:, :, None, :] * a_w[:, None, :, :]
    np.testing.assert_allclose(ca.apply(variables, jnp.asarray(x)), want, rtol=1e-5, atol=1e-6)


def test_resize_shrinks_by_area_and_grows_by_repetition():
    x = jnp.arange(16.0).reshape(1, 4, 4, 1)
    np.testing.assert_array_equal(resize_to(x, (2, 2))[0, :, :, 0], [[2.5, 4.5], [10.5, 12.5]])
    np.testing.assert_array_equal(resize_to(x, (8, 8))[0, ::2, ::2, 0], x[0, :, :, 0])
    assert resize_to(x, (3, 5)).shape == (1, 3, 5, 1)


@pytest.mark.parametrize("change,match", [
    (dict(scale="xl"), "scale"),
    (dict(adapter_input="rgb"), "adapter_input"),
    (dict(adapter_input="gray", adapter_layout=(1, 3)), "adapter_layout"),
    (dict(adapter_input="gray", exchanger_positions=(2, 3)), "exchanger_positions"),
    (dict(adapter_input="gray", fusion=(1, 2)), "fusion"),
])
def test_bad_configs_name_the_field(change, match):
    with pytest.raises(ValueError, match=match):
        dataclasses.replace(VARIANTS["yolov8n"], **change)


def test_input_sides_must_be_multiples_of_32():
    with pytest.raises(ValueError, match="multiple of 32"):
        shapes(VARIANTS["yolov8n"], hw=(80, 32))
