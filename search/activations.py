"""Activation per component (DSFEC §3.3), one component at a time from the paper's mix:
python -m search.activations [--values relu,leaky_relu,swish,mish,hard_swish] [--base dsfec_m]"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

from dsfec_jax import zoo

from .cli import parse, parser, run_search
from .space import SearchSpaceError

COMPONENTS = {"fec": ("act_fec",), "stem": ("act_stem",), "backbone": ("act_backbone",),
              "car_truck_heads": ("act_car_head", "act_truck_head"), "vru_head": ("act_vru_head",)}
BASE_LABEL = "paper mix"


def activation_candidates(base: str, values: tuple[str, ...]) -> list[dict]:
    cfg = zoo.config(base)
    out = [{"label": BASE_LABEL, "overrides": {}}]
    for component, fields in COMPONENTS.items():
        for act in values:
            if all(getattr(cfg, f) == act for f in fields):
                continue  # that is the paper's mix itself
            overrides = {f: act for f in fields}
            try:
                zoo.config(base, **overrides)
            except ValueError as err:
                raise SearchSpaceError(f"{component}={act}: {err}") from None
            out.append({"label": f"{component}={act}", "overrides": overrides})
    return out


def main(argv=None) -> int:
    p = parser("python -m search.activations", __doc__, base="dsfec_m")
    p.add_argument("--values", default="relu,leaky_relu,swish,mish,hard_swish")
    args = parse(p, argv)
    values = tuple(args.values.split(","))
    return run_search(args, f"{args.base}_activations", lambda: activation_candidates(args.base, values),
                      f"{args.base}: activation per component", BASE_LABEL)


if __name__ == "__main__":
    raise SystemExit(main())
