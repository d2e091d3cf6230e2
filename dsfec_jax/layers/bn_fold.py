"""Fold evaluation-mode BatchNorm into the convolution before it, for any flax network.

In evaluation BN is a per-channel affine map, y = (x - mean) * s + beta with s = gamma /
sqrt(var + eps). When x is a convolution's output and nothing else reads x, the map folds into
the conv: kernel' = kernel * s along the output channels, bias' = beta + (bias - mean) * s. That is
ultralytics' `model.fuse()` and what ONNX Runtime's optimizer does to an exported graph; here it
is done once to the variables, so the jitted inference function has no scale-and-shift left.

No family needs code of its own: `find_folds` traces the network once (`jax.make_jaxpr`, nothing
computed) under a method interceptor that marks every conv's output and every BN's input with a
named identity, then reads the jaxpr: a BN whose input IS a conv's output, read by nothing else,
is a pair. A conv output with a second reader (a residual, a second branch), a module called twice
(shared weights) or a BN in training mode is left as it is. `folded_variables` rewrites the
variables: the conv's kernel scaled, its bias set (a new 'bias' param beside the kernel when the
conv had none), the BN's variables gone. `folded_call` runs the same network under an
interceptor that returns a folded BN's input unchanged and adds the new bias after a conv that
has no bias of its own: interceptors act while tracing only, so the compiled program holds the
conv and one bias add, which XLA fuses with the activation after it.
"""

from __future__ import annotations

import collections
import dataclasses
from typing import Callable

import flax.linen as nn
import jax
import jax.extend.core as jex
import jax.numpy as jnp
from jax.ad_checkpoint import checkpoint_name

from . import conv, yolo, yolo_v10
from .batch_norm import BatchNorm

Path = tuple[str, ...]

# Modules whose output channel o is sum(input * kernel[..., o]) (+ bias[o]): scaling the kernel's
# last axis scales output channel o, whatever the layout before it (KKIO, KK1C depthwise, IO).
CHANNEL_LINEAR = (conv.Conv, conv.DepthwiseConv, conv.ConvTranspose, conv.PointLinear, yolo.PaddedConv,
                  yolo_v10.DepthwiseConv, nn.Conv, nn.ConvTranspose, nn.Dense)
BATCH_NORMS = (BatchNorm, nn.BatchNorm)
_MARK = "bn_fold"  # prefix of the named identities the finding trace adds


@dataclasses.dataclass(frozen=True)
class Fold:
    """One conv -> BN pair: module paths, the BN's epsilon, and whether the conv adds a bias itself."""

    conv: Path
    bn: Path
    epsilon: float
    conv_has_bias: bool


@dataclasses.dataclass(frozen=True)
class FoldPlan:
    """Every pair of one network: static, so a folded network's apply can close over it."""

    folds: tuple[Fold, ...]

    @property
    def folded_bns(self) -> frozenset[Path]:
        return frozenset(f.bn for f in self.folds)

    @property
    def added_biases(self) -> frozenset[Path]:
        return frozenset(f.conv for f in self.folds if not f.conv_has_bias)


def _is_eval_bn(module, kwargs) -> bool:
    """A BN over the last axis that normalises with its running averages (what folds)."""
    if isinstance(module, BatchNorm):
        return module.use_running_average
    if module.axis != -1 or not (module.use_scale and module.use_bias):
        return False
    return bool(nn.merge_param("use_running_average", module.use_running_average,
                               kwargs.get("use_running_average")))


def find_folds(call: Callable, variables, *args) -> FoldPlan:
    """The conv -> BN pairs of the network that `call(variables, *args)` runs (a flax `apply` in
    evaluation mode); `variables` and `args` may be arrays or shape structs."""
    convs, bns, calls = {}, {}, collections.Counter()

    def mark(next_fun, fargs, kwargs, context):
        module = context.module
        if context.method_name != "__call__":
            return next_fun(*fargs, **kwargs)
        path = tuple(module.path)
        calls[path] += 1
        if isinstance(module, BATCH_NORMS) and _is_eval_bn(module, kwargs):
            bns[path] = module.epsilon
            return next_fun(checkpoint_name(fargs[0], f"{_MARK}/bn/{len(bns) - 1}"), *fargs[1:], **kwargs)
        out = next_fun(*fargs, **kwargs)
        if isinstance(module, CHANNEL_LINEAR):
            convs[path] = module.has_variable("params", "bias")
            return checkpoint_name(out, f"{_MARK}/conv/{len(convs) - 1}")
        return out

    with nn.intercept_methods(mark):
        jaxpr = jax.make_jaxpr(call)(variables, *args).jaxpr
    conv_paths, bn_paths = list(convs), list(bns)
    conv_out, bn_in, readers = _marks_and_readers(jaxpr)
    folds = []
    for j, var in bn_in.items():
        i = conv_out.get(var)
        if i is None or readers[var] != 1:  # not a conv's output, or read by something besides this BN
            continue
        cp, bp = conv_paths[i], bn_paths[j]
        if calls[cp] == 1 and calls[bp] == 1:  # a shared module would fold one use into every use
            folds.append(Fold(cp, bp, float(bns[bp]), convs[cp]))
    return FoldPlan(tuple(sorted(folds, key=lambda f: f.bn)))


def _marks_and_readers(jaxpr):
    """(conv output var -> conv index, BN index -> BN input var, var -> times read) over the jaxpr
    and every jaxpr nested in it (jitted helpers, custom gradients, loops)."""
    conv_out, bn_in, readers = {}, {}, collections.Counter()
    stack = [jaxpr]
    while stack:
        jp = stack.pop()
        for eqn in jp.eqns:
            for v in eqn.invars:
                if not isinstance(v, jex.Literal):
                    readers[v] += 1
            name = eqn.params.get("name", "") if eqn.primitive.name == "name" else ""
            if name.startswith(f"{_MARK}/conv/"):
                conv_out[eqn.outvars[0]] = int(name.rsplit("/", 1)[1])
            elif name.startswith(f"{_MARK}/bn/"):
                bn_in[int(name.rsplit("/", 1)[1])] = eqn.invars[0]
            stack.extend(jex.jaxprs_in_params(eqn.params))
        for v in jp.outvars:
            if not isinstance(v, jex.Literal):
                readers[v] += 1
    return conv_out, bn_in, readers


def _at(tree: dict, path: Path) -> dict:
    for name in path:
        tree = tree[name]
    return tree


def _without(tree: dict, path: Path) -> dict:
    """`tree` (nested dicts) less the subtree at `path`, and less the parents that leaves empty."""
    if not path or path[0] not in tree:
        return tree
    rest = dict(tree)
    if len(path) == 1:
        del rest[path[0]]
    else:
        rest[path[0]] = _without(tree[path[0]], path[1:])
        if not rest[path[0]]:
            del rest[path[0]]
    return rest


def _with(tree: dict, path: Path, leaves: dict) -> dict:
    """`tree` with the dict at `path` updated by `leaves` (copies along the path only)."""
    if not path:
        return {**tree, **leaves}
    return {**tree, path[0]: _with(tree.get(path[0], {}), path[1:], leaves)}


def fold_pair(kernel, conv_bias, gamma, beta, mean, var, epsilon: float):
    """(kernel', bias') of a conv followed by eval-mode BN: the same outputs, no BN."""
    s = gamma * jax.lax.rsqrt(var + epsilon)  # the BN's per-channel multiplier, as flax computes it
    bias = jnp.zeros_like(beta) if conv_bias is None else conv_bias
    return kernel * s, beta + (bias - mean) * s


def folded_variables(variables: dict, plan: FoldPlan) -> dict:
    """`variables` with every pair of `plan` folded: the conv's kernel and bias rewritten, the BN's
    'params' and 'batch_stats' removed (other collections and leaves are kept as they are)."""
    params, stats = variables["params"], variables.get("batch_stats", {})
    new_params, new_stats = params, stats
    for fold in plan.folds:
        conv_vars, bn_params, bn_stats = _at(params, fold.conv), _at(params, fold.bn), _at(stats, fold.bn)
        kernel, bias = fold_pair(conv_vars["kernel"], conv_vars.get("bias"), bn_params["scale"], bn_params["bias"],
                                 bn_stats["mean"], bn_stats["var"], fold.epsilon)
        new_params = _with(_without(new_params, fold.bn), fold.conv, {"kernel": kernel, "bias": bias})
        new_stats = _without(new_stats, fold.bn)
    out = {**variables, "params": new_params}
    if "batch_stats" in variables:
        out["batch_stats"] = new_stats
    return out


def folded_call(call: Callable, plan: FoldPlan) -> Callable:
    """`call` (fn(variables, *args) running a flax network) on variables from `folded_variables`:
    folded BNs pass their input through; a folded conv without a bias of its own adds the new one."""
    bns, biases = plan.folded_bns, plan.added_biases

    def intercept(next_fun, args, kwargs, context):
        if context.method_name != "__call__":
            return next_fun(*args, **kwargs)
        path = tuple(context.module.path)
        if path in bns:
            return args[0]
        out = next_fun(*args, **kwargs)
        return out + context.module.get_variable("params", "bias") if path in biases else out

    def run(variables, *args, **kwargs):
        with nn.intercept_methods(intercept):
            return call(variables, *args, **kwargs)

    return run
