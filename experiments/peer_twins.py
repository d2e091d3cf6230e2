"""PyTorch twins of the project's non-ultralytics networks, with the project's own weights: the
DSFEC family's 2D network (stem, stages, top-down neck, three heads) and the camera family's
YOLOv3s (Darknet-53 and Shuffle backbones, the shared YOLOv3 head). It runs under an interpreter
with torch (not a dependency of the project), so it imports torch and numpy only.

    PEER/bin/python experiments/peer_twins.py CASE.npz [--threads 1]

CASE.npz comes from `python -m experiments.twin_export` (its docstring has the layout): the
description (family and config fields), the weights in flax's layout (HWIO kernels), an NHWC
input and the jitted JAX outputs. The twin is built from the description and the weights' shapes,
in PyTorch's own idiom (NCHW, `F.conv2d`, grouped convs for the depthwise ones,
`F.conv_transpose2d` for the neck's deconvs); a BatchNorm is applied where the weights still have
one (an unfolded export) and skipped where it was folded. `check` runs the network as it will be
timed (traced and frozen with TorchScript, under `inference_mode`) and compares every output with
JAX's: the largest absolute difference over the output's largest magnitude.

Conventions that have to match the project (layers/conv.py):
- TF 'SAME' padding: at stride 2 on an even size the extra pixel goes at the high end, so those
  convs pad explicitly; every other conv pads symmetrically inside the conv.
- `lax.conv_transpose(..., "SAME")` correlates the stride-dilated input with the kernel as it
  is; PyTorch's transposed conv uses the kernel flipped, so the twin flips it, runs with no
  padding and crops to the 'SAME' window (layers/conv.py `transpose_pads`).
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

BN_EPS = 1e-3  # layers/conv.py's batch_norm (Keras' default); used only when a BN was not folded
MAX_RELATIVE_ERROR = 3e-5  # largest |twin - JAX| over the output's largest |value|


# ---- weights ------------------------------------------------------------------------------------

class Weights:
    """The case's arrays by flax module path, as torch tensors in PyTorch's layouts."""

    def __init__(self, arrays: dict[str, np.ndarray]):
        self.arrays = arrays

    def has(self, collection: str, path: str, name: str) -> bool:
        return f"{collection}/{path}/{name}" in self.arrays

    def get(self, collection: str, path: str, name: str) -> torch.Tensor:
        key = f"{collection}/{path}/{name}"
        if key not in self.arrays:
            raise KeyError(f"the case has no {key!r}: the twin and the exported network disagree")
        return torch.from_numpy(np.ascontiguousarray(self.arrays[key]))

    def conv(self, path: str) -> tuple[torch.Tensor, torch.Tensor | None]:
        """(weight O x I x kH x kW, bias or None) of a dense or depthwise conv: HWIO -> OIHW."""
        kernel = self.get("params", path, "kernel").permute(3, 2, 0, 1).contiguous()
        return kernel, self.get("params", path, "bias") if self.has("params", path, "bias") else None

    def batch_norm(self, path: str):
        """(scale, bias, mean, var) of a BN still in the weights, or None where it was folded."""
        if not self.has("params", path, "scale"):
            return None
        return (self.get("params", path, "scale"), self.get("params", path, "bias"),
                self.get("batch_stats", path, "mean"), self.get("batch_stats", path, "var"))


def activation(name: str, leaky_slope: float):
    """The project's activations by name (layers/activations.py)."""
    table = {"relu": F.relu, "swish": F.silu, "hard_swish": F.hardswish, "mish": F.mish,
             "leaky_relu": lambda x: F.leaky_relu(x, leaky_slope),
             "gelu": lambda x: F.gelu(x, approximate="tanh")}  # jax.nn.gelu's default is the tanh form
    if name not in table:
        raise ValueError(f"activation {name!r} has no twin; known: {sorted(table)}")
    return table[name]


def same_pads(size: int, kernel: int, stride: int) -> tuple[int, int]:
    """TF 'SAME' (low, high) padding, the project's `layers.conv.same_pads`."""
    out = -(-size // stride)
    total = max((out - 1) * stride + kernel - size, 0)
    return total // 2, total - total // 2


# ---- layers -------------------------------------------------------------------------------------

class Conv(nn.Module):
    """A 'SAME' conv (dense, or depthwise when the kernel has one input channel per group) with
    the optional BN after it (None: folded) and an activation (None: linear)."""

    def __init__(self, weights: Weights, path: str, stride: int = 1, bn: str | None = None, act=None):
        super().__init__()
        weight, bias = weights.conv(path)
        self.weight = nn.Parameter(weight, requires_grad=False)
        self.bias = None if bias is None else nn.Parameter(bias, requires_grad=False)
        self.depthwise = weight.shape[1] == 1 and weight.shape[0] > 1
        self.stride, self.kernel = stride, weight.shape[-1]
        norm = weights.batch_norm(bn) if bn else None
        self.norm = None if norm is None else nn.ParameterList([nn.Parameter(t, requires_grad=False) for t in norm])
        self.act = act

    def forward(self, x):
        h, w, c = int(x.shape[2]), int(x.shape[3]), int(x.shape[1])  # constants of the trace (fixed input size)
        ph, pw = same_pads(h, self.kernel, self.stride), same_pads(w, self.kernel, self.stride)
        groups = c if self.depthwise else 1
        if ph[0] == ph[1] and pw[0] == pw[1]:
            y = F.conv2d(x, self.weight, self.bias, self.stride, (ph[0], pw[0]), 1, groups)
        else:
            y = F.conv2d(F.pad(x, (pw[0], pw[1], ph[0], ph[1])), self.weight, self.bias, self.stride, 0, 1, groups)
        if self.norm is not None:
            scale, shift, mean, var = self.norm
            y = F.batch_norm(y, mean, var, scale, shift, False, 0.0, BN_EPS)
        return y if self.act is None else self.act(y)


def conv_bn_act(weights: Weights, path: str, stride: int, act) -> Conv:
    """The project's `ConvBNAct` at `path` (its 'conv' and 'bn')."""
    return Conv(weights, f"{path}/conv", stride, f"{path}/bn", act)


class ConvTranspose(nn.Module):
    """`lax.conv_transpose(x, w, (s, s), "SAME")` plus bias; the stride is the ratio of the sizes
    the caller asks for (the neck's `factor`)."""

    def __init__(self, weights: Weights, path: str):
        super().__init__()
        kernel = weights.get("params", path, "kernel")  # K, K, I, O
        self.weight = nn.Parameter(kernel.flip(0, 1).permute(2, 3, 0, 1).contiguous(), requires_grad=False)
        self.bias = nn.Parameter(weights.get("params", path, "bias"), requires_grad=False)
        self.kernel = kernel.shape[0]

    def forward(self, x, stride: int):
        k, h, w = self.kernel, int(x.shape[2]), int(x.shape[3])
        total = k + stride - 2  # layers/conv.py transpose_pads: the dilated input's padding
        low = k - 1 if stride > k - 1 else -(-total // 2)
        start = k - 1 - low  # padding 0 pads k - 1 on each side; crop what 'SAME' does not pad
        y = F.conv_transpose2d(x, self.weight, self.bias, stride)
        return y[:, :, start:start + h * stride, start:start + w * stride]


# ---- DSFEC --------------------------------------------------------------------------------------

class DSConv(nn.Module):
    def __init__(self, weights, path, stride, act):
        super().__init__()
        self.dw = Conv(weights, f"{path}/dw", stride, f"{path}/dw_bn", act)
        self.pw = Conv(weights, f"{path}/pw", 1, f"{path}/pw_bn", act)

    def forward(self, x):
        return self.pw(self.dw(x))


class ResidualBottleneck(nn.Module):
    def __init__(self, weights, path, stride, act):
        super().__init__()
        self.conv1 = Conv(weights, f"{path}/conv1", 1, f"{path}/bn1", act)
        self.conv2 = Conv(weights, f"{path}/conv2", stride, f"{path}/bn2", act)
        self.conv3 = Conv(weights, f"{path}/conv3", 1, f"{path}/bn3")
        has_proj = weights.has("params", f"{path}/proj", "kernel")
        self.proj = Conv(weights, f"{path}/proj", stride, f"{path}/proj_bn") if has_proj else None
        self.act = act

    def forward(self, x):
        y = self.conv3(self.conv2(self.conv1(x)))
        return self.act(y + (x if self.proj is None else self.proj(x)))


class DenseHead(nn.Module):
    def __init__(self, weights, path, d, act):
        super().__init__()
        tower = []
        for i in range(d["head_convs"]):
            if d["head_kind"] == "conv":
                tower.append(conv_bn_act(weights, f"{path}/tower{i}", 1, act))
            else:
                tower.append(DSConv(weights, f"{path}/tower{i}", 1, act))
        self.tower = nn.Sequential(*tower)
        self.cls = Conv(weights, f"{path}/cls")
        self.box = Conv(weights, f"{path}/box")

    def forward(self, x):
        x = self.tower(x)
        return self.cls(x), self.box(x)


class DSFECTwin(nn.Module):
    """BEV image (B, C, nx, ny) -> (car cls, car box, truck cls, truck box, vru cls, vru box)."""

    def __init__(self, weights: Weights, d: dict):
        super().__init__()
        act = {f: activation(d[f], d["leaky_slope"]) for f in d if f.startswith("act_")}
        self.stem = nn.Sequential(*[conv_bn_act(weights, f"stem{i}", 1, act["act_stem"])
                                    for i in range(d["stem_convs"])])
        block = DSConv if d["block"] == "dsconv" else ResidualBottleneck
        self.stages = nn.ModuleList(
            nn.Sequential(*[block(weights, f"stage{i + 1}_block{b}", d["stage_strides"][i] if b == 0 else 1,
                                  act["act_backbone"]) for b in range(d["stage_blocks"][i])]) for i in range(4))
        used = len(d["neck_widths"])
        self.laterals = nn.ModuleList(Conv(weights, f"neck/lateral{i}") for i in range(used))
        self.deconvs = nn.ModuleList(ConvTranspose(weights, f"neck/deconv{i}") for i in range(1, used))
        self.heads = nn.ModuleList(DenseHead(weights, f"head_{name}", d, act[f"act_{name}_head"])
                                   for name in d["heads"])

    def forward(self, image):
        x, stages = self.stem(image), []
        for stage in self.stages:
            x = stage(x)
            stages.append(x)
        used = stages[::-1][:len(self.laterals)]
        x = self.laterals[0](used[0])
        for deconv, lateral, tap in zip(self.deconvs, list(self.laterals)[1:], used[1:]):
            x = deconv(x, int(tap.shape[2]) // int(x.shape[2])) + lateral(tap)
        return tuple(t for head in self.heads for t in head(x))


# ---- camera YOLOv3 ------------------------------------------------------------------------------

def channel_shuffle(x):
    """torchvision's channel shuffle with 2 groups."""
    b, c, h, w = x.shape
    return x.view(b, 2, c // 2, h, w).transpose(1, 2).reshape(b, c, h, w)


class ShuffleUnit(nn.Module):
    def __init__(self, weights, path, stride, act, split):
        super().__init__()
        self.stride, self.split = stride, split

        def pointwise(name):
            return Conv(weights, f"{path}/{name}", 1, f"{path}/{name}_bn", act)

        def depthwise(name):
            return Conv(weights, f"{path}/{name}", stride, f"{path}/{name}_bn")

        self.main = nn.Sequential(pointwise("main_pw1"), depthwise("main_dw"), pointwise("main_pw2"))
        if stride == 2:
            self.proj = nn.Sequential(depthwise("proj_dw"), pointwise("proj_pw"))

    def forward(self, x):
        if self.stride == 2:
            y = torch.cat([self.proj(x), self.main(x)], 1)
        elif self.split == "chunk":
            kept, rest = x.chunk(2, 1)
            y = torch.cat([kept, self.main(rest)], 1)
        else:
            y = torch.cat([x[:, 0::2], self.main(x[:, 1::2])], 1)
        return channel_shuffle(y) if self.split == "chunk" else y


class DarknetResidual(nn.Module):
    def __init__(self, weights, path, act):
        super().__init__()
        self.conv1 = conv_bn_act(weights, f"{path}/conv1", 1, act)
        self.conv2 = conv_bn_act(weights, f"{path}/conv2", 1, act)

    def forward(self, x):
        return x + self.conv2(self.conv1(x))


def darknet_backbone(weights, d, act) -> list[nn.Module]:
    """The stem folded into stage 0; one module per stage."""
    stages = []
    for s, repeats in enumerate(d["repeats"]):
        layers = [conv_bn_act(weights, "backbone/stem", 1, act)] if s == 0 else []
        layers.append(conv_bn_act(weights, f"backbone/stage{s}/down", 2, act))
        layers += [DarknetResidual(weights, f"backbone/stage{s}/res{i}", act) for i in range(repeats)]
        stages.append(nn.Sequential(*layers))
    return stages


def shuffle_backbone(weights, d) -> list[nn.Module]:
    stages = []
    for s, repeats in enumerate(d["repeats"]):
        act_name = d["stage_styles"][s][1]  # the kernel size comes with the weights
        act = activation(act_name, d["leaky_slope"])
        if s == 0 and d["first_repeat"] == "stem":
            stages.append(conv_bn_act(weights, "backbone/stage0", 2, act))
            continue
        layers = [conv_bn_act(weights, "backbone/stem", 1, act)] if s == 0 else []
        layers += [ShuffleUnit(weights, f"backbone/stage{s}_{i}", 2 if i == 0 else 1, act, d["split"])
                   for i in range(repeats)]
        stages.append(nn.Sequential(*layers))
    return stages


class CameraTwin(nn.Module):
    """Image (B, 3, H, W) -> the three raw maps (B, A (5 + C), H/s, W/s), stride 8 first."""

    TAPS = (2, 3, 4)

    def __init__(self, weights: Weights, d: dict):
        super().__init__()
        darknet = d["backbone"] == "darknet53"
        self.stages = nn.ModuleList(darknet_backbone(weights, d, activation(d["act"], d["leaky_slope"])) if darknet
                                    else shuffle_backbone(weights, d))
        levels = len(self.TAPS)
        acts = [activation(d["act"] if darknet else d["head_styles"][lv][1], d["leaky_slope"]) for lv in range(levels)]
        self.levels = nn.ModuleList(CameraLevel(weights, d, lv, acts[lv], darknet) for lv in range(levels))
        self.outs = nn.ModuleList(Conv(weights, f"head/out{lv}") for lv in range(levels))
        # the lateral into level lv takes the activation of the level it leaves (lv + 1)
        self.laterals = nn.ModuleList(conv_bn_act(weights, f"head/lateral{lv}", 1, acts[lv + 1])
                                      for lv in range(levels - 1))
        self.concat = d["fpn_merge"] == "concat"

    def forward(self, image):
        x, feats = image, []
        for stage in self.stages:
            x = stage(x)
            feats.append(x)
        taps = [feats[i] for i in self.TAPS]
        maps = [None] * len(taps)
        x = taps[-1]
        for lv in reversed(range(len(taps))):
            if lv < len(taps) - 1:
                up = F.interpolate(self.laterals[lv](branch), scale_factor=2.0, mode="nearest")
                x = torch.cat([up, taps[lv]], 1) if self.concat else up + taps[lv]
            branch, out = self.levels[lv](x)
            maps[lv] = self.outs[lv](out)
        return tuple(maps)


class CameraLevel(nn.Module):
    """One YOLO layer: x -> (branch, out). Darknet's: five convs (the branch), then a 3x3 conv
    ('conv5', the out); Shuffle's: the entry conv and the shuffle units, branch and out alike."""

    def __init__(self, weights, d, lv, act, darknet):
        super().__init__()
        path = f"head/level{lv}"
        if darknet:
            self.branch = nn.Sequential(*[conv_bn_act(weights, f"{path}/conv{i}", 1, act) for i in range(5)])
            self.out = conv_bn_act(weights, f"{path}/conv5", 1, act)
        else:
            units = [ShuffleUnit(weights, f"{path}/unit{i}", 1, act, d["split"]) for i in range(d["head_units"])]
            self.branch = nn.Sequential(conv_bn_act(weights, f"{path}/entry", 1, act), *units)
            self.out = nn.Identity()

    def forward(self, x):
        branch = self.branch(x)
        return branch, self.out(branch)


# ---- building, checking ---------------------------------------------------------------------------

def load(path: str) -> tuple[nn.Module, dict, np.ndarray, list[np.ndarray]]:
    """(twin in eval mode, description, NHWC input, JAX outputs) of the case at `path`."""
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    d = json.loads(str(arrays["description"]))
    weights = Weights(arrays)
    if d["family"] == "dsfec":
        twin = DSFECTwin(weights, d)
    elif d["family"] == "camera":
        twin = CameraTwin(weights, d)
    else:
        raise ValueError(f"{path}: description.family={d['family']!r}; expected 'dsfec' or 'camera'")
    outputs = [arrays[f"output/{i}"] for i in range(sum(k.startswith("output/") for k in arrays))]
    return twin.eval(), d, arrays["input"], outputs


def frozen(twin: nn.Module, image: torch.Tensor):
    """The twin traced and frozen with TorchScript, as the peer times it."""
    with torch.inference_mode(), warnings.catch_warnings():
        # the trace keeps the sizes it saw as constants (what a fixed-size deployment wants), and
        # torch says so at every conv; its deprecation notes about TorchScript are noise here too
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        warnings.simplefilter("ignore", FutureWarning)
        return torch.jit.freeze(torch.jit.trace(twin, image, check_trace=False))


def to_project_layout(t: torch.Tensor, reference: np.ndarray) -> np.ndarray:
    """A twin output (NCHW) in the JAX output's layout (NHWC, the camera's anchors split out)."""
    return t.permute(0, 2, 3, 1).contiguous().numpy().reshape(reference.shape)


def check(net, image: torch.Tensor, outputs: list[np.ndarray]) -> dict:
    """Per output: max |twin - JAX| and that over max |JAX|; 'ok' when every relative one is within
    MAX_RELATIVE_ERROR."""
    with torch.inference_mode():
        got = net(image)
    rows = []
    for t, ref in zip(got, outputs):
        diff = float(np.max(np.abs(to_project_layout(t, ref) - ref)))
        scale = float(np.max(np.abs(ref)))
        rows.append({"shape": list(ref.shape), "max_abs_diff": diff, "max_abs": scale,
                     "relative": diff / max(scale, 1e-30)})
    if len(got) != len(outputs):
        raise ValueError(f"the twin gives {len(got)} outputs, JAX {len(outputs)}")
    worst = max(r["relative"] for r in rows)
    return {"ok": worst <= MAX_RELATIVE_ERROR, "worst_relative": worst, "tolerance": MAX_RELATIVE_ERROR,
            "outputs": rows}


LAYOUTS = ("channels_last", "contiguous")


def build_checked(path: str, layout: str = "channels_last"):
    """(frozen twin, its input, the check) of the case at `path`; raises if the check fails.
    `layout`: the tensors' memory format, 'channels_last' (oneDNN's preferred one on the CPU, and
    PyTorch's advice for convolutional networks there) or 'contiguous' (plain NCHW)."""
    if layout not in LAYOUTS:
        raise ValueError(f"layout={layout!r}; expected one of {LAYOUTS}")
    twin, d, image_nhwc, outputs = load(path)
    image = torch.from_numpy(np.ascontiguousarray(image_nhwc.transpose(0, 3, 1, 2)))
    if layout == "channels_last":
        twin, image = twin.to(memory_format=torch.channels_last), image.to(memory_format=torch.channels_last)
    net = frozen(twin, image)
    result = {"model": d["model"], "layout": layout, **check(net, image, outputs)}
    if not result["ok"]:
        raise AssertionError(f"{d['model']}: the twin differs from JAX by {result['worst_relative']:.2e} of the "
                             f"output's scale (tolerance {MAX_RELATIVE_ERROR:.0e}): {json.dumps(result['outputs'])}")
    return net, image, result


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("case", help="an .npz from `python -m experiments.twin_export`")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--layout", choices=LAYOUTS, default="channels_last")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    try:
        _, _, result = build_checked(args.case, args.layout)
    except AssertionError as e:
        print(e, file=sys.stderr)
        return 1
    print(json.dumps({k: v for k, v in result.items() if k != "outputs"}))
    for row in result["outputs"]:
        print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
