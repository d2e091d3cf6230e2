"""monodepth's stereo loss: the horizontal warp, SSIM, smoothness, left-right consistency."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax.models.depth import loss as L

W = 16  # a power of two: k / W * W is exactly k, so integer shifts sample exact columns


def _images(b=2, h=4, w=W, c=3, seed=0):
    return jnp.asarray(np.random.default_rng(seed).random((b, h, w, c)), jnp.float32)


def _disp(value, b=2, h=4, w=W):
    return jnp.full((b, h, w, 1), value, jnp.float32)


@pytest.mark.parametrize("k", [1, 3])
def test_left_view_rebuilt_exactly_from_a_shifted_right_view(k):
    """Everything at disparity k px: right(x) = left(x + k), so left_est(x) = right(x - k) = left(x)
    wherever x - k is inside; outside, 'edge' repeats column 0 and 'border' gives zeros."""
    left = _images()
    right = jnp.concatenate([left[:, :, k:], jnp.zeros_like(left[:, :, :k])], axis=2)
    est = L.generate_image_left(right, _disp(k / W))
    np.testing.assert_array_equal(est[:, :, k:], left[:, :, k:])
    np.testing.assert_array_equal(est[:, :, :k], jnp.broadcast_to(right[:, :, :1], est[:, :, :k].shape))
    border = L.generate_image_left(right, _disp(k / W), "border")
    np.testing.assert_array_equal(border[:, :, k:], left[:, :, k:])
    assert float(jnp.abs(border[:, :, :k]).max()) == 0.0


def test_right_view_rebuilt_exactly_from_the_left():
    left = _images()
    right = jnp.concatenate([left[:, :, 2:], left[:, :, -2:]], axis=2)
    est = L.generate_image_right(left, _disp(2 / W))
    np.testing.assert_array_equal(est[:, :, :-2], right[:, :, :-2])
    np.testing.assert_array_equal(est[:, :, -2:], jnp.broadcast_to(left[:, :, -1:], est[:, :, -2:].shape))


def test_half_pixel_shift_is_the_mean_of_neighbours():
    img = _images()
    est = L.sample_1d_h(img, _disp(0.5 / W))
    np.testing.assert_allclose(est[:, :, :-1], (img[:, :, :-1] + img[:, :, 1:]) / 2, rtol=1e-6)


def test_warp_is_differentiable_in_the_disparity():
    img = _images()
    grad = jax.grad(lambda d: jnp.sum(L.generate_image_left(img, d) ** 2))(_disp(0.3 / W))
    assert float(jnp.abs(grad).sum()) > 0


def test_bad_wrap_mode_is_named():
    with pytest.raises(ValueError, match="wrap_mode"):
        L.sample_1d_h(_images(), _disp(0.0), "wrap")
    with pytest.raises(ValueError, match="wrap_mode"):
        L.MonodepthLoss(wrap_mode="mirror")


def test_ssim_of_an_image_with_itself_is_one():
    x = _images(h=8)
    np.testing.assert_allclose(L.ssim(x, x), 1.0, rtol=1e-5)
    assert L.ssim(x, x).shape == (2, 6, W - 2, 3)  # VALID 3x3 windows
    assert float(L.ssim(x, _images(h=8, seed=1)).mean()) < 0.5
    assert float(L.appearance_loss(x, x)) == pytest.approx(0.0, abs=1e-6)


def test_appearance_loss_mixes_dssim_and_l1():
    x, y = _images(h=8), _images(h=8, seed=1)
    dssim = float(jnp.mean(jnp.clip((1 - L.ssim(x, y)) / 2, 0, 1)))
    l1 = float(jnp.mean(jnp.abs(x - y)))
    assert float(L.appearance_loss(x, y)) == pytest.approx(0.85 * dssim + 0.15 * l1, rel=1e-5)


def test_area_downsample_is_block_mean():
    x = jnp.arange(16.0).reshape(1, 4, 4, 1)
    np.testing.assert_array_equal(L.area_downsample(x, 2)[0, :, :, 0], [[2.5, 4.5], [10.5, 12.5]])
    with pytest.raises(ValueError, match="multiples"):
        L.area_downsample(jnp.zeros((1, 6, 4, 1)), 4)


def test_lr_consistency_zero_for_consistent_disparities():
    assert float(L.lr_consistency_loss(_disp(3 / W), _disp(3 / W))) == 0.0
    # right disparity twice the left: |2c - c| seen from each side
    assert float(L.lr_consistency_loss(_disp(2 / W), _disp(4 / W))) == pytest.approx(2 * 2 / W)
    noisy = _disp(2 / W) + 0.01 * _images(c=1)
    assert float(L.lr_consistency_loss(noisy, _disp(2 / W))) > 0


def test_smoothness_is_edge_aware():
    step = jnp.concatenate([jnp.zeros((1, 4, W // 2, 1)), jnp.ones((1, 4, W // 2, 1))], axis=2)
    flat_image = jnp.zeros((1, 4, W, 3))
    edge_image = jnp.broadcast_to(step, (1, 4, W, 3))
    assert float(L.smoothness_loss(jnp.zeros((1, 4, W, 1)), edge_image)) == 0.0
    on_flat = float(L.smoothness_loss(step, flat_image))
    assert on_flat == pytest.approx(1 / (W - 1))  # one jump of 1 among W - 1 column gradients
    assert float(L.smoothness_loss(step, edge_image)) == pytest.approx(on_flat * np.exp(-1))


def _scene(k=2, h=32, w=32):
    """A pair where everything has disparity k px (at full resolution)."""
    left = _images(b=1, h=h, w=w, seed=3)
    right = jnp.concatenate([left[:, :, k:], left[:, :, -k:]], axis=2)
    return left, right


def test_total_loss_prefers_the_true_disparity_and_adds_up():
    left, right = _scene()
    w = left.shape[2]

    loss = jax.jit(lambda fraction: L.monodepth_loss(
        [jnp.full((1, 32 // 2 ** s, w // 2 ** s, 2), fraction, jnp.float32) for s in range(4)], left, right))
    true_loss, parts = loss(2 / w)
    wrong_loss, wrong_parts = loss(6 / w)
    assert float(true_loss) < float(wrong_loss)
    assert float(parts["lr"]) == 0.0 and float(parts["smoothness"]) == 0.0  # constant, consistent
    assert float(true_loss) == pytest.approx(float(parts["image"] + 0.1 * parts["smoothness"] + parts["lr"]))
    # the full-resolution term of a perfect warp is only its clamped edge columns
    assert float(parts["image_s0"]) < 0.1 * float(wrong_parts["image_s0"])


def test_too_small_a_coarsest_scale_is_named():
    left, right = _scene(h=16)
    disps = [jnp.full((1, 16 // 2 ** s, 32 // 2 ** s, 2), 0.1) for s in range(4)]
    with pytest.raises(ValueError, match="3x3"):
        L.monodepth_loss(disps, left, right)


def test_loss_weights_are_monodepths_defaults():
    cfg = L.MonodepthLoss()
    assert (cfg.alpha_image_loss, cfg.disp_gradient_loss_weight, cfg.lr_loss_weight) == (0.85, 0.1, 1.0)
