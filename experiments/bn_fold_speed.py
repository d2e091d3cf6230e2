"""BatchNorm folded vs kept: the jitted forward of a detector's inference form (zoo.deploy) against
its trained network, interleaved in one process at 1 thread (A, B, A, B, ...), weights on the
device for both. Prints per model the median ms of each and the median ratio kept / folded with
its p10-p90 spread over the rounds.

    python -m experiments.bn_fold_speed --models yolov8n,dsfec_s,shuffle_yolov3 --rounds 200
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import time


def forward_pair(name: str, hw):
    """(kept, folded): zero-argument callables running the jitted forward to completion."""
    import jax

    from dsfec_jax import zoo

    det = zoo.create(name)
    variables = jax.device_put(det.init(jax.random.key(0)))
    folded_det, folded = zoo.deploy(det, variables)
    folded = jax.device_put(folded)
    inputs = det.config.dummy_inputs(1, hw=hw) if hw else det.dummy_inputs(1)
    inputs = jax.device_put(inputs)
    kept_fn, folded_fn = jax.jit(det.apply), jax.jit(folded_det.apply)
    return (lambda: jax.block_until_ready(kept_fn(variables, inputs)),
            lambda: jax.block_until_ready(folded_fn(folded, inputs)))


def interleaved(kept, folded, rounds: int, per_round: int) -> dict:
    from dsfec_jax.core.spread import percentiles

    for fn in (kept, folded, kept, folded):
        fn()
    a, b = [], []
    for _ in range(rounds):
        for fn, out in ((kept, a), (folded, b)):
            t0 = time.perf_counter()
            for _ in range(per_round):
                fn()
            out.append(1e3 * (time.perf_counter() - t0) / per_round)
    return {"kept_ms": percentiles(a), "folded_ms": percentiles(b),
            "ratio": percentiles([x / y for x, y in zip(a, b)])}


# input sizes: the RD maps the issue quotes (256 x 64); DSFEC its grid; the camera model the street frames'
HW = {"yolov8n": (256, 64), "yolov8n_adapter": (256, 64), "shuffle_yolov3": (256, 416), "yolov3_darknet53": (256, 416)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.bn_fold_speed", description=__doc__.splitlines()[0])
    p.add_argument("--models", default="yolov8n,dsfec_s,shuffle_yolov3")
    p.add_argument("--rounds", type=int, default=100)
    p.add_argument("--per-round", type=int, default=3, help="forwards per timing (their mean)")
    p.add_argument("--threads", type=int, default=1)
    args = p.parse_args(argv)
    from dsfec_jax.core import threads

    threads.pin(args.threads)  # before XLA starts
    for name in args.models.split(","):
        r = interleaved(*forward_pair(name, HW.get(name)), args.rounds, args.per_round)
        print(f"{name}: kept {r['kept_ms']['median']:.2f} ms, folded {r['folded_ms']['median']:.2f} ms, "
              f"kept/folded {r['ratio']['median']:.3f} ({r['ratio']['p10']:.3f}-{r['ratio']['p90']:.3f})", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
