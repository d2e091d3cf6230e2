"""The inference form's parts, A/B: the jitted forward of two forms of one detector interleaved in
one process at 1 thread (A, B, A, B, ...), weights on the device for both. Prints per model the
median ms of each and the median ratio A / B with its p10-p90 spread over the rounds.

`--ab fold` (A: the trained network, BNs kept; B: BNs folded, every conv XLA's);
`--ab products` (A: the export's form, every conv XLA's; B: the runtime's, the small wide convs as
one matrix product, layers/conv_product.py); `--ab blocks` (A: the runtime's form with each strided
conv of a thin input XLA's; B: as it ships, over blocks of pixels, layers/conv_space_to_depth.py).
The next three run the runtime form as a deployed predictor does, its weights compiled in as
constants (modalities/inference.py), each traced with one part off (A) and as it ships (B):
`--ab constants` (A: the weights passed as arguments, B: compiled in; Winograd needs them known, so
it is off on both sides); `--ab winograd` (A: every stride-1 3x3 conv XLA's, B: Winograd's
products, layers/winograd.py); `--ab silu` (A: the exact logistic, B: the rational one,
layers/silu.py). `--grid` times single 3x3 convs both ways over image sizes and widths (where
conv_product's MAX_PIXELS and MIN_CHANNELS come from); `--grid winograd` times XLA's conv, F(2x2, 3x3)
and F(4x4, 3x3) from constant kernels over the zoo's shapes (WINOGRAD_MIN_WEIGHTS, F4_MIN_SIDE,
F4_MAX_WEIGHTS).

    python -m experiments.bn_fold_speed --models yolov8n,dsfec_s,shuffle_yolov3 --rounds 200
    python -m experiments.bn_fold_speed --ab products --models yolov3_darknet53,yolov8n --rounds 30
    python -m experiments.bn_fold_speed --ab blocks --models yolov8n,yolov8n_adapter,shuffle_yolov3 --rounds 40
    python -m experiments.bn_fold_speed --ab winograd --models yolov8n,yolov8n_adapter,baseline,dsfec_s --rounds 20
    python -m experiments.bn_fold_speed --grid --rounds 15
    python -m experiments.bn_fold_speed --grid winograd --rounds 9
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
    if ab in CONSTANT_AB:
        return _constant_pair(zoo.deploy(det, variables), inputs, ab)
    convs = zoo.deploy(det, variables, for_export=True)  # folded, every conv XLA's
    first, second = ((det, variables), convs) if ab == "fold" else (convs, zoo.deploy(det, variables))
    return tuple(_run(d.apply, jax.device_put(v), inputs) for d, v in (first, second))


def _blocks_pair(runtime, inputs):
    """(the runtime form with every thin strided conv XLA's, the runtime form as it ships): each
    traced under its own setting of layers/conv_space_to_depth.py's THIN_INPUT."""
    import jax

    from dsfec_jax.layers import conv_space_to_depth

    detector, variables = runtime
    variables = jax.device_put(variables)

    def plain(label: str):  # each its own function, so its own jit cache
        return _compiled(_run(lambda v, x, _label=label: detector.apply(v, x), variables, inputs))

    with _switched(conv_space_to_depth, "THIN_INPUT", 0):
        first = plain("A")
    return first, plain("B")


def _constant_pair(runtime, inputs, ab: str):
    """(A, B) of the runtime form with its weights as constants, A traced with `ab`'s part off and B
    as it ships; `constants`: A takes the weights as arguments, and Winograd (which needs them
    known) is off on both sides."""
    import contextlib

    import jax

    from dsfec_jax.layers import conv_product, silu

    detector, variables = runtime
    variables = jax.device_put(variables)

    def constant(label: str):  # each its own function, so its own jit cache
        return _compiled(_run(lambda x, _label=label: detector.apply(variables, x), inputs))

    if ab == "constants":
        with _switched(conv_product, "WINOGRAD_MIN_WEIGHTS", 1 << 62):
            return _compiled(_run(lambda v, x: detector.apply(v, x), variables, inputs)), constant("B")
    off = {"winograd": (conv_product, "WINOGRAD_MIN_WEIGHTS", 1 << 62),
           "silu": (silu, "rational_logistic", contextlib.nullcontext)}[ab]
    with _switched(*off):
        first = constant("A")
    return first, constant("B")


def _switched(module, name: str, value):
    """A context with module.name set to value (restored after)."""
    import contextlib

    @contextlib.contextmanager
    def switched():
        kept = getattr(module, name)
        setattr(module, name, value)
        try:
            yield
        finally:
            setattr(module, name, kept)

    return switched()


def _compiled(run):
    """`run` traced and compiled now, under the settings in force; `run.compile_s` the first call's time."""
    t0 = time.perf_counter()
    run()
    run.compile_s = time.perf_counter() - t0
    return run


CONSTANT_AB = ("constants", "winograd", "silu")


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


def winograd_forms(shape, seed: int = 0):
    """{form: fn()} of one stride-1 3x3 conv (H, W, cin, cout) with a constant kernel: XLA's conv,
    F(2x2, 3x3) and F(4x4, 3x3) from the kernel transformed once."""
    import jax.numpy as jnp
    import numpy as np

    from dsfec_jax.layers import conv, winograd

    h, w, cin, cout = shape
    rng = np.random.default_rng(seed)
    x = jnp.asarray(rng.standard_normal((1, h, w, cin)), jnp.float32)
    kernel = jnp.asarray(rng.standard_normal((3, 3, cin, cout)) / np.sqrt(9 * cin), jnp.float32)
    pads = ((1, 1), (1, 1))
    forms = {"xla": _run(lambda x: conv.plain_conv(x, kernel, pads), x)}
    for name, f in (("F2", winograd.F2), ("F4", winograd.F4)):
        v = winograd.transformed_kernel(kernel, f)
        forms[name] = _run(lambda x, v=v, f=f: winograd.conv3x3_transformed(x, v, pads, f), x)
    return forms


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
    p.add_argument("--ab", choices=("fold", "products", "blocks", *CONSTANT_AB), default="fold")
    p.add_argument("--grid", nargs="?", const="products", choices=("products", "winograd"),
                   help="single 3x3 convs: XLA's against the product form, or against Winograd's F2 and F4")
    args = p.parse_args(argv)
    from dsfec_jax.core import threads

    threads.pin(args.threads)  # before XLA starts
    if args.grid == "winograd":
        return winograd_grid(args.rounds, args.per_round)
    if args.grid:
        for hw in GRID_HW:
            for channels in GRID_CHANNELS:
                r = interleaved(*conv_pair(hw, channels), args.rounds, args.per_round)
                print(_line(f"3x3 conv {hw[0]}x{hw[1]} px, {channels}->{2 * channels}", r, "xla", "product"), flush=True)
        return 0
    names = {"fold": ("kept", "folded"), "products": ("convs", "products"), "blocks": ("xla_stem", "blocks"),
             "constants": ("arguments", "constants"), "winograd": ("xla", "winograd"),
             "silu": ("exact", "rational")}[args.ab]
    for name in args.models.split(","):
        pair = forward_pair(name, HW.get(name), args.ab)
        r = interleaved(*pair, args.rounds, args.per_round)
        compiled = [getattr(fn, "compile_s", None) for fn in pair]
        first_calls = ("; first call (compile) " + ", ".join(f"{n} {c:.1f} s" for n, c in zip(names, compiled))
                       if None not in compiled else "")
        print(_line(name, r, *names) + first_calls, flush=True)
    return 0


def winograd_grid(rounds: int, per_round: int) -> int:
    """Each WINOGRAD_GRID shape: XLA's conv against F2 and F4, interleaved."""
    for shape in WINOGRAD_GRID:
        forms = winograd_forms(shape)
        for name in ("F2", "F4"):
            r = interleaved(forms["xla"], forms[name], rounds, per_round)
            print(_line(f"3x3 conv {shape[0]}x{shape[1]} px, {shape[2]}->{shape[3]}", r, "xla", name), flush=True)
    return 0


GRID_HW = ((8, 13), (16, 26), (32, 52), (64, 104))  # Darknet-53's strides 32..4 at 256 x 416
# (H, W, cin, cout): YOLOv8n's at 256 x 64, DSFEC-S's and the Baseline's, Darknet-53's deep ones at 256 x 416
WINOGRAD_GRID = ((64, 16, 16, 16), (32, 8, 32, 32), (32, 8, 64, 64), (16, 4, 128, 64), (8, 2, 256, 64),
                 (8, 2, 128, 128), (160, 160, 24, 24), (160, 160, 32, 24), (80, 80, 48, 48), (40, 40, 64, 64),
                 (80, 80, 96, 96), (20, 20, 96, 96), (16, 26, 256, 512), (8, 13, 512, 512), (8, 13, 512, 1024))
GRID_CHANNELS = (64, 128, 256, 512)


if __name__ == "__main__":
    raise SystemExit(main())
