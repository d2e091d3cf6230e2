"""Any product of config overrides of a registered model:
python -m search.grid --base dsfec_s --axis stage_blocks=1,1,3,2|3,3,2,3 --axis stem_filters=16,12

RadarNeXt's ablations (the VoD columns are reported for RadarNeXt bases):
python -m search.grid --base radarnext_mdfen --axis neck=fpn,pan,mdfen --axis backbone=rep_dwc,dense  # Table II
python -m search.grid --base radarnext_mdfen --axis "dcn_positions=1|3|5|2|4|1,2,4" --base-label dcn_positions=4  # III
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

from .cli import parse, parser, run_search
from .space import candidates, parse_axis


def main(argv=None) -> int:
    p = parser("python -m search.grid", __doc__)
    p.add_argument("--axis", action="append", required=True, metavar="FIELD=V1,V2",
                   help="repeatable; tuple fields take A|B with comma-separated tuples")
    p.add_argument("--base-label", default=None, help="the candidate the reports' change column is measured against")
    args = parse(p, argv)

    def build():
        return candidates(args.base, [parse_axis(a, args.base) for a in args.axis])

    name = "_".join(a.partition("=")[0] for a in args.axis)
    return run_search(args, f"{args.base}_grid_{name}", build, f"{args.base}: grid over {', '.join(args.axis)}",
                      args.base_label)


if __name__ == "__main__":
    raise SystemExit(main())
