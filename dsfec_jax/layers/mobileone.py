"""MobileOne re-parameterizable block (Vasu et al., CVPR 2023), as RadarNeXt's Rep-DWC uses it.

Train-time form: k conv+BN branches, plus a 1x1 conv+BN "scale" branch when the kernel is larger
than 1x1, plus a BN-only identity branch when C_in == C_out and stride == 1; summed, then ReLU.
Inference form: one conv with bias, then ReLU. `reparameterize` turns trained variables of the
first into variables of the second (conv-BN fusion: W * gamma / sigma, beta - mu * gamma / sigma;
the 1x1 kernel zero-padded to KxK; the identity as a centred one-hot kernel), so eval-mode
outputs agree to float rounding. Padding is symmetric K // 2 (PyTorch's), not TF 'SAME': with
'SAME' at stride 2 a 3x3 and a 1x1 branch would not be centred on the same input pixel, and the
1x1 could not be folded into the 3x3.
"""

from __future__ import annotations

import math

import flax.linen as nn
import jax.numpy as jnp
import numpy as np
from jax import lax

from .conv import DIMS, DepthwiseImpl, Kernels, fast_shifted_depthwise, kernel_init, shifted_depthwise
from .kernels import hand_written

BN_EPS = 1e-5        # PyTorch BatchNorm2d defaults (the public RadarNeXt code is PyTorch)
BN_MOMENTUM = 0.9    # flax momentum = 1 - PyTorch momentum 0.1


def rep_conv(x_BxHxWxC, w_KxKxIxO, stride: int, groups: int, impl: DepthwiseImpl = "grouped",
             kernels: Kernels = "auto"):
    """Conv with symmetric K // 2 padding; a depthwise kernel may use the fast shifted form.
    kernels="fast" (layers.conv): the shifted form with its hand-written gradient (autodiff keeps
    all K*K shifted copies) and a dense 1x1 conv as a matmul."""
    k = w_KxKxIxO.shape[0]
    fast = hand_written(kernels)
    if groups > 1 and groups == x_BxHxWxC.shape[-1] == w_KxKxIxO.shape[-1] and impl == "shifted":
        depthwise = fast_shifted_depthwise if fast else shifted_depthwise
        return depthwise(x_BxHxWxC, w_KxKxIxO[:, :, 0, :], stride, (k // 2, k // 2))
    if fast and k == 1 and groups == 1:
        return jnp.dot(x_BxHxWxC[:, ::stride, ::stride], w_KxKxIxO[0, 0])
    return lax.conv_general_dilated(x_BxHxWxC, w_KxKxIxO, (stride, stride), [(k // 2, k // 2)] * 2,
                                    dimension_numbers=DIMS, feature_group_count=groups)


def _bn(train: bool, name: str) -> nn.BatchNorm:
    # RadarNeXt draws BN gamma from U(0, 1) at init (radarnext.py init_weights)
    return nn.BatchNorm(use_running_average=not train, momentum=BN_MOMENTUM, epsilon=BN_EPS,
                        scale_init=nn.initializers.uniform(1.0), name=name)


class MobileOneBlock(nn.Module):
    """One MobileOne conv (depthwise when `depthwise`), ReLU after; `deploy` = the fused form."""

    features: int
    kernel: int = 3
    stride: int = 1
    depthwise: bool = False
    branches: int = 1            # k, num_conv_branches (RadarNeXt: 1)
    deploy: bool = False
    depthwise_impl: DepthwiseImpl = "shifted"
    kernels: Kernels = "auto"

    def groups(self, cin: int) -> int:
        if self.depthwise and cin != self.features:
            raise ValueError(f"depthwise MobileOneBlock needs C_in == features, got {cin} -> {self.features}")
        return cin if self.depthwise else 1

    def has_identity(self, cin: int) -> bool:
        return cin == self.features and self.stride == 1

    @nn.compact
    def __call__(self, x_BxHxWxC, train: bool = False):
        cin = x_BxHxWxC.shape[-1]
        g, k = self.groups(cin), self.kernel
        shape = lambda kk: (kk, kk, cin // g, self.features)  # noqa: E731
        conv = lambda w: rep_conv(x_BxHxWxC, w, self.stride, g, self.depthwise_impl, self.kernels)  # noqa: E731
        if self.deploy:
            y = conv(self.param("kernel", kernel_init, shape(k))) + self.param("bias", nn.initializers.zeros,
                                                                              (self.features,))
            return nn.relu(y)
        y = sum(_bn(train, f"conv{b}_bn")(conv(self.param(f"conv{b}", kernel_init, shape(k))))
                for b in range(self.branches))
        if k > 1:
            y = y + _bn(train, "scale_bn")(conv(self.param("scale", kernel_init, shape(1))))
        if self.has_identity(cin):
            y = y + _bn(train, "identity_bn")(x_BxHxWxC)
        return nn.relu(y)

    def macs(self, in_shape, out_shape) -> int:
        """MACs of the deployed (fused) form: the one that is exported and timed."""
        return math.prod(out_shape[:-1]) * self.kernel**2 * (in_shape[-1] // self.groups(in_shape[-1])) * self.features


class RepDWSeparable(nn.Module):
    """One Rep-DWC layer: a depthwise 3x3 MobileOne block (carries the stride), then a pointwise
    1x1 MobileOne block to `features`. RadarNeXt's backbone layers and its neck's RepBlocks."""

    features: int
    stride: int = 1
    branches: int = 1
    deploy: bool = False
    depthwise_impl: DepthwiseImpl = "shifted"
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, x_BxHxWxC, train: bool = False):
        cin = x_BxHxWxC.shape[-1]
        x = MobileOneBlock(cin, 3, self.stride, True, self.branches, self.deploy, self.depthwise_impl,
                           self.kernels, name="dw")(x_BxHxWxC, train)
        return MobileOneBlock(self.features, 1, 1, False, self.branches, self.deploy, kernels=self.kernels,
                              name="pw")(x, train)


def _fuse(kernel, bn_params, bn_stats):
    """Conv (HWIO) + BN -> (kernel, bias)."""
    std = np.sqrt(np.asarray(bn_stats["var"]) + BN_EPS)
    t = np.asarray(bn_params["scale"]) / std
    return np.asarray(kernel) * t, np.asarray(bn_params["bias"]) - np.asarray(bn_stats["mean"]) * t


def fuse_branches(params: dict, stats: dict) -> dict:
    """One block's trained {params, batch_stats} -> {kernel, bias} of its deploy form. Read from
    the shapes alone (k conv branches, a scale branch, an identity branch when present), so a
    whole variables tree can be fused without the modules that made it."""
    k, _, cin_per_group, features = np.shape(params["conv0"])
    kernel = np.zeros((k, k, cin_per_group, features), np.float32)
    bias = np.zeros((features,), np.float32)
    branches = [(params[name], f"{name}_bn") for name in sorted(params) if name.startswith("conv") and "_" not in name]
    if "scale" in params:
        pad = k // 2
        branches.append((np.pad(np.asarray(params["scale"]), ((pad, pad), (pad, pad), (0, 0), (0, 0))), "scale_bn"))
    if "identity_bn" in params:
        eye = np.zeros_like(kernel)
        out = np.arange(features)
        eye[k // 2, k // 2, out % cin_per_group, out] = 1.0  # depthwise: cin_per_group == 1
        branches.append((eye, "identity_bn"))
    for w, bn in branches:
        fw, fb = _fuse(w, params[bn], stats[bn])
        kernel, bias = kernel + fw, bias + fb
    return {"kernel": jnp.asarray(kernel), "bias": jnp.asarray(bias)}


def is_branched_block(params: dict) -> bool:
    return isinstance(params, dict) and "conv0" in params and "conv0_bn" in params


def reparameterize_tree(variables: dict) -> dict:
    """Fuse every MobileOne block in a variables tree; everything else is copied unchanged.
    Blocks without BN state left disappear from 'batch_stats'."""
    def walk(params, stats):
        if is_branched_block(params):
            return fuse_branches(params, stats), None
        out_p, out_s = {}, {}
        for key, sub in params.items():
            if isinstance(sub, dict):
                fp, fs = walk(sub, (stats or {}).get(key, {}))
                out_p[key] = fp
                if fs:
                    out_s[key] = fs
            else:
                out_p[key] = sub
        for key, sub in (stats or {}).items():
            if key not in params:
                out_s[key] = sub
        return out_p, out_s

    params, stats = walk(dict(variables["params"]), dict(variables.get("batch_stats", {})))
    return {"params": params, "batch_stats": stats}


def reparameterize_block(block: MobileOneBlock, cin: int, params: dict, stats: dict) -> dict:
    """Trained {params, batch_stats} of one block -> {params: {kernel, bias}} of its deploy form."""
    block.groups(cin)  # validates a depthwise block's widths
    return {"params": fuse_branches(params, stats)}
