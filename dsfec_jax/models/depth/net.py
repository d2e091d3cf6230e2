"""The monodepth disparity network (mrharicot/monodepth `build_vgg`, narrower; config.py).

images (B, H, W, 3) float32 in [0, 1], NHWC, H and W multiples of cfg.stride -> a tuple of
NUM_SCALES disparity maps, finest first: scale s is (B, H / 2**s, W / 2**s, 2) with channel 0 the
left-view and channel 1 the right-view disparity, each a fraction of the image width in
(0, cfg.max_disparity).

As monodepth: every conv zero-pads (k - 1) // 2 on each side (its explicit tf.pad + VALID), ELU
after every conv but the disparity heads (0.3 * sigmoid), Xavier-uniform kernels and zero biases
(slim.conv2d's defaults), nearest-neighbour upsampling, no normalisation layers.
Variables: {'params'} only.
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from .config import DISPARITY_CHANNELS, NUM_SCALES, MonodepthConfig


class Conv(nn.Module):
    """k x k conv with monodepth's symmetric zero padding, ELU unless `act` is None."""
    features: int
    kernel: int
    stride: int = 1
    act: bool = True

    @nn.compact
    def __call__(self, x):
        p = (self.kernel - 1) // 2
        x = nn.Conv(self.features, (self.kernel, self.kernel), (self.stride, self.stride), padding=((p, p), (p, p)),
                    kernel_init=nn.initializers.xavier_uniform())(x)
        return jax.nn.elu(x) if self.act else x


def upsample_nn(x, ratio: int = 2):
    """Nearest-neighbour x`ratio` (tf.image.resize_nearest_neighbor at an integer ratio)."""
    return jnp.repeat(jnp.repeat(x, ratio, axis=1), ratio, axis=2)


class MonodepthNet(nn.Module):
    cfg: MonodepthConfig

    @nn.compact
    def __call__(self, images):
        cfg = self.cfg
        if images.ndim != 4 or images.shape[-1] != 3:
            raise ValueError(f"{cfg.name}: images must be (B, H, W, 3) NHWC, got {images.shape}")
        if images.shape[1] % cfg.stride or images.shape[2] % cfg.stride:
            raise ValueError(f"{cfg.name}: input {images.shape[1]}x{images.shape[2]} must be a multiple of "
                             f"{cfg.stride} on both sides")
        skips = self.encoder(images)
        return self.decoder(skips)

    def encoder(self, x):
        """The conv_block outputs, at 1/2, 1/4, ..., 1/2**levels resolution."""
        skips = []
        for i, (w, k) in enumerate(zip(self.cfg.encoder_widths, self.cfg.encoder_kernels)):
            x = Conv(w, k, 1, name=f"enc{i}_a")(x)
            x = Conv(w, k, 2, name=f"enc{i}_b")(x)
            skips.append(x)
        return skips

    def decoder(self, skips):
        """Disparities finest first. The scale 1/2**j is decoded from the coarser one, the encoder's
        map of scale j (none at full resolution) and, below the coarsest head, the coarser
        disparity upsampled (monodepth's udisp)."""
        cfg = self.cfg
        x, disps, coarser = skips[-1], [], None
        for j in range(len(skips) - 1, -1, -1):
            width = cfg.encoder_widths[j - 1] if j else cfg.top_width
            parts = [Conv(width, 3, name=f"upconv{j}")(upsample_nn(x))]
            if j:
                parts.append(skips[j - 1])
            if coarser is not None:
                parts.append(upsample_nn(coarser))
            x = Conv(width, 3, name=f"iconv{j}")(jnp.concatenate(parts, axis=-1))
            if j < NUM_SCALES:
                logits = Conv(DISPARITY_CHANNELS, 3, act=False, name=f"disp{j}")(x)
                coarser = cfg.max_disparity * jax.nn.sigmoid(logits)
                disps.append(coarser)
        return tuple(reversed(disps))


def init_variables(cfg: MonodepthConfig, rng: jax.Array) -> dict:
    """Fresh variables for `cfg`: slim.conv2d's Xavier-uniform kernels (limit sqrt(6 / (fan_in +
    fan_out)), fans k*k*c_in and k*k*c_out) and zero biases, drawn with numpy from a generator
    seeded by `rng`'s key data. Same distribution as the modules' own kernel_init, but without
    XLA: compiling the random draws of every kernel shape takes tens of seconds on a CPU."""
    images = jax.ShapeDtypeStruct((1, cfg.height, cfg.width, 3), jnp.float32)
    shapes = jax.eval_shape(MonodepthNet(cfg).init, rng, images)
    gen = np.random.default_rng(np.asarray(jax.random.key_data(rng), np.uint32).ravel().tolist())

    def draw(path, leaf):
        if getattr(path[-1], "key", None) != "kernel":
            return np.zeros(leaf.shape, leaf.dtype)
        kh, kw, c_in, c_out = leaf.shape
        limit = np.sqrt(6.0 / (kh * kw * (c_in + c_out)))
        return gen.uniform(-limit, limit, leaf.shape).astype(leaf.dtype)

    return jax.tree_util.tree_map_with_path(draw, shapes)


def count_params(variables: dict) -> int:
    return int(sum(x.size for x in jax.tree.leaves(variables)))
