"""Stem filters (DSFEC Table 2), the FEC's last width tied to them: python -m search.stem [--values 32,16,12,8]"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

from dsfec_jax import zoo

from .cli import parse, parser, run_search
from .space import Axis, candidates


def main(argv=None) -> int:
    p = parser("python -m search.stem", __doc__)
    p.add_argument("--values", default="32,16,12,8")
    args = parse(p, argv)
    axis = Axis("stem_filters", tuple(int(v) for v in args.values.split(",")))
    return run_search(args, f"{args.base}_stem_filters", lambda: candidates(args.base, [axis]),
                      f"{args.base}: stem filters (FEC f3 tied)", axis.label(zoo.config(args.base).stem_filters))


if __name__ == "__main__":
    raise SystemExit(main())
