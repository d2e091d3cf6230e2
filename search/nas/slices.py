"""Elastic widths by leading slices: a weight-sharing supernet whose subnets keep the first c
channels of every searchable layer (USConv's W[:c_out, :c_in], Fig. 4 of the YOLOv8n-Adapter
paper), for networks built of plain conv / BN / linear modules (DSFEC: FEC, stem, DSConv blocks).

A subnet runs through the supernet with a channel mask on the output of every module whose width
the space changes (its convs, linears and batch norms: the mask after BN makes a masked channel 0
whatever BN's shift; DSFEC's activations all map 0 to 0). The masks are inputs of the compiled
function, so one compile serves every width (search/nas/elastic.py does the same for YOLO's
C2f layout). What the masks keep is the subnet's own network: a kept channel reads only kept
channels (the rest are 0), so it computes what the sliced weights compute, and its training-mode
BN statistics are the sliced network's. Depthwise convs, scatter, max pooling over points and the
neck's inputs keep zero channels at zero. Depth is the family's traced `depth` input
(search.oneshot), so depth choices need no mask.

`extract` is then plain slicing: every leaf of the subnet's tree is the leading block of the
supernet's leaf of the same path (a test checks the stand-alone network built from the subnet's
config, with the extracted weights, against the masked supernet).
"""

from __future__ import annotations

from typing import Iterator

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from dsfec_jax import zoo

from .space import Genes, SearchSpace

Path = tuple[str, ...]
WIDTH_LEAVES = ("kernel", "scale")  # a module's output width: its kernel's or its BN scale's last axis


def module_widths(params: dict, prefix: Path = ()) -> Iterator[tuple[Path, int]]:
    """(path, output width) of every module with a kernel or a BN scale."""
    leaf = next((params[k] for k in WIDTH_LEAVES if k in params and not isinstance(params[k], dict)), None)
    if leaf is not None:
        yield prefix, int(leaf.shape[-1])
    for name, sub in params.items():
        if isinstance(sub, dict):
            yield from module_widths(sub, prefix + (name,))


def widths_of(detector) -> dict[Path, int]:
    shapes = jax.eval_shape(lambda: detector.init(jax.random.key(0)))["params"]
    return dict(module_widths(shapes))


class SliceMasks:
    """genes -> {'/'-joined module path: (C,) float32 mask} for every module whose width some
    gene changes, without tracing the subnet: each width gene's options are read once from the
    subnets that differ from the largest in that gene alone (depth genes held at their largest,
    since they add or remove whole blocks, not channels). A module set by two genes is refused."""

    def __init__(self, space: SearchSpace):
        self.space = space
        largest = space.largest()
        self.full = widths_of(zoo.create(space.base, **space.overrides(largest)))
        self.control: dict[Path, tuple[int, dict[int, int]]] = {}
        for i, choice in enumerate(space.choices):
            if choice.kind == "depth":
                continue
            for o in range(len(choice.options) - 1):
                genes = largest[:i] + (o,) + largest[i + 1:]
                widths = widths_of(zoo.create(space.base, **space.overrides(genes)))
                if set(widths) != set(self.full):
                    raise ValueError(f"{space.name}: {choice.name}={choice.options[o]} changes which modules exist; "
                                     "only depth choices may (kind='depth')")
                claim_widths(self.control, space, i, o, widths, self.full, "module")

    def widths(self, genes: Genes) -> dict[Path, int]:
        return {p: table.get(genes[i], self.full[p]) for p, (i, table) in self.control.items()}

    def masks(self, genes: Genes) -> dict[str, np.ndarray]:
        out = {}
        for p, w in self.widths(tuple(genes)).items():
            m = np.zeros(self.full[p], np.float32)
            m[:w] = 1.0
            out["/".join(p)] = m
        return out


def claim_widths(control: dict, space: SearchSpace, gene: int, option: int, widths: dict, full: dict,
                 what: str) -> None:
    """Record in `control` ({path: (gene, {option: width})}) the widths that `gene` at `option` sets
    (the paths whose width differs from `full`'s), refusing a path another gene already sets: a
    width read from one look-up table must have one owner."""
    for p, w in widths.items():
        if w == full[p]:
            continue
        owner, table = control.setdefault(p, (gene, {}))
        if owner != gene:
            raise ValueError(f"{space.name}: {what} {'/'.join(p)} is set by both "
                             f"{space.choices[owner].name} and {space.choices[gene].name}")
        table[option] = w


def _mask_outputs(channel_masks: dict):
    def interceptor(next_fun, args, kwargs, context):
        out = next_fun(*args, **kwargs)
        if context.method_name == "__call__":
            m = channel_masks.get("/".join(context.module.scope.path))
            if m is not None:
                out = out * m
        return out

    return interceptor


def masked_apply(supernet, variables: dict, inputs: dict, channel_masks: dict, train: bool = False):
    """The supernet's outputs for the subnet `channel_masks` select (as `Detector.apply`)."""
    with nn.intercept_methods(_mask_outputs(channel_masks)):
        return supernet.apply(variables, inputs, train=train)


def extract(variables: dict, subnet) -> dict:
    """The subnet's {'params', 'batch_stats'} (its own tree and shapes): the leading slice of the
    supernet's leaf at every path of the subnet's tree."""
    target = jax.eval_shape(lambda: subnet.init(jax.random.key(0)))

    def walk(tree, src, path):
        if isinstance(tree, dict):
            missing = set(tree) - set(src)
            if missing:
                raise ValueError(f"{'/'.join(path)}: the supernet has no {sorted(missing)}")
            return {k: walk(v, src[k], path + (k,)) for k, v in tree.items()}
        src = np.asarray(src)
        if src.ndim != len(tree.shape) or any(n > m for n, m in zip(tree.shape, src.shape)):
            raise ValueError(f"{'/'.join(path)}: subnet shape {tree.shape} is not a leading slice of {src.shape}")
        return jnp.asarray(src[tuple(slice(0, n) for n in tree.shape)])

    return {c: walk(target[c], variables[c], (c,)) for c in ("params", "batch_stats") if c in target}
