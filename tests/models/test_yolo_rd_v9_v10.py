"""YOLOv9t and YOLOv10n bases and the Adapter on them: parameter counts against ultralytics and the
paper's Table 4, Adapter-at-init == base, output shapes, and the new layers' facts."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax.layers.yolo import PaddedConv
from dsfec_jax.layers.yolo_gelan import ADown, AConv
from dsfec_jax.layers.yolo_v10 import Attention, DepthwiseConv
from dsfec_jax.models.yolo_rd.head_v10 import V10DetectHead
from dsfec_jax.models.yolo_rd.net import SHARED_SUBTREES, inference_maps, with_base_weights
from dsfec_jax.models.yolo_rd.paper import TABLE4
from dsfec_jax.models.yolo_rd.variants import VARIANTS
from conftest import random_fill

TINY_HW = (64, 32)
quick_jit = functools.partial(jax.jit, compiler_options={"xla_backend_optimization_level": 0})
COCO80 = tuple(f"class{i}" for i in range(80))


@functools.lru_cache(maxsize=None)
def shapes(cfg, hw=TINY_HW, batch: int = 1):
    """(output shapes, variable shapes) without compiling anything."""
    x = {k: jnp.asarray(v) for k, v in cfg.dummy_inputs(batch, 0, hw=hw).items()}
    return jax.eval_shape(cfg.build().init_with_output, jax.random.key(0), x)


def size(tree) -> int:
    return sum(int(np.prod(a.shape)) for a in jax.tree_util.tree_leaves(tree))


def n_params(cfg) -> int:
    return size(shapes(cfg)[1]["params"])


def fused_count(tree) -> int:
    """Parameters after ultralytics' `fuse()`: every BN folded into its conv (C fewer each), every
    RepConvN's 1x1 branch folded into its 3x3 and every RepVGGDW's 3x3 into its 7x7 (the folded
    branch's weights and one bias fewer). v10Detect keeps both heads, as THU-MIG's summaries do."""
    if not isinstance(tree, dict):
        return int(np.prod(tree.shape))
    total = sum(fused_count(v) for k, v in tree.items() if k != "scale")
    kernel = lambda name: tree[name]["conv"]["kernel"].shape
    if {"conv1", "conv2"} <= set(tree) and "conv" in tree["conv2"] and kernel("conv2")[:2] == (1, 1):
        total -= int(np.prod(kernel("conv2"))) + kernel("conv2")[-1]  # RepConvN
    if {"conv", "conv1"} <= set(tree) and "conv" in tree["conv"] and kernel("conv")[0] == 7:
        total -= int(np.prod(kernel("conv1"))) + kernel("conv1")[-1]  # RepVGGDW
    return total


# Trainable parameters at nc = 6, pinned (the nc = 80 counts below reproduce ultralytics' exactly)
NC6 = {"yolov9t": 2_006_562, "yolov10n": 2_709_364, "yolov9t_adapter": 2_197_176, "yolov10n_adapter": 2_945_418}
# ... and after ultralytics' fuse(): what the paper's Table 4 prints (1.97, 2.70, 2.16, 2.93 M)
FUSED_NC6 = {"yolov9t": 1_971_938, "yolov10n": 2_696_740, "yolov9t_adapter": 2_161_568,
             "yolov10n_adapter": 2_931_650}
# ultralytics at nc = 80, less the 16 frozen DFL weights: yolov9t.yaml "2128720 parameters";
# YOLOv10n "2,775,520 parameters" (both heads; ultralytics issue 20191) and "(fused) 2762608"
# (THU-MIG/yolov10 issue 503)
NC80 = {"yolov9t": 2_128_704, "yolov10n": 2_775_504}
FUSED_NC80_V10N = 2_762_592


@pytest.mark.parametrize("name", sorted(NC6))
def test_counts_at_nc6_are_pinned(name):
    assert n_params(VARIANTS[name]) == NC6[name]


@pytest.mark.parametrize("name", sorted(FUSED_NC6))
def test_fused_counts_are_the_papers_table4(name):
    fused = fused_count(shapes(VARIANTS[name])[1]["params"])
    assert fused == FUSED_NC6[name]
    assert round(fused / 1e6, 2) == TABLE4["RADDet"][name]["params"]
    assert abs(NC6[name] / (TABLE4["RADDet"][name]["params"] * 1e6) - 1) < 0.03  # unfused: within 3 %


@pytest.mark.parametrize("name", sorted(NC80))
def test_counts_at_nc80_match_ultralytics(name):
    assert n_params(dataclasses.replace(VARIANTS[name], classes=COCO80)) == NC80[name]


def test_yolov10n_heads_at_nc80():
    """Fused with both heads: THU-MIG's summary; the one-to-one head alone: the YOLOv10 paper's 2.3 M."""
    params = shapes(dataclasses.replace(VARIANTS["yolov10n"], classes=COCO80))[1]["params"]
    assert fused_count(params) == FUSED_NC80_V10N
    assert size(params["head"]["one2one"]) == size(params["head"]["one2many"]) == 464_896
    assert round((size(params) - size(params["head"]["one2many"])) / 1e6, 1) == 2.3


@pytest.mark.parametrize("base", ("yolov9t", "yolov10n"))
def test_adapter_adds_the_same_design(base):
    """Stem + seven Exchangers after backbone layers 2-8; v10n's backbone widths there are v8n's."""
    tree = shapes(VARIANTS[f"{base}_adapter"])[1]["params"]["adapter"]
    assert set(tree) == {"stem"} | {f"exchangers_{k}" for k in range(7)}
    assert size(tree) == NC6[f"{base}_adapter"] - NC6[base]
    assert size(tree) == {"yolov9t": 190_614, "yolov10n": 236_054}[base]  # yolov8n's Adapter: 236,054


def test_output_shapes_for_a_256x64_map():
    no = 4 * 16 + 6
    want = [(2, 32, 8, no), (2, 16, 4, no), (2, 8, 2, no)]
    outs, _ = shapes(VARIANTS["yolov9t_adapter"], hw=(256, 64), batch=2)
    assert [o.shape for o in outs] == want
    outs, _ = shapes(VARIANTS["yolov10n_adapter"], hw=(256, 64), batch=2)
    assert set(outs) == {"one2many", "one2one"}
    assert [o.shape for o in outs["one2many"]] == [o.shape for o in inference_maps(outs)] == want


def random_variables(cfg, seed: int) -> dict:
    """Random weights and BN statistics from the shapes; the Adapter's alpha and gamma at their 0."""
    return random_fill(shapes(cfg)[1], seed, scale_range=(0.5, 1.5), var_range=(0.5, 1.5), zeros=("alpha", "gamma"))


@pytest.mark.parametrize("base", ("yolov9t", "yolov10n"))
def test_adapter_at_init_equals_the_base_with_the_same_weights(base):
    base_cfg, adapter_cfg = VARIANTS[base], VARIANTS[f"{base}_adapter"]
    for collection in ("params", "batch_stats"):
        for name in SHARED_SUBTREES:
            assert jax.tree.map(jnp.shape, shapes(base_cfg)[1][collection][name]) == \
                jax.tree.map(jnp.shape, shapes(adapter_cfg)[1][collection][name])
    base_vars = random_variables(base_cfg, 1)
    adapter_vars = with_base_weights(random_variables(adapter_cfg, 2), base_vars)
    x = {k: jnp.asarray(v) for k, v in adapter_cfg.dummy_inputs(1, 3, hw=TINY_HW).items()}
    want = jax.tree.leaves(quick_jit(base_cfg.build().apply)(base_vars, x))
    run_adapter = quick_jit(adapter_cfg.build().apply)
    assert len(want) == (6 if base == "yolov10n" else 3) and all(np.isfinite(np.asarray(o)).all() for o in want)
    assert all(np.array_equal(a, b) for a, b in zip(jax.tree.leaves(run_adapter(adapter_vars, x)), want))
    # the check can fail: a non-zero alpha in the first (mode-1) Exchanger changes the detector
    adapter = dict(adapter_vars["params"]["adapter"])
    adapter["exchangers_0"] = {**adapter["exchangers_0"], "alpha": jnp.float32(0.5)}
    moved = run_adapter({**adapter_vars, "params": {**adapter_vars["params"], "adapter": adapter}}, x)
    assert not any(np.allclose(a, b) for a, b in zip(jax.tree.leaves(moved), want))


def test_v10_one2one_head_reads_detached_features_and_both_heads_get_the_bias_init():
    head = V10DetectHead(6, strides=(32,))
    feats = (jnp.asarray(np.random.default_rng(0).normal(size=(1, 2, 2, 16)), jnp.float32),)
    variables = quick_jit(head.init)(jax.random.key(0), feats)
    for h in ("one2many", "one2one"):
        np.testing.assert_allclose(variables["params"][h]["box0_out"]["bias"], np.ones(64))
        np.testing.assert_allclose(variables["params"][h]["cls0_out"]["bias"], np.full(6, np.log(5 / 6 / 20**2)),
                                   rtol=1e-6)
    grad_of = lambda h: jax.grad(lambda f: jnp.sum(head.apply(variables, (f,))[h][0] ** 2))
    g_many, g_one = quick_jit(lambda f: (grad_of("one2many")(f), grad_of("one2one")(f)))(feats[0])
    assert not np.any(np.asarray(g_one)) and np.any(np.asarray(g_many))


def test_attention_matches_pytorch_layout_in_numpy():
    """ultralytics Attention in NCHW: qkv viewed (B, heads, 2 key_dim + head_dim, N), split q, k, v;
    softmax(q^T k * key_dim^-0.5) over keys; v @ attn^T viewed (B, C, H, W) + pe(v); proj."""
    rng = np.random.default_rng(0)
    b, h, w, dim, heads = 2, 3, 2, 16, 2
    x = rng.normal(size=(b, h, w, dim)).astype(np.float32)
    att = Attention(heads)
    variables = jax.tree.map(lambda a: jnp.asarray(rng.uniform(0.5, 1.5, a.shape), jnp.float32),
                             quick_jit(att.init)(jax.random.key(0), jnp.asarray(x)))
    p, s = variables["params"], variables["batch_stats"]

    def conv_bn(name, v_BxCxN, depthwise=False):
        kernel = np.asarray(p[name]["conv"]["kernel"])
        if depthwise:  # 3x3 per channel, zero padding 1, on (B, C, H, W)
            img = np.pad(v_BxCxN.reshape(b, -1, h, w), ((0, 0), (0, 0), (1, 1), (1, 1)))
            y = sum(img[:, :, i:i + h, j:j + w] * kernel[i, j, 0][None, :, None, None]
                    for i in range(3) for j in range(3)).reshape(b, -1, h * w)
        else:
            y = np.einsum("bcn,cd->bdn", v_BxCxN, kernel[0, 0])
        st, bn = s[name]["bn"], p[name]["bn"]
        return ((y - np.asarray(st["mean"])[:, None]) / np.sqrt(np.asarray(st["var"])[:, None] + 1e-3)
                * np.asarray(bn["scale"])[:, None] + np.asarray(bn["bias"])[:, None])

    head_dim, key_dim = dim // heads, dim // heads // 2
    x_nchw = x.transpose(0, 3, 1, 2).reshape(b, dim, h * w)
    qkv = conv_bn("qkv", x_nchw).reshape(b, heads, 2 * key_dim + head_dim, h * w)
    q, k, v = qkv[:, :, :key_dim], qkv[:, :, key_dim:2 * key_dim], qkv[:, :, 2 * key_dim:]
    logits = np.einsum("bhdi,bhdj->bhij", q, k) * key_dim**-0.5
    attn = np.exp(logits - logits.max(-1, keepdims=True))
    attn /= attn.sum(-1, keepdims=True)
    y = np.einsum("bhdj,bhij->bhdi", v, attn).reshape(b, dim, h * w)
    y = conv_bn("proj", y + conv_bn("pe", v.reshape(b, dim, h * w), depthwise=True))
    want = y.reshape(b, dim, h, w).transpose(0, 2, 3, 1)
    np.testing.assert_allclose(att.apply(variables, jnp.asarray(x)), want, rtol=1e-4, atol=1e-5)


def test_depthwise_conv_is_one_padded_conv_per_channel():
    rng = np.random.default_rng(0)
    x = jnp.asarray(rng.normal(size=(1, 7, 6, 3)), jnp.float32)
    kernel = jnp.asarray(rng.normal(size=(3, 3, 1, 3)), jnp.float32)
    y = DepthwiseConv(3, 2).apply({"params": {"kernel": kernel}}, x)
    for c in range(3):
        one = PaddedConv(1, 3, 2).apply({"params": {"kernel": kernel[:, :, :, c:c + 1]}}, x[..., c:c + 1])
        np.testing.assert_allclose(y[..., c:c + 1], one, rtol=1e-5, atol=1e-6)


def test_aconv_and_adown_halve_like_pytorch():
    """avg_pool2d(2, 1) then a stride-2 3x3 conv padded by 1: output (i, j) is the mean of the input's
    2x2 block at (2i, 2j) through the kernel's centre tap; ADown: half conv, half max pool + 1x1."""
    x = jnp.asarray(np.random.default_rng(0).normal(size=(1, 8, 6, 4)), jnp.float32)
    aconv = AConv(1)
    kernel = jnp.zeros((3, 3, 4, 1)).at[1, 1, 0, 0].set(1.0)
    variables = {"params": {"cv1": {"conv": {"kernel": kernel}, "bn": {"scale": jnp.ones(1), "bias": jnp.zeros(1)}}},
                 "batch_stats": {"cv1": {"bn": {"mean": jnp.zeros(1), "var": jnp.ones(1)}}}}
    block_means = x[0, :, :, 0].reshape(4, 2, 3, 2).mean(axis=(1, 3))
    np.testing.assert_allclose(aconv.apply(variables, x)[0, :, :, 0],
                               jax.nn.silu(block_means / np.sqrt(1 + 1e-3)), rtol=1e-5, atol=1e-6)
    out, adown = jax.eval_shape(ADown(10).init_with_output, jax.random.key(0), x)
    assert out.shape == (1, 4, 3, 10)
    assert size(adown["params"]) == (9 * 2 * 5 + 2 * 5) + (2 * 5 + 2 * 5)  # 3x3 conv + BN, 1x1 conv + BN


@pytest.mark.parametrize("change,match", [
    (dict(arch="v11"), "arch"),
    (dict(arch="v9", scale="n"), "scale"),
    (dict(arch="v10", scale="s"), "scale"),
    (dict(arch="v10", adapter_input="gray", exchanger_positions=(2, 3, 4, 5, 6, 7, 11)), "exchanger_positions"),
])
def test_bad_arch_configs_name_the_field(change, match):
    with pytest.raises(ValueError, match=match):
        dataclasses.replace(VARIANTS["yolov8n"], **change)


def test_v10_exchangers_may_follow_psa():
    cfg = dataclasses.replace(VARIANTS["yolov10n_adapter"], exchanger_positions=(2, 3, 4, 5, 6, 7, 10))
    assert shapes(cfg)[1]["params"]["adapter"]["exchangers_6"]["project"]["conv"]["kernel"].shape == (1, 1, 128, 256)
