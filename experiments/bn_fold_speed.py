"""The inference form's parts, A/B: the jitted forward of two forms of one detector interleaved in
one process at 1 thread (A, B, A, B, ...), weights on the device for both. Prints per model the
median ms of each and the median ratio A / B with its p10-p90 spread over the rounds.

`--ab fold` (A: the trained network, BNs kept; B: BNs folded, every conv XLA's);
`--ab products` (A: the export's form, every conv XLA's; B: the runtime's, the small wide convs as
one matrix product, layers/conv_product.py); `--ab blocks` (A: the runtime's form with each strided
conv of a thin input XLA's; B: as it ships, over blocks of pixels, layers/conv_space_to_depth.py); `--grid` times single 3x3 convs both ways over image
sizes and widths (where conv_product's MAX_PIXELS and MIN_CHANNELS come from).

    python -m experiments.bn_fold_speed --models yolov8n,dsfec_s,shuffle_yolov3 --rounds 200
    python -m experiments.bn_fold_speed --ab products --models yolov3_darknet53,yolov8n --rounds 30
    python -m experiments.bn_fold_speed --ab blocks --models yolov8n,yolov8n_adapter,shuffle_yolov3 --rounds 40
    python -m experiments.bn_fold_speed --grid --rounds 15
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import time


def forward_pair(name: str, hw, ab: str = "fold"):
    """(A, B): zero-argument callables running the jitted forward to completion."""
    import jax

    from dsfec_jax import zoo

    det = zoo.create(name)
    variables = jax.device_put(det.init(jax.random.key(0)))
    inputs = jax.device_put(det.config.dummy_inputs(1, hw=hw) if hw else det.dummy_inputs(1))
    if ab == "blocks":
        return _blocks_pair(zoo.deploy(det, variables), inputs)
    convs = zoo.deploy(det, variables, for_export=True)  # folded, every conv XLA's
    first, second = ((det, variables), convs) if ab == "fold" else (convs, zoo.deploy(det, variables))
    return tuple(_run(d.apply, jax.device_put(v), inputs) for d, v in (first, second))


def _blocks_pair(runtime, inputs):
    """(the runtime form with every thin strided conv XLA's, the runtime form as it ships): each
    traced under its own setting of layers/conv_space_to_depth.py's THIN_INPUT."""
    import jax

    from dsfec_jax.layers import conv_space_to_depth

    detector, variables = runtime
    shipped, pair = conv_space_to_depth.THIN_INPUT, []
    for thin in (0, shipped):
        conv_space_to_depth.THIN_INPUT = thin
        run = _run(lambda v, x: detector.apply(v, x), jax.device_put(variables), inputs)  # its own jit cache
        run()  # compiled now, under this setting
        pair.append(run)
    conv_space_to_depth.THIN_INPUT = shipped
    return tuple(pair)


def _run(fn, *args):
    import jax

    jitted = jax.jit(fn)
    return lambda: jax.block_until_ready(jitted(*args))


def conv_pair(pixels_hw, channels: int):
    """(XLA's conv, the product form) of one 3x3 stride-1 conv from `channels` to 2 x `channels`."""
    import jax.numpy as jnp
    import numpy as np

    from dsfec_jax.layers import conv, conv_product

    rng = np.random.default_rng(0)
    x = jnp.asarray(rng.standard_normal((1, *pixels_hw, channels)), jnp.float32)
    w = jnp.asarray(rng.standard_normal((3, 3, channels, 2 * channels)), jnp.float32)
    pads = ((1, 1), (1, 1))
    return (_run(lambda x, w: conv.plain_conv(x, w, pads), x, w),
            _run(lambda x, w: conv_product.conv_as_product(x, w, 1, pads), x, w))


def interleaved(first, second, rounds: int, per_round: int) -> dict:
    from dsfec_jax.core.spread import percentiles

    for fn in (first, second, first, second):
        fn()
    a, b = [], []
    for _ in range(rounds):
        for fn, out in ((first, a), (second, b)):
            t0 = time.perf_counter()
            for _ in range(per_round):
                fn()
            out.append(1e3 * (time.perf_counter() - t0) / per_round)
    return {"a_ms": percentiles(a), "b_ms": percentiles(b), "ratio": percentiles([x / y for x, y in zip(a, b)])}


def _line(label: str, r: dict, a: str, b: str) -> str:
    return (f"{label}: {a} {r['a_ms']['median']:.2f} ms, {b} {r['b_ms']['median']:.2f} ms, "
            f"{a}/{b} {r['ratio']['median']:.3f} ({r['ratio']['p10']:.3f}-{r['ratio']['p90']:.3f})")


# input sizes: the RD maps the issue quotes (256 x 64); DSFEC its grid; the camera model the street frames'
HW = {"yolov8n": (256, 64), "yolov8n_adapter": (256, 64), "shuffle_yolov3": (256, 416), "yolov3_darknet53": (256, 416)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.bn_fold_speed", description=__doc__.splitlines()[0])
    p.add_argument("--models", default="yolov8n,dsfec_s,shuffle_yolov3")
    p.add_argument("--rounds", type=int, default=100)
    p.add_argument("--per-round", type=int, default=3, help="forwards per timing (their mean)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--ab", choices=("fold", "products", "blocks"), default="fold")
    p.add_argument("--grid", action="store_true", help="single 3x3 convs, XLA's against the product form")
    args = p.parse_args(argv)
    from dsfec_jax.core import threads

    threads.pin(args.threads)  # before XLA starts
    if args.grid:
        for hw in GRID_HW:
            for channels in GRID_CHANNELS:
                r = interleaved(*conv_pair(hw, channels), args.rounds, args.per_round)
                print(_line(f"3x3 conv {hw[0]}x{hw[1]} px, {channels}->{2 * channels}", r, "xla", "product"), flush=True)
        return 0
    names = {"fold": ("kept", "folded"), "products": ("convs", "products"), "blocks": ("xla_stem", "blocks")}[args.ab]
    for name in args.models.split(","):
        r = interleaved(*forward_pair(name, HW.get(name), args.ab), args.rounds, args.per_round)
        print(_line(name, r, *names), flush=True)
    return 0


GRID_HW = ((8, 13), (16, 26), (32, 52), (64, 104))  # Darknet-53's strides 32..4 at 256 x 416
GRID_CHANNELS = (64, 128, 256, 512)


if __name__ == "__main__":
    raise SystemExit(main())
