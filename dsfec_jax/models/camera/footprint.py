"""Counts and the memory footprint of a camera detector, by arithmetic over its layers: the network
is traced shape-only (`jax.eval_shape`, nothing computed) with a method interceptor that records
every convolution (the layers' own `macs`, as the profiler reads them) and every non-conv layer
that makes a new map; parameters come from the variable shapes.

Conventions:
- params: the 'params' collection (conv weights, biases, BN scale and offset; BN moving
  statistics are state: `batch_stats`). Model size = params x 4 bytes (fp32); darknet's weights
  file also stores the moving mean and variance (`weights_file_bytes`: + batch_stats, + 20 bytes
  of header).
- MACs: multiply-accumulates of the convolutions (depthwise counted per channel). GFLOPs =
  2 x MACs / 1e9, darknet's convention (its "BFLOPs": 2 n size^2 c / groups out_h out_w per
  [convolutional], nothing else counted): yolov3-voc at 416 -> 65.4.
- the paper's memory formula (Sec. 3.4): parameters C_in C_out K^2 + C_out per conv (C_in /
  groups for a depthwise conv; + C_out is the bias a BN folds into: the inference form), plus
  per-layer outputs C_out H W, 4 bytes each, batch 1. "Layers" is read two ways: `conv` (each
  conv with its BN and activation, in place) and `all` (plus every other layer that writes a new
  map in darknet's sense: a residual add ([shortcut]), a shuffle unit's concatenation (its channel
  shuffle is a view of it), the FPN's upsample and route / add). Input image and the yolo layers
  (decode, not part of the network here) are left out.
"""

from __future__ import annotations

import dataclasses
import math

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from ...layers.conv import Conv, DepthwiseConv
from ...layers.darknet import DarknetResidual
from ...layers.shufflenet import ShuffleUnit
from .config import CameraConfig
from .yolo3_neck_head import FpnMerge

BYTES = 4  # fp32
MB, MIB = 1e6, 2**20
HEADER_BYTES = 20  # darknet weights file: major, minor, revision (int32) and `seen` (int64 since 0.2)
PAPER_HW = (416, 416)


@dataclasses.dataclass(frozen=True)
class Layer:
    """One layer of the trace: `kind` 'conv' | 'depthwise' | 'shortcut' | 'concat' | 'upsample' |
    'route' | 'add'; shapes (B, H, W, C); for convs the kernel, groups, bias flag and MACs."""

    path: str
    kind: str
    out_shape: tuple[int, ...]
    in_channels: int = 0
    kernel: int = 0
    groups: int = 1
    bias: bool = False
    macs: int = 0

    @property
    def is_conv(self) -> bool:
        return self.kind in ("conv", "depthwise")

    @property
    def out_elems(self) -> int:
        """C_out H W (batch 1)."""
        return math.prod(self.out_shape[1:])

    @property
    def paper_params(self) -> int:
        """C_in / groups C_out K^2 + C_out (0 for a layer without weights)."""
        if not self.is_conv:
            return 0
        c_out = self.out_shape[-1]
        return self.in_channels // self.groups * c_out * self.kernel**2 + c_out


def _conv_layer(module, args, out) -> Layer:
    depthwise = isinstance(module, DepthwiseConv)
    cin = args[0].shape[-1]
    return Layer("/".join(module.path), "depthwise" if depthwise else "conv", tuple(out.shape), cin,
                 module.kernel, cin if depthwise else 1, bool(getattr(module, "use_bias", False)),
                 int(module.macs(args[0].shape, out.shape)))


def _map_layers(module, args, out) -> list[Layer]:
    """The non-conv maps a block writes (module docstring, 'all' layers)."""
    path = "/".join(module.path)
    if isinstance(module, DarknetResidual):
        return [Layer(path, "shortcut", tuple(out.shape))]
    if isinstance(module, ShuffleUnit):
        return [Layer(path, "concat", tuple(out.shape))]
    if isinstance(module, FpnMerge):
        lateral = args[0].shape
        up = (lateral[0], 2 * lateral[1], 2 * lateral[2], lateral[3])
        return [Layer(path + "/upsample", "upsample", up),
                Layer(path, "route" if module.mode == "concat" else "add", tuple(out.shape))]
    return []


def trace(cfg: CameraConfig, hw: tuple[int, int] = PAPER_HW, batch: int = 1) -> tuple[list[Layer], dict]:
    """(layers in execution order, variable shapes) of `cfg` at input `hw`, without computing."""
    layers: list[Layer] = []

    def interceptor(next_fun, args, kwargs, context):
        out = next_fun(*args, **kwargs)
        module = context.module
        if context.method_name == "__call__":
            if isinstance(module, (Conv, DepthwiseConv)):
                layers.append(_conv_layer(module, args, out))
            else:
                layers.extend(_map_layers(module, args, out))
        return out

    net = cfg.build()
    image = jax.ShapeDtypeStruct((batch, *hw, 3), jnp.float32)
    variables = jax.eval_shape(net.init, jax.random.key(0), image)
    with nn.intercept_methods(interceptor):
        jax.eval_shape(net.apply, variables, image)
    return layers, variables


def count(tree) -> int:
    return sum(int(np.prod(a.shape)) for a in jax.tree_util.tree_leaves(tree))


def footprint(cfg: CameraConfig, hw: tuple[int, int] = PAPER_HW) -> dict:
    """Params, model size, MACs / GFLOPs and the paper's memory formula of `cfg` at `hw`, batch 1."""
    layers, variables = trace(cfg, hw)
    params, stats = count(variables["params"]), count(variables.get("batch_stats", {}))
    convs = [lay for lay in layers if lay.is_conv]
    macs = sum(lay.macs for lay in convs)
    paper_params = sum(lay.paper_params for lay in convs)
    conv_outputs = sum(lay.out_elems for lay in convs)
    all_outputs = conv_outputs + sum(lay.out_elems for lay in layers if not lay.is_conv)
    mem = {"param_bytes": paper_params * BYTES, "conv_output_bytes": conv_outputs * BYTES,
           "all_output_bytes": all_outputs * BYTES}
    mem["conv_total_bytes"] = mem["param_bytes"] + mem["conv_output_bytes"]
    mem["all_total_bytes"] = mem["param_bytes"] + mem["all_output_bytes"]
    return {
        "name": cfg.name, "input_hw": tuple(hw), "params": params, "batch_stats": stats,
        "conv_layers": len(convs), "size_mb": params * BYTES / MB, "size_mib": params * BYTES / MIB,
        "weights_file_bytes": (params + stats) * BYTES + HEADER_BYTES,
        "macs": macs, "gmacs": macs / 1e9, "gflops": 2 * macs / 1e9,
        "paper_params": paper_params, "paper_memory": mem,
        "paper_memory_mb": {k: v / MB for k, v in mem.items()},
        "paper_memory_mib": {k: v / MIB for k, v in mem.items()},
    }


def paper_memory_mib(cfg: CameraConfig, variables=None, layers: str = "all") -> float:
    """The paper's memory figure of `cfg` at 416 x 416 in MiB (params + layer outputs, fp32; `layers`
    'all' or 'conv', module docstring). `variables` is unused (the family record's `stem_memory`
    signature): the formula reads the architecture."""
    return footprint(cfg)["paper_memory_mib"][f"{layers}_total_bytes"]
