"""The project side of the PyTorch twins (experiments/peer_twins.py): one network's inference form,
an input and its jitted JAX output, written for the twin to rebuild, load and check.

    python -m experiments.twin_export --model baseline --out case.npz
    PEER/bin/python experiments/peer_twins.py case.npz          # builds the twin, prints the check

Networks with a twin: the DSFEC family's 2D network (what runs after the pillar scatter:
`backbone` then `detect`, on the scattered BEV image of the family's dummy pillars) and the
camera family's YOLOv3s (the whole network, on a random image of `hw`). The weights are the
initialiser's, with every BatchNorm given random statistics and affine parameters (so folding
them changes the kernels), then `zoo.deploy`'s inference form (BN folded), or with `fold=False`
the BNs kept, so the twin's own BN is checked too.

The .npz: 'description' (JSON: the family and the config fields the twin reads), 'input' (NHWC),
'output/<i>' (the JAX outputs in a fixed order), 'params/<module path>/<name>' and
'batch_stats/<module path>/<name>' (flax's layouts: kernels HWIO, images NHWC).
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import dataclasses
import io
import json
import sys
from typing import Callable

import numpy as np

TWIN_FAMILIES = ("dsfec", "camera")
CAMERA_HW = (256, 416)  # the camera input size


@dataclasses.dataclass
class TwinCase:
    """One network as the twin mirrors it: `run(variables, input)` -> a tuple of arrays."""

    model: str
    description: dict
    variables: dict
    input: np.ndarray
    run: Callable


def family(model: str) -> str | None:
    """'dsfec' or 'camera' when `model` has a twin, else None (an ultralytics peer, or none)."""
    from dsfec_jax import zoo
    from dsfec_jax.models.camera.config import CameraConfig
    from dsfec_jax.models.dsfec.net import DSFECConfig

    try:
        cfg = zoo.config(model)
    except KeyError:
        return None
    return {DSFECConfig: "dsfec", CameraConfig: "camera"}.get(type(cfg))


def random_batch_norms(variables: dict, seed: int) -> dict:
    """`variables` with every BN's statistics and affine parameters drawn at random (the initial
    mean 0, var 1, scale 1, bias 0 would make folding the identity and the check blind to it)."""
    from flax.traverse_util import flatten_dict, unflatten_dict

    rng = np.random.default_rng(seed)
    stats = flatten_dict(variables.get("batch_stats", {}))
    params = flatten_dict(variables["params"])
    for key, value in stats.items():
        shape = np.shape(value)
        if key[-1] == "mean":
            stats[key] = rng.normal(0.0, 0.2, shape).astype(np.float32)
            params[key[:-1] + ("scale",)] = rng.uniform(0.5, 1.5, shape).astype(np.float32)
            params[key[:-1] + ("bias",)] = rng.normal(0.0, 0.2, shape).astype(np.float32)
        else:
            stats[key] = rng.uniform(0.5, 2.0, shape).astype(np.float32)
    return {**variables, "params": unflatten_dict(params), "batch_stats": unflatten_dict(stats)}


def case(model: str, hw: tuple[int, int] | None = None, fold: bool = True, seed: int = 0) -> TwinCase:
    """The network of `model` as its twin mirrors it, its variables on the device and its input."""
    import jax

    from dsfec_jax import zoo

    kind = family(model)
    if kind is None:
        raise ValueError(f"{model!r} has no PyTorch twin; twins exist for the {' and '.join(TWIN_FAMILIES)} families")
    detector = zoo.create(model)
    variables = random_batch_norms(jax.device_get(detector.init(jax.random.key(seed))), seed)
    detector, variables = zoo.deploy(detector, variables, fold_batch_norm=fold)
    variables = jax.device_put(variables)
    if kind == "dsfec":
        return _dsfec_case(model, detector, variables, seed)
    return _camera_case(model, detector, variables, hw or CAMERA_HW, seed)


def _method(detector, variables, method: str, *args):
    """`method` of the network in evaluation, on a folded detector or a plain one."""
    if hasattr(detector, "apply_method"):
        return detector.apply_method(variables, method, *args)
    return detector.module.apply(variables, *args, method=method)


def _dsfec_case(model, detector, variables, seed) -> TwinCase:
    import jax

    from dsfec_jax.layers.activations import LEAKY_SLOPE
    from dsfec_jax.models.dsfec.net import ACT_FIELDS

    cfg = detector.config
    points = cfg.dummy_inputs(1, seed=seed)
    bev = np.asarray(jax.jit(lambda v, p: _method(detector, v, "encode", p["points"], p["mask"], p["coords"]))(
        variables, points))

    def heads_of(v, image):
        return _method(detector, v, "detect", _method(detector, v, "backbone", image))

    names = tuple(jax.eval_shape(heads_of, variables, bev))  # the config's heads, in the network's order

    def run(v, image):
        heads = heads_of(v, image)
        return tuple(heads[name][part] for name in names for part in ("cls", "box"))

    description = {"family": "dsfec", "model": model, "heads": list(names), "leaky_slope": LEAKY_SLOPE,
                   **{f: getattr(cfg, f) for f in ("stem_convs", "block", "stage_blocks", "stage_strides",
                                                    "neck_widths", "head_convs", "head_kind", *ACT_FIELDS)}}
    return TwinCase(model, description, variables, bev, jax.jit(run))


def _camera_case(model, detector, variables, hw, seed) -> TwinCase:
    import jax

    from dsfec_jax.layers.activations import LEAKY_SLOPE

    cfg = detector.config
    image = cfg.dummy_inputs(1, seed=seed, hw=tuple(hw))["image"]
    description = {"family": "camera", "model": model, "leaky_slope": LEAKY_SLOPE,
                   "stage_styles": [cfg.stage_style(s) for s in range(len(cfg.repeats))],
                   "head_styles": [cfg.head_style(lv) for lv in range(len(cfg.head_widths))],
                   **{f: getattr(cfg, f) for f in ("backbone", "repeats", "first_repeat", "head_units", "fpn_merge",
                                                    "split", "act", "num_anchors", "outputs_per_anchor")}}
    return TwinCase(model, description, variables, image,
                    jax.jit(lambda v, x: tuple(detector.apply(v, {"image": x}))))


def arrays(twin: TwinCase) -> dict[str, np.ndarray]:
    """Everything the twin reads, by the .npz names of the module docstring."""
    import jax
    from flax.traverse_util import flatten_dict

    outputs = jax.device_get(twin.run(twin.variables, twin.input))
    out = {"description": np.array(json.dumps(twin.description)), "input": np.asarray(twin.input)}
    out.update({f"output/{i}": np.asarray(o) for i, o in enumerate(outputs)})
    for collection, tree in jax.device_get(twin.variables).items():
        out.update({f"{collection}/{k}": np.asarray(v) for k, v in flatten_dict(tree, sep="/").items()})
    return out


def write(twin: TwinCase, path: str) -> None:
    """The case as an .npz at `path`, written atomically."""
    from dsfec_jax.core import atomic

    buffer = io.BytesIO()
    np.savez(buffer, **arrays(twin))
    atomic.write_bytes(path, buffer.getvalue())


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.twin_export", description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True, help="a DSFEC-family or camera variant")
    p.add_argument("--out", required=True, help="the .npz to write")
    p.add_argument("--hw", default=None, help="camera: input height,width (default 256,416)")
    p.add_argument("--keep-batch-norm", action="store_true", help="export the unfolded network (BNs kept)")
    args = p.parse_args(argv)
    hw = tuple(int(v) for v in args.hw.split(",")) if args.hw else None
    write(case(args.model, hw, fold=not args.keep_batch_norm), args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
