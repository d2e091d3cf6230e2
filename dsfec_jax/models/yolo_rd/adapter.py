"""The multi-representation Adapter (paper Sec. 3.3; no public code): a Stem and Exchangers.

- Stem: three Convs (3x3, conv + BN + SiLU) on the auxiliary representation (`stem_widths`,
  `stem_strides`; default 1 -> 32 -> 64 -> 128 channels at stride 4).
- Exchanger i (after backbone layer `exchanger_positions[i]`), mode 1: the backbone's features are
  primary and the auxiliary branch's are auxiliary, the result replaces the backbone's; mode 2:
  the roles swap, the result replaces the auxiliary branch's. In both:
      F_aux   = resize(BN(conv1x1(X_aux)))   to the primary's width and size
      X_fused = fuse(X_primary, F_aux)
      out     = X_primary + alpha * CoordinateAttention(X_fused)        (paper Eq. 1)
  gamma and alpha start at 0 (paper Sec. 4.1), so at initialisation every Exchanger returns its
  primary input unchanged: YOLOv8n-Adapter then computes exactly YOLOv8n (same weights).
- Fusion options (Table 6), the paper states only option 1's weight; the sums are our choice,
  all three add the auxiliary features to the whole primary ("preserving the core information
  from the primary feature and enhancing it with ... the auxiliary feature"):
      1 (PAF): X_p + w * F_aux, w = sigmoid(gamma * GAP(F_aux)), one weight per channel,
               gamma a learnable scalar (0 -> w = 0.5);
      2:       X_p + F_aux (element-wise sum);
      3:       X_p + lam * F_aux, lam a learnable scalar (0.5 at init, as option 1's w);
      0:       searchable (a one-shot supernet, search/nas): all three, the option an input.
- Choices the paper leaves open: the 1x1 conv is conv (no bias) + BN without activation (a linear
  projection keeps the sign of what it adds); resizing is area averaging when shrinking by an
  integer factor and nearest-neighbour repetition when growing by one (ultralytics' upsampling),
  bilinear otherwise; gamma, alpha and lam are scalars per Exchanger ("a learnable parameter").
All BNs use ultralytics' eps 1e-3 and momentum 0.97 (the paper's model is built in ultralytics,
whose initialize_weights sets every BatchNorm2d so).
"""

from __future__ import annotations

from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp

from ...layers.coord_attention import CoordinateAttention
from ...layers.yolo import BN_EPS, BN_MOMENTUM, YoloConv
from .layout import SEARCHABLE


def resize_to(x_BxHxWxC, hw: tuple[int, int]):
    """Resize to (H, W): area average when both sides shrink by integer factors, nearest-neighbour
    repetition when both grow by integer factors, bilinear otherwise."""
    h, w = x_BxHxWxC.shape[1:3]
    th, tw = hw
    if h >= th and w >= tw and h % th == 0 and w % tw == 0:
        return x_BxHxWxC if (h, w) == (th, tw) else nn.avg_pool(x_BxHxWxC, window_shape=(h // th, w // tw), strides=(h // th, w // tw))
    if th >= h and tw >= w and th % h == 0 and tw % w == 0:
        return jnp.repeat(jnp.repeat(x_BxHxWxC, th // h, axis=1), tw // w, axis=2)
    return jax.image.resize(x_BxHxWxC, (x_BxHxWxC.shape[0], th, tw, x_BxHxWxC.shape[-1]), "bilinear")


class Stem(nn.Module):
    """Three Convs on the auxiliary representation: preliminary features and the scale change."""

    widths: tuple[int, ...]
    strides: tuple[int, ...]

    @nn.compact
    def __call__(self, x, train: bool = False):
        for j, (c, s) in enumerate(zip(self.widths, self.strides)):
            x = YoloConv(c, 3, s, name=f"conv{j}")(x, train)
        return x


class Exchanger(nn.Module):
    """Primary-Auxiliary Fusion + Coordinate Attention + the alpha-weighted residual (Eq. 1)."""

    fusion: int = 1
    attention_reduction: int = 32
    attention_min_mip: int = 8

    @nn.compact
    def __call__(self, primary, aux, train: bool = False):
        f_aux = YoloConv(primary.shape[-1], 1, act=False, name="project")(aux, train)
        f_aux = resize_to(f_aux, primary.shape[1:3])
        fused = primary + self._aux_weight(f_aux) * f_aux
        attended = CoordinateAttention(self.attention_reduction, self.attention_min_mip, BN_EPS, BN_MOMENTUM,
                                       name="attention")(fused, train)
        alpha = self.param("alpha", nn.initializers.zeros, ())
        return primary + alpha * attended

    def _aux_weight(self, f_aux):
        """The weight of the auxiliary features in the fusion (see the module docstring)."""
        if self.fusion == SEARCHABLE:
            return self._searchable_weight(f_aux)
        if self.fusion == 1:
            gamma = self.param("gamma", nn.initializers.zeros, ())
            return jax.nn.sigmoid(gamma * jnp.mean(f_aux, axis=(1, 2), keepdims=True))
        if self.fusion == 2:
            return 1.0
        if self.fusion == 3:
            return self.param("fusion_weight", nn.initializers.constant(0.5), ())
        raise ValueError(f"fusion option {self.fusion!r}; valid: 1, 2, 3 (0: searchable)")

    def _searchable_weight(self, f_aux):
        """A one-shot supernet's Exchanger: it holds every option's parameters (gamma and the
        learnable weight, initialised as in options 1 and 3) and uses the option in the variable
        'nas'/'fusion' (an input, so one compiled step serves every choice; unchosen parameters get
        zero gradient)."""
        choice = self.variable("nas", "fusion", lambda: jnp.int32(1)).value
        gamma = self.param("gamma", nn.initializers.zeros, ())
        lam = self.param("fusion_weight", nn.initializers.constant(0.5), ())
        paf = jax.nn.sigmoid(gamma * jnp.mean(f_aux, axis=(1, 2), keepdims=True))
        return jnp.where(choice == 1, paf, jnp.where(choice == 2, jnp.ones_like(paf), lam))


class Adapter(nn.Module):
    """The auxiliary branch: `stem` once, then `exchange` after each of its backbone layers."""

    cfg: Any  # a YoloRDConfig (config.py imports the net to build it, so the net never imports config.py)

    def setup(self):
        c = self.cfg
        self.stem = Stem(tuple(c.stem_widths), tuple(c.stem_strides))
        self.exchangers = [Exchanger(f, c.attention_reduction, c.attention_min_mip) for f in c.fusions]

    def __call__(self, aux_image, train: bool = False):
        return self.stem(aux_image, train)

    def exchange(self, layer: int, backbone_x, aux_x, train: bool = False):
        """After backbone layer `layer`: (backbone features, auxiliary features), either updated."""
        if layer not in self.cfg.exchanger_positions:
            return backbone_x, aux_x
        k = self.cfg.exchanger_positions.index(layer)
        if self.cfg.adapter_layout[k] == 1:
            return self.exchangers[k](backbone_x, aux_x, train), aux_x
        return backbone_x, self.exchangers[k](aux_x, backbone_x, train)
