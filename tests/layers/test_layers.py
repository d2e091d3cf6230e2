import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax.core.grid import Grid
from dsfec_jax.layers import (ACTIVATIONS, FEC, DepthwiseConv, ResidualBottleneck, activation,
                              check_fec_filters, decorate_points, masked_max, scatter_to_bev)


@pytest.mark.parametrize("stride", [1, 2])
@pytest.mark.parametrize("size", [(8, 8), (9, 7), (16, 12)])
def test_shifted_and_grouped_depthwise_agree(stride, size):
    x = jax.random.normal(jax.random.key(1), (2, *size, 5))
    shifted = DepthwiseConv(3, stride, "shifted")
    variables = shifted.init(jax.random.key(0), x)
    a = shifted.apply(variables, x)
    b = DepthwiseConv(3, stride, "grouped").apply(variables, x)
    assert a.shape == b.shape == (2, -(-size[0] // stride), -(-size[1] // stride), 5)
    np.testing.assert_allclose(a, b, atol=1e-5, rtol=1e-5)


def test_activation_names():
    assert set(ACTIVATIONS) >= {"relu", "leaky_relu", "swish", "mish", "hard_swish", "gelu"}
    x = jnp.array([-2.0, 0.0, 3.0])
    np.testing.assert_allclose(activation("leaky_relu")(x), [-0.2, 0.0, 3.0], rtol=1e-6)
    np.testing.assert_allclose(activation("mish")(x)[2], 3 * np.tanh(np.log1p(np.exp(3.0))), rtol=1e-6)
    with pytest.raises(ValueError, match="unknown activation 'elu'.*relu"):
        activation("elu")


@pytest.mark.parametrize("filters,broken", [((32, 16, 12), "f1 < f2"), ((32, 128, 128), "f2 > f3"),
                                            ((12, 128, 32), "f1 >= f3")])
def test_fec_rule_names_the_broken_values(filters, broken):
    with pytest.raises(ValueError, match=broken) as err:
        check_fec_filters(filters)
    assert str(filters[0]) in str(err.value) and str(filters[2]) in str(err.value)
    with pytest.raises(ValueError):
        FEC(filters).init(jax.random.key(0), jnp.zeros((1, 2, 3, 13)))


def test_fec_is_three_pointwise_layers_without_batch_norm():
    variables = FEC((32, 128, 12)).init(jax.random.key(0), jnp.zeros((1, 4, 3, 13)))
    assert "batch_stats" not in variables
    shapes = jax.tree.map(lambda a: a.shape, variables["params"])
    assert shapes == {"conv1": {"kernel": (13, 32), "bias": (32,)}, "conv2": {"kernel": (32, 128), "bias": (128,)},
                      "conv3": {"kernel": (128, 12), "bias": (12,)}}


def test_decorate_points_offsets():
    grid = Grid((0.0, 4.0), (-2.0, 2.0), (-2.0, 2.0), 1.0)
    pts = np.zeros((1, 1, 2, 4), np.float32)
    pts[0, 0, 0, :3] = [2.2, 0.4, 1.0]
    pts[0, 0, 1, :3] = [2.6, 0.8, 0.0]
    coords = np.array([[[2, 2]]], np.int32)  # cell x in [2, 3), y in [0, 1)
    out = decorate_points(jnp.asarray(pts), jnp.array([[[True, True]]]), jnp.asarray(coords), grid)
    np.testing.assert_allclose(out[0, 0, 0, 4:7], [-0.2, -0.2, 0.5], atol=1e-6)   # to point mean
    np.testing.assert_allclose(out[0, 0, 0, 7:10], [-0.3, -0.1, 1.0], atol=1e-6)  # to pillar centre
    masked = decorate_points(jnp.asarray(pts), jnp.array([[[True, False]]]), jnp.asarray(coords), grid)
    assert float(jnp.abs(masked[0, 0, 1]).max()) == 0.0


def test_masked_max_ignores_padding_and_zeroes_empty_pillars():
    h = jnp.array([[[[1.0], [5.0]], [[-3.0], [-1.0]], [[7.0], [9.0]]]])
    mask = jnp.array([[[True, False], [True, True], [False, False]]])
    np.testing.assert_allclose(masked_max(h, mask)[0, :, 0], [1.0, -1.0, 0.0])


def test_scatter_places_pillars_and_drops_unused_slots():
    grid = Grid((0.0, 4.0), (-2.0, 2.0), (-2.0, 2.0), 1.0)
    feats = jnp.arange(1, 7, dtype=jnp.float32).reshape(1, 3, 2)
    coords = jnp.array([[[0, 3], [2, 1], [-1, -1]]])
    bev = scatter_to_bev(feats, coords, grid)
    assert bev.shape == (1, 4, 4, 2)
    np.testing.assert_allclose(bev[0, 0, 3], [1, 2])
    np.testing.assert_allclose(bev[0, 2, 1], [3, 4])
    assert float(bev.sum()) == 10.0


def test_residual_bottleneck_projects_when_shape_changes():
    x = jnp.ones((1, 8, 8, 16))
    block = ResidualBottleneck(32, stride=2)
    variables = block.init(jax.random.key(0), x)
    assert "proj" in variables["params"]
    assert block.apply(variables, x).shape == (1, 4, 4, 32)
    same = ResidualBottleneck(16, stride=1).init(jax.random.key(0), x)
    assert "proj" not in same["params"]


@pytest.mark.parametrize("cin,features,kernel,stride,depthwise,branches,size", [
    (8, 8, 3, 1, True, 1, 9),    # depthwise, stride 1: conv + scale + identity (3 branches)
    (8, 8, 3, 2, True, 1, 10),   # depthwise, stride 2, even size: conv + scale (2 branches)
    (8, 8, 3, 2, True, 2, 9),    # k = 2 conv branches, odd size
    (8, 8, 1, 1, False, 1, 8),   # pointwise, C_in == C_out: conv + identity
    (8, 16, 1, 1, False, 1, 8),  # pointwise widening: conv only
    (8, 16, 3, 2, False, 3, 7),  # dense 3x3, k = 3
])
def test_mobileone_fused_equals_unfused(cin, features, kernel, stride, depthwise, branches, size):
    import jax
    import numpy as np
    from dsfec_jax.layers.mobileone import MobileOneBlock, reparameterize_block

    x = jax.random.normal(jax.random.key(0), (2, size, size, cin))
    block = MobileOneBlock(features, kernel, stride, depthwise, branches)
    variables = block.init(jax.random.key(1), x)
    rng = np.random.default_rng(2)  # non-trivial running statistics, as after training
    stats = jax.tree_util.tree_map_with_path(
        lambda p, v: rng.uniform(0.5, 2.0, v.shape) if p[-1].key == "var" else rng.normal(0, 0.5, v.shape),
        variables["batch_stats"])
    params = jax.tree.map(lambda v: v + rng.normal(0, 0.1, v.shape), variables["params"])  # BN beta != 0
    unfused = block.apply({"params": params, "batch_stats": stats}, x)
    deploy = MobileOneBlock(features, kernel, stride, depthwise, branches, deploy=True)
    fused_vars = reparameterize_block(block, cin, params, stats)
    fused = deploy.apply(fused_vars, x)
    assert fused.shape == unfused.shape == (2, -(-size // stride), -(-size // stride), features)
    np.testing.assert_allclose(fused, unfused, atol=1e-5, rtol=1e-5)
    grouped = MobileOneBlock(features, kernel, stride, depthwise, branches, deploy=True, depthwise_impl="grouped")
    np.testing.assert_allclose(grouped.apply(fused_vars, x), fused, atol=1e-5)
    n_branches = len([k for k in variables["batch_stats"]])
    assert n_branches == branches + (kernel > 1) + (cin == features and stride == 1)


def _bilinear_reference(img_HxWxC, y: float, x: float):
    """Zeros outside the map: the grid_sample(padding_mode='zeros') convention DCNv3 uses."""
    import math as m
    h, w, _ = img_HxWxC.shape
    acc = np.zeros(img_HxWxC.shape[-1])
    for yy in (m.floor(y), m.floor(y) + 1):
        for xx in (m.floor(x), m.floor(x) + 1):
            if 0 <= yy < h and 0 <= xx < w:
                acc += (1 - abs(y - yy)) * (1 - abs(x - xx)) * img_HxWxC[yy, xx]
    return acc


def test_dcnv3_sampling_matches_a_per_point_reference():
    from dsfec_jax.layers.dcnv3 import deformable_sample

    rng = np.random.default_rng(0)
    b, h, w, g, c, s = 2, 5, 6, 2, 3, 2.0
    value = rng.normal(size=(b, h, w, g, c)).astype(np.float32)
    offset = rng.normal(0, 1.5, size=(b, h, w, g, 9, 2)).astype(np.float32)  # many taps fall outside
    mask = rng.dirichlet(np.ones(9), size=(b, h, w, g)).astype(np.float32)
    ref = np.zeros((b, h, w, g, c))
    for bi in range(b):
        for i in range(h):
            for j in range(w):
                for gi in range(g):
                    for p in range(9):
                        kx, ky = p // 3 - 1, p % 3 - 1  # x-major point order
                        xs = j + s * (kx + offset[bi, i, j, gi, p, 0])
                        ys = i + s * (ky + offset[bi, i, j, gi, p, 1])
                        ref[bi, i, j, gi] += mask[bi, i, j, gi, p] * _bilinear_reference(value[bi, :, :, gi], ys, xs)
    out = np.asarray(deformable_sample(value, offset, mask, s))
    np.testing.assert_allclose(out, ref.reshape(b, h, w, g * c), atol=1e-5)
    # zero offsets and all weight on the centre point read the map itself
    centre = np.zeros_like(mask)
    centre[..., 4] = 1.0
    np.testing.assert_allclose(deformable_sample(value, np.zeros_like(offset), centre, s),
                               value.reshape(b, h, w, g * c), atol=1e-6)


def test_dcnv3_layer_shapes_and_zero_initialised_offsets():
    import jax
    from dsfec_jax.layers.dcnv3 import DCNv3

    x = jax.random.normal(jax.random.key(0), (1, 8, 8, 16))
    layer = DCNv3(16, groups=4)
    variables = layer.init(jax.random.key(1), x)
    assert layer.apply(variables, x).shape == (1, 8, 8, 16)
    assert not np.any(variables["params"]["offset"]["kernel"]) and not np.any(variables["params"]["mask"]["kernel"])
    grads = jax.grad(lambda v: layer.apply(v, x).sum())(variables)
    assert np.any(grads["params"]["offset"]["kernel"])  # offsets learn through the bilinear weights
    with pytest.raises(ValueError, match="multiple of groups"):
        DCNv3(18, groups=4).init(jax.random.key(1), jax.numpy.zeros((1, 4, 4, 18)))


def test_pointpillars_batch_norm_stays_finite_on_a_batch_without_points():
    from dsfec_jax.layers.pillars import PointPillarsEncoder

    enc = PointPillarsEncoder(8)
    x, mask = jnp.zeros((2, 4, 3, 13)), jnp.zeros((2, 4, 3), bool)
    variables = enc.init(jax.random.key(0), x, mask)
    out, updates = enc.apply(variables, x, mask, train=True, mutable=["batch_stats"])
    assert bool(jnp.isfinite(out).all()) and all(bool(jnp.isfinite(v).all()) for v in jax.tree.leaves(updates))
