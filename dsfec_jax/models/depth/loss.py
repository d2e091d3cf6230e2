"""monodepth's self-supervised stereo loss (Godard et al. 2017, eq. 1-4; mrharicot/monodepth
`monodepth_model.py` build_outputs / build_losses).

Conventions: images (B, H, W, C) float in [0, 1]; disparities (B, H, W, 1) as a fraction of the
width. The right camera sits to the right of the left one, so a point at column x of the left
image is at x - d * W in the right image:
    left_est(x)  = right(x - d_left(x) * W)      generate_image_left(right, d_left)
    right_est(x) = left(x + d_right(x) * W)      generate_image_right(left, d_right)

At each of the 4 scales s (images area-downsampled by 2**s, i.e. 2**s x 2**s means; the network's
sizes are multiples of 2**s), for both views:
- appearance: alpha * mean(clip((1 - SSIM) / 2, 0, 1)) + (1 - alpha) * mean|est - image|, alpha
  0.85; SSIM on 3x3 average pools, VALID (so 2 pixels smaller), C1 = 0.01**2, C2 = 0.03**2.
- smoothness: mean |dx d| exp(-mean_c |dx I|) + mean |dy d| exp(-mean_c |dy I|), weighted
  0.1 / 2**s. The paper's eq. 3 has both terms. (monodepth's code keeps only the x term: its
  loss indexes the first 4 of the 8 maps get_disparity_smoothness returns, x then y.)
- left-right consistency: mean |d_right warped to the left view - d_left| (and the mirror), weight 1.
total = sum over scales and views of appearance + 0.1 smoothness / 2**s + 1.0 lr.

The warp is monodepth's bilinear_sampler_1d_h: horizontal only, linear between the two nearest
columns. `wrap_mode` 'edge' clamps the sample column to the image (the edge column repeats);
'border' (monodepth's command-line default) pads one column of zeros on each side first, so
samples falling off the image fade to black. This project trains with 'edge': the left image's
left margin, which the right camera does not see, is then matched against the repeated edge column
rather than against black.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

WRAP_MODES = ("edge", "border")
SSIM_C1, SSIM_C2 = 0.01 ** 2, 0.03 ** 2


@dataclasses.dataclass(frozen=True)
class MonodepthLoss:
    """monodepth_main.py's defaults, but for wrap_mode: 'edge' here, 'border' there (module docstring)."""
    alpha_image_loss: float = 0.85          # SSIM share of the appearance loss
    disp_gradient_loss_weight: float = 0.1  # smoothness, divided by 2**scale
    lr_loss_weight: float = 1.0             # left-right consistency
    wrap_mode: str = "edge"                 # 'edge' | 'border' (module docstring)

    def __post_init__(self):
        if self.wrap_mode not in WRAP_MODES:
            raise ValueError(f"MonodepthLoss.wrap_mode={self.wrap_mode!r}; expected one of {WRAP_MODES}")
        if not 0 <= self.alpha_image_loss <= 1:
            raise ValueError(f"MonodepthLoss.alpha_image_loss={self.alpha_image_loss} must be in [0, 1]")


def sample_1d_h(images, x_offset, wrap_mode: str = "edge"):
    """images (B, H, W, C) sampled at column x + x_offset * W of each pixel (x_offset (B, H, W, 1),
    a fraction of the width), linear between the two nearest columns (bilinear_sampler_1d_h)."""
    if wrap_mode not in WRAP_MODES:
        raise ValueError(f"wrap_mode={wrap_mode!r}; expected one of {WRAP_MODES}")
    width = images.shape[2]
    x = jnp.arange(width, dtype=images.dtype)[None, None, :] + x_offset[..., 0] * width
    edge = 1 if wrap_mode == "border" else 0
    if edge:
        images = jnp.pad(images, ((0, 0), (0, 0), (1, 1), (0, 0)))
        x = x + 1
    last = width - 1 + 2 * edge
    x = jnp.clip(x, 0.0, last)
    x0_f = jnp.floor(x)
    # the weights use the unclamped right neighbour x0 + 1, as monodepth does: at x == last the
    # left column gets weight 1
    w_left, w_right = (x0_f + 1 - x)[..., None], (x - x0_f)[..., None]
    x0 = x0_f.astype(jnp.int32)
    x1 = jnp.minimum(x0 + 1, last)
    # one gather from the flattened images, as monodepth's tf.gather (compiles faster than
    # take_along_axis)
    b, h, w, c = images.shape
    row_start = (jnp.arange(b * h, dtype=jnp.int32) * w).reshape(b, h, 1)
    flat = images.reshape(-1, c)
    take = lambda cols: jnp.take(flat, (row_start + cols).reshape(-1), axis=0).reshape(b, h, width, c)
    return w_left * take(x0) + w_right * take(x1)


def generate_image_left(right, disp_left, wrap_mode: str = "edge"):
    """The left view rebuilt from the right image with the left disparity."""
    return sample_1d_h(right, -disp_left, wrap_mode)


def generate_image_right(left, disp_right, wrap_mode: str = "edge"):
    """The right view rebuilt from the left image with the right disparity."""
    return sample_1d_h(left, disp_right, wrap_mode)


def area_downsample(images, factor: int):
    """Mean over factor x factor blocks (tf.image.resize_area at an integer ratio)."""
    if factor == 1:
        return images
    b, h, w, c = images.shape
    if h % factor or w % factor:
        raise ValueError(f"images {h}x{w} cannot be area-downsampled by {factor}: sides must be multiples of it")
    return images.reshape(b, h // factor, factor, w // factor, factor, c).mean(axis=(2, 4))


def scale_pyramid(images, num_scales: int) -> list:
    return [area_downsample(images, 2 ** s) for s in range(num_scales)]


def _avg3(x):
    """3x3 mean, stride 1, VALID (slim.avg_pool2d(x, 3, 1, 'VALID')) of every channel: one
    depthwise convolution (XLA compiles it far faster than a pooling window or shifted slices)."""
    c = x.shape[-1]
    kernel = jnp.full((3, 3, 1, c), 1.0 / 9.0, x.dtype)
    return jax.lax.conv_general_dilated(x, kernel, (1, 1), "VALID", dimension_numbers=("NHWC", "HWIO", "NHWC"),
                                        feature_group_count=c)


def ssim(x, y):
    """monodepth's SSIM map (3x3 mean windows, VALID: (B, H-2, W-2, C)). The five window means
    (x, y, x^2, y^2, xy) are taken in one pass."""
    c = x.shape[-1]
    means = _avg3(jnp.concatenate([x, y, x * x, y * y, x * y], axis=-1))
    mu_x, mu_y, xx, yy, xy = (means[..., i * c:(i + 1) * c] for i in range(5))
    sigma_x, sigma_y, sigma_xy = xx - mu_x ** 2, yy - mu_y ** 2, xy - mu_x * mu_y
    num = (2 * mu_x * mu_y + SSIM_C1) * (2 * sigma_xy + SSIM_C2)
    den = (mu_x ** 2 + mu_y ** 2 + SSIM_C1) * (sigma_x + sigma_y + SSIM_C2)
    return num / den


def appearance_loss(estimate, target, alpha: float = 0.85):
    """alpha * mean(clip((1 - SSIM) / 2, 0, 1)) + (1 - alpha) * mean L1."""
    dssim = jnp.clip((1 - ssim(estimate, target)) / 2, 0, 1)
    return alpha * jnp.mean(dssim) + (1 - alpha) * jnp.mean(jnp.abs(estimate - target))


def _dx(x):
    return x[:, :, :-1, :] - x[:, :, 1:, :]


def _dy(x):
    return x[:, :-1, :, :] - x[:, 1:, :, :]


def smoothness_loss(disp, image):
    """Edge-aware smoothness (paper eq. 3): disparity gradients damped where the image has edges."""
    wx = jnp.exp(-jnp.mean(jnp.abs(_dx(image)), axis=3, keepdims=True))
    wy = jnp.exp(-jnp.mean(jnp.abs(_dy(image)), axis=3, keepdims=True))
    return jnp.mean(jnp.abs(_dx(disp) * wx)) + jnp.mean(jnp.abs(_dy(disp) * wy))


def lr_consistency_loss(disp_left, disp_right, wrap_mode: str = "edge"):
    """mean |right disparity seen from the left - left disparity| + the mirror term."""
    right_to_left = generate_image_left(disp_right, disp_left, wrap_mode)
    left_to_right = generate_image_right(disp_left, disp_right, wrap_mode)
    return jnp.mean(jnp.abs(right_to_left - disp_left)) + jnp.mean(jnp.abs(left_to_right - disp_right))


def monodepth_loss(disps, left, right, cfg: MonodepthLoss = MonodepthLoss()):
    """(total, parts) for the network's disparities (finest first, (B, H/2**s, W/2**s, 2)) and the
    stereo pair (B, H, W, 3) in [0, 1]. parts: image, smoothness, lr (each summed over scales and
    views, unweighted) and image_s0 (the full-resolution appearance loss).
    Both views of a scale run as one batch (the left and right terms have the same sizes, so
    2 * the mean over both is monodepth's sum of the two means), and each warp samples the image
    and the other view's disparity together: half the ops to compile."""
    small = [d.shape[1:3] for d in disps if min(d.shape[1:3]) < 3]
    if small:
        raise ValueError(f"monodepth_loss: disparity maps {small} are smaller than SSIM's 3x3 window; the "
                         f"coarsest scale must be at least 3 x 3 (input at least {3 * 2 ** (len(disps) - 1)} px a side)")
    left_pyr, right_pyr = scale_pyramid(left, len(disps)), scale_pyramid(right, len(disps))
    image = smooth = lr = 0.0
    image_s0 = None
    for s, d in enumerate(disps):
        d_left, d_right = d[..., 0:1], d[..., 1:2]
        from_right = generate_image_left(jnp.concatenate([right_pyr[s], d_right], -1), d_left, cfg.wrap_mode)
        from_left = generate_image_right(jnp.concatenate([left_pyr[s], d_left], -1), d_right, cfg.wrap_mode)
        estimates = jnp.concatenate([from_right[..., :3], from_left[..., :3]], 0)  # left_est, right_est
        targets = jnp.concatenate([left_pyr[s], right_pyr[s]], 0)
        image_s = 2 * appearance_loss(estimates, targets, cfg.alpha_image_loss)
        image_s0 = image_s if s == 0 else image_s0
        image = image + image_s
        smooth = smooth + 2 * smoothness_loss(jnp.concatenate([d_left, d_right], 0), targets) / 2 ** s
        warped_disp = jnp.concatenate([from_right[..., 3:], from_left[..., 3:]], 0)  # right_to_left, left_to_right
        lr = lr + 2 * jnp.mean(jnp.abs(warped_disp - jnp.concatenate([d_left, d_right], 0)))
    total = image + cfg.disp_gradient_loss_weight * smooth + cfg.lr_loss_weight * lr
    return total, {"image": image, "smoothness": smooth, "lr": lr, "image_s0": image_s0}
