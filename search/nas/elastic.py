"""Elastic widths for a weight-sharing supernet: one full-width network whose subnet is an input.

The supernet is the space's largest subnet (with YOLO's Exchangers in the searchable fusion mode,
models/yolo_rd/adapter.py). A subnet runs through it with a channel mask on the output of every
conv block (`YoloConv`: conv + BN + SiLU), applied after the activation, so the masked channels
are exactly 0 wherever they go. The masks are arrays passed into the compiled function, so one
compiled step serves every subnet (USConv's leading-slice weights, Fig. 4, without a recompile
per width). What the masks keep is the subnet's own network:
- a conv block of width c' keeps its first c' channels, except the `cv1` of a C2f-style block
  (split in two halves after it), which keeps the first c' of each half;
- a kept channel only ever reads kept channels (the others are 0), so its conv computes what the
  sliced W[:c'_out, :c'_in] computes, and its training-mode BN statistics are the sliced net's;
- concatenation, splitting, residual adds, max pools (their window always holds a real 0), upsampling,
  area resizing, the Exchangers' fusion weights and Coordinate Attention (X x a gate) keep zero
  channels at zero.
BN running statistics: every subnet updates the shared running statistics (the masked channels'
with meaningless values), so, as SPOS and the paper do, a subnet's statistics are recalibrated on
training batches before it is scored.

`extract` takes a subnet's weights out of the supernet: the output axes of the conv blocks by the
mask layout above, the input axes by a probe pass in which every conv block outputs its mask and
every conv records which of its input channels are non-zero. A test checks that the stand-alone
network built from the subnet's config, with those weights, computes what the masked supernet does.
"""

from __future__ import annotations

from typing import Iterator

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from dsfec_jax import zoo
from dsfec_jax.layers.yolo import PaddedConv, YoloConv

from .slices import claim_widths, masked_apply  # noqa: F401  (masked_apply: masks on blocks' outputs by path)

Path = tuple[str, ...]


def _is_conv_block(tree) -> bool:
    return isinstance(tree, dict) and "conv" in tree and "bn" in tree and "kernel" in tree["conv"]


def conv_blocks(params: dict, prefix: Path = ()) -> Iterator[tuple[Path, dict, dict]]:
    """(path, block params, parent params) of every conv block (a YoloConv) in a params tree."""
    for name, sub in params.items():
        if not isinstance(sub, dict):
            continue
        if _is_conv_block(sub):
            yield prefix + (name,), sub, params
        else:
            yield from conv_blocks(sub, prefix + (name,))


def _halved(name: str, parent: dict) -> bool:
    """A C2f-style block's cv1, whose output is split in two halves (csp_chain: cv1, m0.., cv2)."""
    return name == "cv1" and "cv2" in parent and "m0" in parent


def kept_channels(full: int, width: int, halved: bool) -> np.ndarray:
    """Indices of the channels a block of `full` channels keeps at subnet width `width`."""
    if not halved:
        return np.arange(width)
    return np.concatenate([np.arange(width // 2), full // 2 + np.arange(width // 2)])


def param_shapes(detector) -> dict:
    """The parameter shapes of a network (no compile). Cached per (class, config, x64 mode): a mask
    table traces the same few dozen configs for every supernet a run builds (seconds of tracing
    each time for the YOLO space: docs/search.md, "SPOS"). The cached tree is shared: read it, never change it."""
    key = _shapes_key(detector)
    if key is None:
        return _traced_shapes(detector)
    if key not in _PARAM_SHAPES:
        if len(_PARAM_SHAPES) >= _PARAM_SHAPES_KEPT:
            _PARAM_SHAPES.clear()
        _PARAM_SHAPES[key] = _traced_shapes(detector)
    return _PARAM_SHAPES[key]


_PARAM_SHAPES: dict = {}
_PARAM_SHAPES_KEPT = 256


def _shapes_key(detector) -> tuple | None:
    """(class, config, x64: float64 dtypes), or None where the config is missing or unhashable."""
    key = (type(detector), getattr(detector, "config", None), jax.config.jax_enable_x64)
    try:
        hash(key)
    except TypeError:
        return None
    return key if key[1] is not None else None


def _traced_shapes(detector) -> dict:
    return jax.eval_shape(lambda: detector.init(jax.random.key(0)))["params"]


def block_widths(detector) -> dict[Path, int]:
    """{conv block path: output width} of a network (from shapes only)."""
    return {p: b["conv"]["kernel"].shape[-1] for p, b, _ in conv_blocks(param_shapes(detector))}


def kept_outputs(supernet, subnet) -> dict[Path, np.ndarray]:
    """{conv block path: the supernet channels the subnet keeps} (same module paths in both)."""
    full = {p: (b["conv"]["kernel"].shape[-1], _halved(p[-1], parent)) for p, b, parent in conv_blocks(param_shapes(supernet))}
    out = {}
    for p, b, _ in conv_blocks(param_shapes(subnet)):
        if p not in full:
            raise ValueError(f"conv block {'/'.join(p)} of the subnet is not in the supernet")
        width = b["conv"]["kernel"].shape[-1]
        out[p] = kept_channels(full[p][0], width, full[p][1])
    return out


def masks(supernet, subnet) -> dict[str, jax.Array]:
    """{'/'-joined conv block path: (C,) float32 mask}: the input `masked_apply` takes."""
    shapes = {p: b["conv"]["kernel"].shape[-1] for p, b, _ in conv_blocks(param_shapes(supernet))}
    out = {}
    for p, kept in kept_outputs(supernet, subnet).items():
        m = np.zeros(shapes[p], np.float32)
        m[kept] = 1.0
        out["/".join(p)] = jnp.asarray(m)
    return out


def probe_inputs(supernet, variables: dict, channel_masks: dict) -> dict[Path, np.ndarray]:
    """{conv path: indices of its non-zero input channels} when every conv block outputs its mask:
    the channels each conv reads in the subnet (eager, once per subnet)."""
    seen: dict[Path, np.ndarray] = {}

    def interceptor(next_fun, args, kwargs, context):
        module = context.module
        if isinstance(module, PaddedConv) and context.method_name == "__call__":
            x = np.asarray(args[0])
            seen[tuple(module.scope.path)] = np.flatnonzero(np.any(x != 0, axis=tuple(range(x.ndim - 1))))
        out = next_fun(*args, **kwargs)
        if isinstance(module, YoloConv) and context.method_name == "__call__":
            m = channel_masks.get("/".join(module.scope.path))
            if m is not None:
                out = jnp.broadcast_to(m, out.shape)
        return out

    ones = {k: np.ones_like(v) for k, v in supernet.dummy_inputs(1).items()}
    with nn.intercept_methods(interceptor):
        supernet.apply(variables, ones)
    return seen


def extract(supernet, variables: dict, subnet) -> dict:
    """The subnet's variables ({'params', 'batch_stats'}, the subnet's tree and shapes) sliced out of
    the supernet's `variables`."""
    channel_masks = masks(supernet, subnet)
    outputs = kept_outputs(supernet, subnet)
    inputs = probe_inputs(supernet, variables, channel_masks)
    target = jax.eval_shape(lambda: subnet.init(jax.random.key(0)))

    def take(path: Path, leaf, source):
        source = np.asarray(source)
        index = []
        for axis, (n_sub, n_sup) in enumerate(zip(leaf.shape, source.shape)):
            if n_sub == n_sup:
                index.append(slice(None))
            elif leaf.ndim == 4 and axis == 2:  # a conv kernel's input channels
                index.append(_checked(inputs[path[1:-1]], n_sub, path))
            else:  # output channels: a conv block's kept ones, else the leading ones
                index.append(_checked(_owner_outputs(path[1:], outputs, n_sub), n_sub, path))
        return jnp.asarray(source[np.ix_(*[np.arange(s)[i] if isinstance(i, slice) else i
                                           for s, i in zip(source.shape, index)])])

    def walk(tree, src, path):
        if isinstance(tree, dict):
            missing = set(tree) - set(src)
            if missing:
                raise ValueError(f"{'/'.join(path)}: the supernet has no {sorted(missing)}")
            return {k: walk(v, src[k], path + (k,)) for k, v in tree.items()}
        return take(path, tree, src)

    return {c: walk(target[c], variables[c], (c,)) for c in target if c in ("params", "batch_stats")}


def _owner_outputs(path: Path, outputs: dict[Path, np.ndarray], n: int) -> np.ndarray:
    """The kept output channels of the conv block owning the leaf at `path` (its conv or BN), or
    the first n for a leaf outside conv blocks (a bare conv's bias and outputs)."""
    for cut in range(len(path) - 1, 0, -1):
        if path[:cut] in outputs:
            return outputs[path[:cut]]
    return np.arange(n)


def _checked(index: np.ndarray, n: int, path: Path) -> np.ndarray:
    if len(index) != n:
        raise ValueError(f"{'/'.join(path)}: the probe found {len(index)} channels where the subnet has {n}")
    return index


class MaskTable:
    """Masks of any subnet without tracing it: each conv block's width is set by at most one gene
    (a backbone block, a Stem conv or a pyramid level; an Exchanger's projection follows its
    primary's), so the widths are read once per (gene, option) from the subnets that differ from
    the largest in that gene alone (about 40 shape traces for Table 1), and a subnet's masks are
    then look-ups: fast enough to draw a new subnet every SPOS step. A block that two genes set,
    or a gene that adds or removes blocks (depth), is refused here (a test checks the table
    against `masks` on sampled subnets)."""

    def __init__(self, space, supernet):
        self.space = space
        params = param_shapes(supernet)
        self.full = {p: (b["conv"]["kernel"].shape[-1], _halved(p[-1], parent)) for p, b, parent in conv_blocks(params)}
        full_widths = {p: width for p, (width, _) in self.full.items()}
        self.control: dict[Path, tuple[int, dict[int, int]]] = {}
        largest = space.largest()
        top = space.overrides(largest)
        for i, choice in enumerate(space.choices):
            for o in range(len(choice.options) - 1):
                genes = largest[:i] + (o,) + largest[i + 1:]
                overrides = space.overrides(genes)
                if {k for k in overrides if overrides[k] != top.get(k)} <= {"fusion"}:
                    continue  # a fusion option is an input of the supernet ('nas'), not a width
                widths = block_widths(zoo.create(space.base, **overrides))
                if set(widths) != set(self.full):
                    raise ValueError(f"{space.name}: {choice.name}={choice.options[o]} changes which conv blocks exist "
                                     "(a depth choice): masks cannot select it")
                claim_widths(self.control, space, i, o, widths, full_widths, "conv block")

    def widths(self, genes) -> dict[Path, int]:
        out = {}
        for p, (full, _) in self.full.items():
            owner = self.control.get(p)
            out[p] = owner[1].get(genes[owner[0]], full) if owner else full
        return out

    def masks(self, genes) -> dict[str, np.ndarray]:
        """{'/'-joined path: (C,) float32 mask} of the subnet `genes` (as `masks` gives)."""
        out = {}
        for p, w in self.widths(tuple(genes)).items():
            full, halved = self.full[p]
            m = np.zeros(full, np.float32)
            m[kept_channels(full, w, halved)] = 1.0
            out["/".join(p)] = m
        return out


def supernet_of(space) -> "zoo.Detector":
    """The space's supernet: its largest subnet, with searchable fusions where the space has any."""
    overrides = space.overrides(space.largest())
    if "fusion" in overrides:
        overrides["fusion"] = 0
    return zoo.create(space.base, **overrides)


def with_fusions(variables: dict, fusions) -> dict:
    """The supernet's variables with Exchanger k's fusion option set to fusions[k] (the 'nas'
    collection: `exchangers_<k>/fusion`, arrays, so choices do not recompile)."""
    nas = variables.get("nas")
    if nas is None:
        return variables
    def put(tree):
        return {k: (put(v) if isinstance(v, dict) and "fusion" not in v
                    else {"fusion": jnp.int32(fusions[int(k.rsplit("_", 1)[1])])}) for k, v in tree.items()}
    return {**variables, "nas": put(nas)}
