"""python -m dsfec_jax.profile --models baseline,dsfec_l,dsfec_m,dsfec_s [--json] [--paper]

Prints one record per model (params, GFLOPs per stage with XLA's count beside it, memory,
jitted batch-1 latency per stage), for any zoo family: range-Doppler models (yolov8n, ...) are
profiled on 256 x 64 maps with their own stages (modalities/rd/profile.py), camera models (shuffle_yolov3,
yolov3_darknet53) on 416 x 416 images (stages backbone / head; memory by the Shuffle-YOLOv3
paper's formula). --threads must be handled before XLA starts (first jax computation).

An entry point: it looks each model's Modality record up (modalities.registry) and passes it to the
modality-free profiler. `--tables-only --readme README.md` rebuilds the zoo tables from the stored
records without profiling; `--train-worker ...` is the train bench's worker process
(profile/training.py's `run` launches it; users run `dsfec bench --train`).
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from ..core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import json
import shlex
import sys


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m dsfec_jax.profile", description=__doc__.splitlines()[0])
    p.add_argument("--models", default="baseline,dsfec_l,dsfec_m,dsfec_s", help="comma-separated zoo names")
    p.add_argument("--json", action="store_true", help="print a JSON list of records")
    p.add_argument("--paper", action="store_true", help="also print the paper's Tables 1-3 beside ours")
    p.add_argument("--no-latency", action="store_true", help="sizes only (no timing loop)")
    p.add_argument("--repeats", type=int, default=20)
    p.add_argument("--warmup", type=int, default=3)
    p.add_argument("--threads", type=int, default=None, help="CPU threads for XLA (the process is pinned to this many CPUs)")
    p.add_argument("--out", default=None, help="also write {command, records} JSON here (atomically)")
    p.add_argument("--readme", default=None, help="regenerate the zoo table(s) in this README from the records (zoo_table.py: one per modality)")
    p.add_argument("--tables-only", action="store_true",
                   help="with --readme: rebuild every zoo table from its stored record file, profiling nothing")
    return p.parse_args(argv)


def set_threads(threads: int | None) -> None:
    """Pin the process to `threads` CPUs before XLA starts (it sizes its pool then; core/threads.py)."""
    if threads is None:
        return
    from ..core.threads import pin

    try:
        pin(threads)
    except (ValueError, RuntimeError) as e:
        sys.exit(str(e))


def human(records: list[dict]) -> str:
    from ..core import spread

    lines = []
    for r in records:
        lat = r.get("latency_ms")
        mem = "-" if r["memory_mb"] is None else f"{r['memory_mb']:.2f}"
        folded = f" (BN-folded {r['params_folded']:,d})" if "params_folded" in r else ""
        lines.append(
            f"{r['model']:<15} params {r['params']:>10,d}{folded}  GFLOPs {r['gflops']:7.3f} (XLA {r['xla_gflops']:7.3f}, "
            f"{100 * r['xla_vs_analytic']:+.1f} %)  memory {mem} MB (XLA peak {r['xla_peak_mb']:.1f} MB)  "
            + (f"latency {spread.text(lat, r.get('latency_p10_ms'), r['latency_p90_ms'], 2)} ms (median, p10-p90)"
               if lat else "latency -")
        )
        lines.append("           GFLOPs/stage " + ", ".join(f"{k} {v:.3f}" for k, v in r["gflops_per_stage"].items()))
        if lat:
            band = r.get("latency_per_stage_p10_p90_ms", {})
            lines.append("           ms/stage " + ", ".join(f"{k} {spread.text(v, *band.get(k, (None, None)), 2)}"
                                                          for k, v in r["latency_per_stage_ms"].items()))
    busy = next((r["machine_load"] for r in records if (r.get("machine_load") or {}).get("busy")), None)
    if busy:  # one timing loop for all models: one verdict
        lines.append(f"warning: timed on a busy machine ({busy['text'][len('busy: '):]}): not the machine's latency")
    return "\n".join(lines)


def tables_only(args) -> int:
    """--tables-only: the README's zoo tables rebuilt from the stored records (no profiling)."""
    from ..modalities.registry import MODALITIES
    from . import zoo_table

    if not args.readme:
        sys.exit("--tables-only needs --readme README.md (the file whose zoo tables are rebuilt)")
    zoo_table.rebuild_readme(args.readme, MODALITIES.values())
    return 0


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["--train-worker"]:
        from ..modalities.registry import modality_of
        from . import training

        return training.worker_main(argv[1:], modality_of)
    args = parse(argv)
    if args.tables_only:
        return tables_only(args)
    set_threads(args.threads)
    from ..core import atomic
    from .. import zoo
    from ..modalities.registry import modality_of
    from . import compare, records, zoo_table

    names = [n.strip() for n in args.models.split(",") if n.strip()]
    unknown = [n for n in names if n not in zoo.available()]
    if unknown:
        sys.exit(f"unknown model(s) {unknown}; available: {zoo.available()}")
    recs = records.profile(records.detectors_for(names), not args.no_latency, args.repeats, args.warmup,
                           modality_of=modality_of, announce=True)
    print(json.dumps(recs, indent=2) if args.json else human(recs))
    if args.paper:
        dsfec = modality_of(compare.TABLE2_BASE)  # DSFEC's Tables 2-3: shown beside any model of its modality
        mine = any(modality_of(n) is dsfec for n in names)
        rows = compare.table1_rows(recs) + (compare.table2_rows(dsfec) + compare.table3_rows(dsfec) if mine else [])
        rows += compare.rd_rows(recs)
        print(json.dumps(rows, indent=2) if args.json else "\n" + compare.markdown(rows))
    if args.out or args.readme:
        command = "python -m dsfec_jax.profile " + " ".join(shlex.quote(a) for a in argv)
        payload = {"command": command, "records": recs}
        if args.out:
            atomic.write_json(args.out, payload)
        if args.readme:
            zoo_table.update_readme(args.readme, payload, modality_of)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
