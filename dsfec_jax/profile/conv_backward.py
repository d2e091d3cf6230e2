"""python -m dsfec_jax.profile.conv_backward [--sizes 12,24,48,96] [--channels 24,32,64,96] [--batch 8] [--threads 2]

Times the backward of a stride-1 3x3 conv in each form the fast kernels choose between
(layers/conv.py): the kernel gradient as per-tap products or by Winograd's F(3x3, 4x4), the input
gradient as XLA's conv or by F(4x4, 3x3), beside the forward, for every size x channels (C -> C).
Its table is where `WINOGRAD_MIN_CHANNELS` and `WINOGRAD_INPUT_GRAD_MIN_PIXELS` come from; run
it to check them on another CPU. Each form is jitted alone and timed in steady state (median of
`--repeats` calls, each right after an untimed one); the forms alternate within each repetition.
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from ..core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import shlex
import sys
import time
from typing import Callable

SAME = ((1, 1), (1, 1))
FORMS = ("forward", "kernel_grad_taps", "kernel_grad_winograd", "input_grad_xla", "input_grad_winograd")


def parse(argv=None) -> argparse.Namespace:
    from ..argtypes import positive_int, positive_int_list

    p = argparse.ArgumentParser(prog="python -m dsfec_jax.profile.conv_backward", description=__doc__.splitlines()[2])
    p.add_argument("--sizes", type=positive_int_list, default=[12, 24, 48, 96], help="image sides (square), comma-separated")
    p.add_argument("--channels", type=positive_int_list, default=[24, 32, 64, 96], help="channels in and out, comma-separated")
    p.add_argument("--batch", type=positive_int, default=8)
    p.add_argument("--repeats", type=positive_int, default=9)
    p.add_argument("--threads", type=positive_int, default=None, help="pin to this many CPUs first (default: all)")
    return p.parse_args(argv)


def programs() -> dict[str, Callable]:
    """Each form as a jitted function of (x, g, w)."""
    import jax

    from ..layers import conv, winograd

    def input_grad_xla(x, g, w):
        return jax.vjp(lambda x_: conv.plain_conv(x_, w), x)[1](g)[0]

    return {"forward": jax.jit(lambda x, g, w: conv.plain_conv(x, w)),
            "kernel_grad_taps": jax.jit(lambda x, g, w: conv.conv_kernel_grad(x, g, 3)),
            "kernel_grad_winograd": jax.jit(lambda x, g, w: winograd.conv3x3_kernel_grad(x, g, SAME)),
            "input_grad_xla": jax.jit(input_grad_xla),
            "input_grad_winograd": jax.jit(lambda x, g, w: winograd.conv3x3_input_grad(g, w, SAME))}


def time_forms(size: int, channels: int, batch: int, repeats: int) -> dict[str, float]:
    """{form: median ms} on random (batch, size, size, channels) inputs."""
    import jax
    import numpy as np

    x, g = (jax.random.normal(jax.random.key(k), (batch, size, size, channels)) for k in (0, 1))
    w = jax.random.normal(jax.random.key(2), (3, 3, channels, channels))
    fns = programs()
    samples: dict[str, list[float]] = {f: [] for f in FORMS}
    for rep in range(repeats + 1):  # the first round compiles and warms up
        for form in FORMS:
            jax.block_until_ready(fns[form](x, g, w))
            start = time.perf_counter()
            jax.block_until_ready(fns[form](x, g, w))
            if rep:
                samples[form].append(1e3 * (time.perf_counter() - start))
    return {form: float(np.median(ms)) for form, ms in samples.items()}


def table(rows: list[tuple[int, int, dict[str, float]]]) -> str:
    head = ("| size | channels | forward ms | kernel grad: taps / Winograd ms | speed-up | "
            "input grad: XLA / Winograd ms | speed-up |\n|---|---|---|---|---|---|---|")
    lines = [f"| {s} | {c} | {t['forward']:.2f} | {t['kernel_grad_taps']:.2f} / {t['kernel_grad_winograd']:.2f} | "
             f"{t['kernel_grad_taps'] / t['kernel_grad_winograd']:.2f}x | "
             f"{t['input_grad_xla']:.2f} / {t['input_grad_winograd']:.2f} | "
             f"{t['input_grad_xla'] / t['input_grad_winograd']:.2f}x |" for s, c, t in rows]
    return "\n".join([head, *lines])


def main(argv=None) -> int:
    args = parse(argv)
    if args.threads is not None:
        from ..core.threads import pin

        pin(args.threads)  # before the first jax computation: XLA sizes its pool from it
    import jax

    from ..core.environment import cpu_model, xla_threads
    from ..layers import conv

    jax.config.update("jax_cpu_enable_async_dispatch", False)
    rows = [(s, c, time_forms(s, c, args.batch, args.repeats)) for s in args.sizes for c in args.channels]
    print(table(rows))
    print(f"\nbatch {args.batch}, {xla_threads()} XLA thread(s), {cpu_model()}, jax {jax.__version__}; "
          f"thresholds now: WINOGRAD_MIN_CHANNELS={conv.WINOGRAD_MIN_CHANNELS}, "
          f"WINOGRAD_INPUT_GRAD_MIN_PIXELS={conv.WINOGRAD_INPUT_GRAD_MIN_PIXELS}")
    given = sys.argv[1:] if argv is None else list(argv)
    print("Command: `" + shlex.join(["python", "-m", "dsfec_jax.profile.conv_backward", *given]) + "`")
    return 0


if __name__ == "__main__":
    sys.exit(main())
