"""Blocks per stage (DSFEC Table 3): python -m search.blocks --stage 2 [--values 1,2,3,4,5,6] [--base dsfec_l]

A depth axis is what weight sharing fits, so the default strategy here is one-shot: one
supernet trains for the recipe's budget and every candidate inherits its weights
(`--strategy train` trains each candidate; in the quick profile both start from the
base's shipped weights, see search.inherit).
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

from dsfec_jax import zoo

from .cli import parse, parser, run_search
from .space import Axis, candidates


def arguments(argv=None):
    p = parser("python -m search.blocks", __doc__, strategy="oneshot")
    p.add_argument("--stage", type=int, required=True, choices=(1, 2, 3, 4))
    p.add_argument("--values", default="1,2,3,4,5,6", help="block counts to try")
    return parse(p, argv)


def main(argv=None) -> int:
    args = arguments(argv)
    values = tuple(int(v) for v in args.values.split(","))
    axis = Axis(f"stage{args.stage}_blocks", values)
    base_blocks = zoo.config(args.base).stage_blocks[args.stage - 1]
    return run_search(args, f"{args.base}_stage{args.stage}_blocks", lambda: candidates(args.base, [axis]),
                      f"{args.base}: blocks in stage {args.stage}", axis.label(base_blocks))


if __name__ == "__main__":
    raise SystemExit(main())
