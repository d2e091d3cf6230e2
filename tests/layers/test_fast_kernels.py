"""The fast CPU-training formulations (layers/conv.py, kernels="fast") give the values and the
gradients of the plain ones (kernels="plain"), layer by layer and on whole small models."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import lax

from dsfec_jax.layers import Conv, ConvTranspose, DepthwiseConv
from dsfec_jax.layers.conv import (DIMS, FAST_CONV_MIN_CHANNELS, PointLinear, conv_kernel_grad, fast_conv, fast_shifted_depthwise,
                                   plain_conv, pointwise_conv, shifted_depthwise, subpixel_conv_transpose)
from dsfec_jax.models.dsfec.loss import LossConfig, detection_loss
from conftest import as_float64, random_variables, tiny
from train.test_train_step import toy_batch

RTOL = 1e-4  # the bar: relative error of gradients, float32


def rel_err(a, b) -> float:
    """Relative L2 error of a against b over a whole pytree."""
    num = sum(float(jnp.sum((x - y) ** 2)) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))
    den = sum(float(jnp.sum(y ** 2)) for y in jax.tree.leaves(b))
    return (num / den) ** 0.5


def assert_leaves_close(fast, plain):
    """Leaf by leaf, so that no small layer hides behind a large one. A leaf whose gradient is
    zero in exact arithmetic (a conv bias right before batch norm) holds only rounding (~1e-14
    in float64): it is held to the whole tree's scale instead of its own."""
    floor = 1e-9 * max(float(jnp.abs(p).max()) for p in jax.tree.leaves(plain))
    for (path, p), f in zip(jax.tree_util.tree_flatten_with_path(plain)[0], jax.tree.leaves(fast)):
        scale = max(float(jnp.abs(p).max()), floor)
        assert float(jnp.abs(f - p).max()) / scale < RTOL, jax.tree_util.keystr(path)


def grads(fn, *args):
    """Value and gradients (every argument) of sum(sin(fn(*args))): a loss whose output gradient
    differs from pixel to pixel, so every tap and phase is exercised."""
    loss = lambda *a: jnp.sum(jnp.sin(fn(*a)))  # noqa: E731
    return fn(*args), jax.grad(loss, argnums=tuple(range(len(args))))(*args)


@pytest.mark.parametrize("shape,stride", [((2, 7, 9, 3), 1), ((3, 8, 8, 4), 2), ((2, 9, 6, 5), 2),
                                          ((1, 5, 5, 2), 3), ((3, 6, 6, 2), 1)])
def test_depthwise_gradient_equals_autodiff(shape, stride):
    x = jax.random.normal(jax.random.key(0), shape)
    w = jax.random.normal(jax.random.key(1), (3, 3, shape[-1]))
    plain_y, plain_g = grads(lambda x, w: shifted_depthwise(x, w, stride), x, w)
    fast_y, fast_g = grads(lambda x, w: fast_shifted_depthwise(x, w, stride), x, w)
    np.testing.assert_array_equal(fast_y, plain_y)
    assert rel_err(fast_g, plain_g) < RTOL
    assert rel_err(jax.jit(jax.grad(lambda x, w: jnp.sum(jnp.sin(fast_shifted_depthwise(x, w, stride))),
                                    (0, 1)))(x, w), plain_g) < RTOL


@pytest.mark.parametrize("shape,stride,kernel", [((2, 8, 8, 3), 2, 3), ((3, 7, 9, 2), 1, 3), ((2, 9, 9, 2), 2, 5)])
def test_depthwise_gradient_with_symmetric_pads(shape, stride, kernel):
    """MobileOne's padding (K // 2 on both sides, PyTorch's), not TF 'SAME'."""
    x = jax.random.normal(jax.random.key(2), shape)
    w = jax.random.normal(jax.random.key(3), (kernel, kernel, shape[-1]))
    pads = (kernel // 2, kernel // 2)
    plain_y, plain_g = grads(lambda x, w: shifted_depthwise(x, w, stride, pads), x, w)
    fast_y, fast_g = grads(lambda x, w: fast_shifted_depthwise(x, w, stride, pads), x, w)
    np.testing.assert_array_equal(fast_y, plain_y)
    assert rel_err(fast_g, plain_g) < RTOL


@pytest.mark.parametrize("dtype,tol", [(jnp.float32, 1e-5), (jnp.float64, 1e-12)])
@pytest.mark.parametrize("shape,stride,kernel,pads", [((2, 7, 9, 3), 1, 3, None), ((3, 8, 8, 4), 2, 3, None),
                                                      ((1, 9, 6, 5), 3, 3, None), ((2, 9, 9, 2), 2, 5, (2, 2)),
                                                      ((2, 6, 7, 3), 1, 3, (1, 1))])
def test_depthwise_kernel_gradient_loop_runs_in_the_program_and_equals_xlas(shape, stride, kernel, pads, dtype, tol,
                                                                          float64):
    """On the CPU the kernel gradient is the compiled loop (an XLA custom call in the program), with
    XLA's own formulation's values, bit for bit the same on a second call."""
    from dsfec_jax.layers import conv

    x = jax.random.normal(jax.random.key(4), shape, dtype)
    _, ho, wo = conv._padded(x, kernel, stride, pads)  # the output size
    g = jax.random.normal(jax.random.key(5), (shape[0], ho, wo, shape[-1]), dtype)
    loop = jax.jit(lambda x, g: conv._depthwise_kernel_grad(x, g, kernel, stride, pads))
    assert "dsfec_depthwise_kernel_grad" in loop.lower(x, g).as_text()
    got, reference = loop(x, g), conv._xla_depthwise_kernel_grad(x, g, kernel, stride, pads)
    assert got.shape == (kernel, kernel, shape[-1]) and got.dtype == dtype
    assert float(jnp.abs(got - reference).max() / jnp.abs(reference).max()) < tol
    np.testing.assert_array_equal(loop(x, g), got)


def test_depthwise_kernel_gradient_of_other_dtypes_stays_in_xla():
    from dsfec_jax.layers import conv

    x = jnp.ones((1, 5, 5, 2), jnp.bfloat16)
    lowered = jax.jit(lambda x: conv._depthwise_kernel_grad(x, x, 3, 1, None)).lower(x).as_text()
    assert "dsfec_depthwise_kernel_grad" not in lowered


def force_winograd(monkeypatch, on: bool) -> None:
    """The thresholds that pick `fast_conv`'s backward: Winograd's for every 3x3 (both gradients)
    or for none, whatever the channels and the image size."""
    from dsfec_jax.layers import conv

    monkeypatch.setattr(conv, "WINOGRAD_MIN_CHANNELS", 1 if on else 10**9)
    monkeypatch.setattr(conv, "WINOGRAD_INPUT_GRAD_MIN_PIXELS", 0 if on else 10**9)


@pytest.fixture(params=["per_image", "whole_batch", "winograd"])
def kernel_grad_path(request, monkeypatch):
    """Every form of the dense conv's backward: the thresholds pick one for any image size and
    channel count (Winograd's: 3x3 kernels only, the others take the tap products)."""
    from dsfec_jax.layers import conv

    monkeypatch.setattr(conv, "PER_IMAGE_KERNEL_GRAD_MIN_PIXELS", 0 if request.param == "per_image" else 10**9)
    force_winograd(monkeypatch, request.param == "winograd")
    return request.param


@pytest.mark.parametrize("shape,kernel,cout", [((2, 7, 9, 16), 3, 16), ((3, 6, 5, 17), 3, 20),
                                              ((1, 8, 8, 16), 5, 18), ((2, 6, 7, 16), 2, 16), ((2, 5, 5, 3), 1, 4)])
def test_dense_conv_kernel_gradient_equals_autodiff(shape, kernel, cout, kernel_grad_path):
    """The tap products, per image or over the whole batch, give XLA's kernel gradient: odd and
    even kernels ('SAME' pads low and high unequal), odd sizes, batch 1-3."""
    x = jax.random.normal(jax.random.key(4), shape)
    w = jax.random.normal(jax.random.key(5), (kernel, kernel, shape[-1], cout)) * 0.2
    plain_y, plain_g = grads(plain_conv, x, w)
    fast_y, fast_g = grads(fast_conv, x, w)
    np.testing.assert_array_equal(fast_y, plain_y)
    assert rel_err(fast_g[0], plain_g[0]) < RTOL and rel_err(fast_g[1], plain_g[1]) < RTOL
    # the test can fail: taps read one pixel off give a far-off kernel gradient (a 1x1 kernel's
    # gradient, a sum over pixels, does not see a shift)
    shifted = jnp.roll(x, 1, axis=2)
    assert kernel == 1 or rel_err(jax.grad(lambda w: jnp.sum(jnp.sin(fast_conv(shifted, w))))(w), plain_g[1]) > 1e-2


@pytest.mark.parametrize("pads", [((1, 0), (1, 0)), ((0, 2), (1, 1)), ((2, 1), (0, 0))])
def test_dense_conv_kernel_gradient_with_explicit_pads(pads, kernel_grad_path):
    """The sub-pixel deconv's dense conv pads low and high unequally and its output is not
    the input's size."""
    x = jax.random.normal(jax.random.key(6), (2, 6, 7, 16))
    w = jax.random.normal(jax.random.key(7), (2, 2, 16, 12)) * 0.2
    plain_y, plain_g = grads(lambda x, w: plain_conv(x, w, pads), x, w)
    fast_y, fast_g = grads(lambda x, w: fast_conv(x, w, pads), x, w)
    np.testing.assert_array_equal(fast_y, plain_y)
    assert rel_err(fast_g[0], plain_g[0]) < RTOL and rel_err(fast_g[1], plain_g[1]) < RTOL
    # can fail: for a fixed output gradient, the other side's padding pairs it with other taps
    g = jax.random.normal(jax.random.key(8), plain_y.shape)
    swapped = tuple(p[::-1] for p in pads)
    assert rel_err(conv_kernel_grad(x, g, 2, swapped), conv_kernel_grad(x, g, 2, pads)) > 1e-2


@pytest.mark.parametrize("shape", [(2, 7, 9, 5), (3, 4, 6), (11, 8)])
def test_pointwise_conv_gradient_equals_autodiff(shape):
    x = jax.random.normal(jax.random.key(8), shape)
    w = jax.random.normal(jax.random.key(9), (shape[-1], 6))
    plain_y, plain_g = grads(jnp.dot, x, w)
    fast_y, fast_g = grads(pointwise_conv, x, w)
    np.testing.assert_array_equal(fast_y, plain_y)
    assert rel_err(fast_g[0], plain_g[0]) < RTOL and rel_err(fast_g[1], plain_g[1]) < RTOL
    assert "custom_vjp_call" in str(jax.make_jaxpr(pointwise_conv)(x, w))  # the hand-written backward runs


@pytest.mark.parametrize("kernel", [1, 2, 3, 4])
@pytest.mark.parametrize("stride", [1, 2, 3])
@pytest.mark.parametrize("fast_grad", [False, True, "winograd"])
def test_subpixel_upsampling_equals_conv_transpose(kernel, stride, fast_grad, monkeypatch):
    """"winograd": the dense conv's backward is Winograd's wherever its kernel is 3x3 (kernel 3
    at stride 1, kernel 4 at stride 2: the phases' taps make a 3x3 window)."""
    force_winograd(monkeypatch, fast_grad == "winograd")
    x = jax.random.normal(jax.random.key(kernel), (2, 5, 7, 3))
    w = jax.random.normal(jax.random.key(stride), (kernel, kernel, 3, 4))
    plain = lambda x, w: lax.conv_transpose(x, w, (stride, stride), "SAME", dimension_numbers=DIMS)  # noqa: E731
    plain_y, plain_g = grads(plain, x, w)
    fast_y, fast_g = grads(lambda x, w: subpixel_conv_transpose(x, w, stride, bool(fast_grad)), x, w)
    assert fast_y.shape == plain_y.shape == (2, 5 * stride, 7 * stride, 4)
    np.testing.assert_allclose(fast_y, plain_y, rtol=1e-5, atol=1e-5)
    assert rel_err(fast_g, plain_g) < RTOL


@pytest.mark.parametrize("module", [lambda k: Conv(6, 1, 1, use_bias=True, kernels=k),
                                    lambda k: Conv(6, 1, 2, kernels=k),
                                    lambda k: Conv(6, 3, 2, kernels=k),
                                    lambda k: Conv(FAST_CONV_MIN_CHANNELS, 3, 1, kernels=k),
                                    lambda k: DepthwiseConv(3, 2, kernels=k),
                                    lambda k: PointLinear(6, kernels=k),
                                    lambda k: PointLinear(6, use_bias=False, kernels=k),
                                    lambda k: ConvTranspose(5, 3, 2, kernels=k),
                                    lambda k: ConvTranspose(FAST_CONV_MIN_CHANNELS, 3, 2, kernels=k),
                                    lambda k: ConvTranspose(FAST_CONV_MIN_CHANNELS, 2, 2, kernels=k)])
def test_each_layer_fast_equals_plain(module):
    x = jax.random.normal(jax.random.key(0), (2, 7, 6, FAST_CONV_MIN_CHANNELS))
    variables = module("plain").init(jax.random.key(1), x)

    def run(kernels):
        return grads(lambda v, x: module(kernels).apply(v, x), variables, x)

    (plain_y, plain_g), (fast_y, fast_g) = run("plain"), run("fast")
    np.testing.assert_allclose(fast_y, plain_y, rtol=1e-5, atol=1e-5)
    assert rel_err(fast_g, plain_g) < RTOL


@pytest.mark.parametrize("kernels,hand_written", [("fast", True), ("plain", False)])
def test_point_linear_trains_with_the_pointwise_backward_only_when_fast(kernels, hand_written):
    x = jnp.ones((2, 5, 3, 7))
    layer = PointLinear(4, kernels=kernels)
    variables = layer.init(jax.random.key(0), x)
    assert ("custom_vjp_call" in str(jax.make_jaxpr(lambda v: layer.apply(v, x))(variables))) == hand_written


def test_an_unknown_kernels_value_names_the_field():
    with pytest.raises(ValueError, match="kernels='quick'.*'fast', 'plain'"):
        Conv(4, 1, kernels="quick").init(jax.random.key(0), jnp.zeros((1, 4, 4, 2)))
    with pytest.raises(ValueError, match="kernels"):
        tiny("dsfec_s", kernels="quick")


@pytest.mark.parametrize("name,winograd", [("dsfec_s", False), ("dsfec_s", True)])  # the Baseline: per-layer tests
def test_whole_model_training_gradients_equal(name, winograd, float64, monkeypatch):
    """The train-mode loss of a whole small network (FEC or PointPillars encoder, DSConv or
    residual backbone, deconv neck, heads) has the same gradients with either formulation; with
    `winograd`, every 3x3 stride-1 dense conv's backward is Winograd's (a tiny model's few
    channels would leave it to the tap products)."""
    from dsfec_jax.layers import winograd as winograd_module

    force_winograd(monkeypatch, winograd)
    original, calls = winograd_module.conv3x3_kernel_grad, []
    monkeypatch.setattr(winograd_module, "conv3x3_kernel_grad", lambda *a: calls.append(a) or original(*a))
    batch = as_float64(toy_batch(tiny(name)))
    plain, fast = tiny(name, kernels="plain"), tiny(name, kernels="fast")
    # random weights from eval_shape: `init` would compile the whole forward once more (~10 s)
    variables = as_float64(random_variables(plain, 0))
    loss_cfg = LossConfig()

    def loss_and_grads(det):
        def loss(params):
            outputs, _ = det.apply({**variables, "params": params}, batch["inputs"], train=True)
            return detection_loss(outputs, batch["targets"], loss_cfg)[0]
        return jax.jit(jax.value_and_grad(loss))(variables["params"])

    (plain_loss, plain_g), (fast_loss, fast_g) = loss_and_grads(plain), loss_and_grads(fast)
    assert bool(calls) == winograd  # the form under test is the one that ran
    assert jax.tree.leaves(fast_g)[0].dtype == jnp.float64
    assert float(fast_loss) == pytest.approx(float(plain_loss), rel=1e-10)
    assert rel_err(fast_g, plain_g) < RTOL
    # and leaf by leaf, so that no small layer hides behind a large one
    assert_leaves_close(fast_g, plain_g)


@pytest.mark.parametrize("name", ["radarnext_mdfen"])  # SECOND-FPN's k = s deconvs: the per-layer tests
def test_radarnext_training_gradients_equal(name, float64):
    """RadarNeXt (MobileOne depthwise with symmetric pads, 1x1 MobileOne convs as matmuls,
    kernel == stride deconvs): train-mode output gradients equal with either formulation.
    One Rep-DWC layer per backbone stage (13 backbone layers -> 3, a fraction of the compile
    time): each stage's stride-2 layer stays, and the neck's four stride-1 RepBlocks carry the
    identity branches and the stride-1 depthwise path that the backbone's further layers
    repeated; the PAN/MDFEN channels are fixed by the architecture, head and pillar net narrowed."""
    from dsfec_jax import zoo
    from dsfec_jax.core.grid import Grid

    tiny_grid = dict(grid=Grid((0.0, 5.12), (-2.56, 2.56), (-3.0, 2.0), 0.16), max_pillars=128,  # 32 x 32
                     layer_nums=(1, 1, 1), pillar_filters=16, head_width=16)
    plain, fast = zoo.create(name, kernels="plain", **tiny_grid), zoo.create(name, kernels="fast", **tiny_grid)
    # random weights (DCN offsets included) from eval_shape: `init` would compile the forward (~15 s)
    variables, inputs = as_float64(random_variables(plain, 0)), as_float64(plain.config.dummy_inputs(2, occupancy=0.3))

    def output_grads(det):
        def loss(params):
            outputs, _ = det.apply({**variables, "params": params}, inputs, train=True)
            return sum(jnp.sum(jnp.sin(o)) for o in jax.tree.leaves(outputs))
        return jax.jit(jax.grad(loss))(variables["params"])

    plain_g, fast_g = output_grads(plain), output_grads(fast)
    assert rel_err(fast_g, plain_g) < RTOL
    assert_leaves_close(fast_g, plain_g)


@pytest.mark.parametrize("kernels", ["fast", "plain"])
@pytest.mark.parametrize("shape,masked", [((3, 5, 7, 6), False), ((2, 40, 5), False), ((2, 40, 5), True)])
def test_batch_norm_equals_flax_in_values_statistics_and_gradients(kernels, shape, masked):
    """layers.batch_norm.BatchNorm holds flax's BatchNorm variables and computes its values:
    train outputs, the running-average update and the gradients (the fast one by its closed form)."""
    import flax.linen as nn

    from dsfec_jax.layers.batch_norm import BatchNorm

    x = jax.random.normal(jax.random.key(0), shape) * 3.0 + 1.5
    mask = (jax.random.uniform(jax.random.key(1), shape[:-1] + (1,)) > 0.3) if masked else None
    ours, flax_bn = BatchNorm(False, 0.9, 1e-3, kernels), nn.BatchNorm(use_running_average=False, momentum=0.9, epsilon=1e-3)
    variables = flax_bn.init(jax.random.key(2), x, mask=mask)
    assert jax.tree.structure(ours.init(jax.random.key(2), x, mask=mask)) == jax.tree.structure(variables)
    c = shape[-1]
    params = {"scale": jnp.linspace(0.5, 2.0, c), "bias": jnp.linspace(-1.0, 1.0, c)}
    stats = {"mean": jnp.linspace(-0.2, 0.3, c), "var": jnp.linspace(0.5, 1.5, c)}

    def run(module):
        def loss(p, x):
            y, updated = module.apply({"params": p, "batch_stats": stats}, x, mask=mask, mutable=["batch_stats"])
            weights = jnp.arange(y.size, dtype=y.dtype).reshape(y.shape) / y.size  # a different gradient per element
            return jnp.sum(jnp.sin(y) * weights), updated
        return jax.value_and_grad(loss, (0, 1), has_aux=True)(params, x)

    (ours_loss, ours_stats), ours_g = run(ours)
    (flax_loss, flax_stats), flax_g = run(flax_bn)
    assert float(ours_loss) == pytest.approx(float(flax_loss), rel=1e-6)
    for key in ("mean", "var"):
        np.testing.assert_allclose(ours_stats["batch_stats"][key], flax_stats["batch_stats"][key], rtol=1e-6)
    assert_leaves_close(ours_g, flax_g)
    # evaluation uses the running averages, in flax's order of operations: the same bits
    evaluated = [m.clone(use_running_average=True).apply({"params": params, "batch_stats": stats}, x)
                 for m in (ours, nn.BatchNorm(momentum=0.9, epsilon=1e-3))]
    np.testing.assert_array_equal(evaluated[0], evaluated[1])


@pytest.mark.parametrize("kernels,backend,switch,expected", [
    ("auto", "cpu", None, True), ("auto", "gpu", None, False), ("auto", "tpu", None, False),  # measured on the CPU only
    ("fast", "gpu", None, True), ("plain", "cpu", None, False),
    ("fast", "cpu", "off", False), ("auto", "cpu", "xla", False), ("auto", "cpu", "auto", True)])
def test_kernels_auto_picks_the_hand_written_ones_on_the_cpu_only(kernels, backend, switch, expected, monkeypatch):
    from dsfec_jax.layers import kernels as kernels_module

    monkeypatch.setattr(kernels_module.jax, "default_backend", lambda: backend)
    if switch is None:
        monkeypatch.delenv("DSFEC_KERNELS", raising=False)
    else:
        monkeypatch.setenv("DSFEC_KERNELS", switch)
    assert kernels_module.hand_written(kernels) is expected


def test_an_unknown_switch_value_names_the_variable(monkeypatch):
    monkeypatch.setenv("DSFEC_KERNELS", "fastest")
    with pytest.raises(ValueError, match="DSFEC_KERNELS='fastest'.*'off' or 'xla'"):
        Conv(4, 1).init(jax.random.key(0), jnp.zeros((1, 4, 4, 2)))


SWITCHED_LAYERS = [lambda k: Conv(FAST_CONV_MIN_CHANNELS, 1, kernels=k), lambda k: Conv(FAST_CONV_MIN_CHANNELS, 3, kernels=k),
                   lambda k: DepthwiseConv(3, 1, kernels=k), lambda k: ConvTranspose(FAST_CONV_MIN_CHANNELS, 3, 2, kernels=k),
                   lambda k: PointLinear(6, kernels=k)]


@pytest.mark.parametrize("layer", SWITCHED_LAYERS)
def test_the_switch_turns_every_hand_written_kernel_off(layer, monkeypatch):
    """DSFEC_KERNELS=off: a layer built "fast" (or "auto", the default, on this CPU) traces no
    hand-written formulation and its training step lowers to no custom call (the numba depthwise
    gradient is one); it computes the XLA formulation's gradients, which the hand-written ones
    match to RTOL."""
    x = jax.random.normal(jax.random.key(0), (1, 8, 8, FAST_CONV_MIN_CHANNELS))
    variables = layer("plain").init(jax.random.key(1), x)
    forward = lambda k: str(jax.make_jaxpr(lambda v: layer(k).apply(v, x))(variables))  # noqa: E731
    grad = lambda k: jax.jit(jax.grad(lambda v: jnp.sum(jnp.sin(layer(k).apply(v, x)))))  # noqa: E731
    monkeypatch.delenv("DSFEC_KERNELS", raising=False)
    assert "custom_vjp_call" in forward("auto") or "dot_general" in forward("auto")  # 1x1 convs: a matmul forward
    fast = grad("fast")(variables)
    if isinstance(layer("fast"), DepthwiseConv):  # the FFI call the switch must remove
        assert "custom_call @dsfec_depthwise_kernel_grad" in grad("auto").lower(variables).as_text()
    monkeypatch.setenv("DSFEC_KERNELS", "off")
    for kernels in ("fast", "auto"):
        assert forward(kernels) == forward("plain")
        assert "custom_call" not in grad(kernels).lower(variables).as_text()
    assert rel_err(fast, grad("fast")(variables)) < RTOL  # switched: the plain program (its jaxpr above)
