"""The Shuffle-YOLOv3 paper's Tables 2-4 and its Sec. 3.4 memory figure, ours beside the paper's:

    python -m experiments.camera_tables [--out DIR] [--weights [MODEL=]PATH ...] [--frames 200]
        [--voc DIR] [--voc-frames N] [--eval FILE ...] [--finetune-eval FILE] [--profile FILE ...]
        [--bench FILE ...] [--size 416] [--seed 0] [--set FIELD=VALUE ...] [--no-eval]

Table 2 (Model | Backbone | Input | Model size | mAP | FPS (CPU)): model size = params x 4 bytes
(footprint.py; with the weights file's size where there is one), mAP = VOC07 mAP@0.5 on the
synthetic street test split (our stand-in for the paper's 6-class traffic set), FPS = 1000 / the
1-thread JAX latency. Table 3 (VOC mAP@0.5): the street-trained models scored on the 100 real
VOC2012 images at the classes both know (car, bus, person, bicycle), and a fine-tuned run's eval.
Table 4 (inference ms): this CPU at 1 and 2 threads, and the Darknet53 / Shuffle speed ratio.
Memory: the paper's Sec. 3.4 formula (models/camera/footprint.py).

Where the figures come from, first found wins:
- evaluations: `--eval FILE` (the output of `dsfec eval ... --json`; its "model" and "data" say
  which cell it fills; --finetune-eval also takes experiments.camera_voc_finetune's finetune.json,
  its fine-tuned row), else `dsfec eval` run here on the weights (--weights MODEL=PATH, default
  model shuffle_yolov3; without --weights the shipped dsfec_jax/weights/MODEL.msgpack where it
  exists): the street test split (--frames, data seed --seed) for explicit weights, the VOC images
  (--voc DIR) for any; for shipped weights the street figure is their manifest's measured test
  split. --no-eval runs nothing.
- latency: `--bench FILE` (`dsfec bench --out`'s bench.json, or its --json list: image to boxes)
  over `--profile FILE` (`python -m dsfec_jax.profile` records: the network alone, default
  dsfec_jax/profile/records/zoo_camera.json).
Missing figures are '-' with a footnote saying why. Writes camera_tables.md and camera_tables.json
(the command, seed, environment, inputs, every evaluation's own command and result, the cells)
atomically into --out (default experiments/records/camera) and prints the markdown.
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import contextlib
import io
import json
import os
import shlex
import sys
from pathlib import Path

from dsfec_jax import zoo
from dsfec_jax.core.atomic import write_json, write_text
from dsfec_jax.core.checkpoint import manifest_path
from dsfec_jax.core.environment import environment
from dsfec_jax.models.camera import paper  # the paper's numbers, one constant per table, each citing it
from dsfec_jax.models.camera.footprint import footprint
from dsfec_jax.modalities.image.zoo_table import TABLE as CAMERA_TABLE

from experiments.common import fmt

MODELS = ("yolov3_darknet53", "shuffle_yolov3")  # the paper's row order
OURS = "shuffle_yolov3"  # --weights PATH without MODEL=
# Tables 2-3 of the paper: model, backbone, input (Table 3 adds SSD)
PAPER_ROWS = {"yolov3_darknet53": ("YOLOv3", "Darknet-53", "416x416"),
              "shuffle_yolov3": ("Shuffle-YOLOv3", "Modified shuffle", "416x416"),
              "ssd321_vgg": ("SSD", "VGG19", "321x321")}
# Table 3: the training data printed beside each mAP ("*" the paper's third-party YOLOv3 VOC result)
TABLE3_TRAINED_ON = {"yolov3_darknet53": "07+12+coco*", "shuffle_yolov3": "07+12", "ssd321_vgg": "07+12"}
TABLE3_COLUMNS = (("voc2012", "VOC2012 IoU=0.5"), ("voc2007", "VOC2007 IoU=0.5"), ("coco50", "COCO IoU=0.5"))
TABLE4_COLUMNS = (("arm_a72", "ARM Cortex-A72 1.8 GHz"), ("cpu_i7", "Intel i7 3.0 GHz"), ("gpu_1080ti", "GPU 1080Ti"))
DEFAULT_VOC = Path(os.environ.get("DSFEC_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")) \
    / "voc_review_od_metrics" / "data" / "database"
DEFAULT_OUT = "experiments/records/camera"


def shown(path) -> str:
    """`path` relative to the working directory where it lies below it (records read the same anywhere)."""
    p = Path(path).resolve()
    return str(p.relative_to(Path.cwd())) if p.is_relative_to(Path.cwd()) else str(path)


def read_json(path, flag: str, expected: str):
    """The JSON in `path`, or exit naming the flag, the file and what was expected."""
    p = Path(path)
    if not p.is_file():
        raise SystemExit(f"{flag} {p}: no such file; expected {expected}")
    try:
        return json.loads(p.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise SystemExit(f"{flag} {p}: not JSON ({err}); expected {expected}") from err


def data_kind(result: dict) -> str:
    """'street' or 'voc': which benchmark an eval result scored (`dsfec eval`'s --data)."""
    kind = str(result.get("data", "")).partition(":")[0]
    return "street" if kind in ("street", "synthetic") else kind


def read_eval(path, flag: str) -> dict:
    result = read_json(path, flag, "the output of `dsfec eval ... --json`")
    if isinstance(result, dict) and "rows" in result:  # experiments.camera_voc_finetune's finetune.json
        tuned = [r["scores"] for r in result["rows"] if str(r.get("row", "")).startswith("fine-tuned")]
        if not tuned:
            raise SystemExit(f"{flag} {path}: no 'fine-tuned' row; expected camera_voc_finetune's finetune.json")
        result = {"model": OURS, "data": "voc:held-out", "frames": tuned[-1].get("images"),
                  "classes_scored": tuned[-1].get("classes", []), **tuned[-1]}
    if not isinstance(result, dict) or not {"model", "data", "mAP50"} <= set(result):
        raise SystemExit(f"{flag} {path}: no 'model', 'data' and 'mAP50'; expected the output of "
                         "`dsfec eval --model shuffle_yolov3 ... --json`")
    if data_kind(result) not in ("street", "voc"):
        raise SystemExit(f"{flag} {path}: data {result['data']!r}; expected street or voc:DIR")
    return {**result, "source": f"{flag} {shown(path)}"}


def read_latency(path, flag: str) -> list[dict]:
    """Latency rows {model, runtime, threads, ms, cpu, source} of a profile or bench record."""
    payload = read_json(path, flag, "a profile record ({'records': [...]}) or `dsfec bench`'s bench.json")
    try:
        rows = []
        for r in payload["records"] if isinstance(payload, dict) else payload:
            if "total_ms" in r:  # dsfec bench: raw image to boxes
                rows.append({"model": r["model"], "runtime": r["runtime"], "threads": r["threads"],
                             "ms": r["total_ms"], "cpu": r.get("cpu"), "source": f"bench {shown(path)}"})
            elif r.get("latency_ms"):  # the profiler: the network alone
                setup = r["latency_setup"]
                rows.append({"model": r["model"], "runtime": "jax", "threads": setup["threads"],
                             "ms": r["latency_ms"], "cpu": setup.get("cpu"), "source": f"profile {shown(path)}"})
    except (KeyError, TypeError) as err:
        raise SystemExit(f"{flag} {path}: unreadable latency record ({err!r}); expected a profile record "
                         "or `dsfec bench`'s bench.json") from err
    return rows


def run_eval(argv: list[str]) -> dict:
    """`dsfec eval ... --json` run here; its JSON with the command that made it."""
    from dsfec_jax import cli

    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        cli.main(argv)
    command = "dsfec " + shlex.join(argv)
    try:
        return {**json.loads(printed.getvalue()), "source": f"`{command}`", "command": command}
    except json.JSONDecodeError as err:
        raise SystemExit(f"`{command}` printed no JSON ({err}): {printed.getvalue()[-300:]!r}") from err


def eval_argv(model: str, weights: Path, data: str, split: str, frames: int | None, args) -> list[str]:
    argv = ["eval", "--model", model, "--weights", str(weights), "--data", data, "--split", split,
            "--size", str(args.size), "--seed", str(args.seed), "--json"]
    return argv + (["--frames", str(frames)] if frames else []) + [a for s in args.set for a in ("--set", s)]


def parse_weights(items: list[str]) -> dict[str, Path]:
    out = {}
    for item in items:
        model, sep, path = item.partition("=")
        model, path = (model, path) if sep and model in MODELS else (OURS, item)
        if not Path(path).is_file():
            raise SystemExit(f"--weights {item}: no such file {path}")
        out[model] = Path(path)
    return out


def manifest_test(weights: Path) -> dict | None:
    """The measured street test figures in a shipped weights file's manifest (None without)."""
    path = manifest_path(weights)
    measured = json.loads(path.read_text()).get("measured", {}) if path.is_file() else {}
    return {**measured["test"], "source": f"manifest {shown(path)}"} if "test" in measured else None


def gather_evals(args, weights: dict[str, Path], explicit: set[str], notes: list[str]) -> dict:
    """(model, 'street' | 'voc') -> eval result, in the order of the module docstring."""
    evals = {}
    for path in args.eval:
        r = read_eval(path, "--eval")
        evals.setdefault((r["model"], data_kind(r)), r)
    voc = Path(args.voc).is_dir()
    if weights and not voc and not args.no_eval:
        notes.append(f"No VOC evaluation: --voc {args.voc} is not a folder.")
    for model, path in weights.items():
        if (model, "street") not in evals:  # explicit weights are evaluated, shipped ones have a manifest
            fresh = model in explicit and not args.no_eval
            street = run_eval(eval_argv(model, path, "street", "test", args.frames, args)) if fresh else manifest_test(path)
            if street is not None:
                evals[(model, "street")] = street
        if voc and not args.no_eval and (model, "voc") not in evals:
            evals[(model, "voc")] = run_eval(eval_argv(model, path, f"voc:{args.voc}", "all", args.voc_frames, args))
    return evals


def ratio(a, b) -> str:
    return "-" if a is None or b is None else f"{a / b:.2f}x"


def latency_of(latency: dict, model: str, runtime: str, threads: int):
    row = latency.get((model, runtime, threads))
    return None if row is None else row["ms"]


def table2(fp: dict, evals: dict, latency: dict, weights: dict) -> dict:
    rows, fps = [], {}
    for m in MODELS:
        name, backbone, size = PAPER_ROWS[m]
        ref, ev = paper.TABLE2[m], evals.get((m, "street"))
        file_mb = f" [file {weights[m].stat().st_size / 1e6:.1f}]" if m in weights else ""
        ms = latency_of(latency, m, "jax", 1)
        fps[m] = None if ms is None else 1e3 / ms
        rows.append([name, backbone, f"{size} ({size})", f"{fp[m]['size_mb']:.1f}{file_mb} ({ref['size_mb']:g})",
                     f"{fmt(ev and ev['mAP50'], 1)} ({ref['mAP']:g})", f"{fmt(fps[m])} ({ref['fps_cpu']:g})"])
    s, d = OURS, "yolov3_darknet53"
    map_s, map_d = ((evals.get((m, "street")) or {}).get("mAP50") for m in (s, d))
    delta = "-" if map_s is None or map_d is None else f"{map_s - map_d:+.1f}"
    rows.append(["Shuffle / YOLOv3", "", "", f"{fp[s]['size_mb'] / fp[d]['size_mb']:.1%} ({paper.SIZE_RATIO:.1%})",
                 f"{delta} ({paper.TABLE2[s]['mAP'] - paper.TABLE2[d]['mAP']:+.1f})",
                 f"{ratio(fps[s], fps[d])} ({ratio(paper.TABLE2[s]['fps_cpu'], paper.TABLE2[d]['fps_cpu'])})"])
    notes = ["Cells: ours (paper). Model size: params x 4 bytes (fp32) in MB (1e6); [file]: the weights file "
             "evaluated. mAP: VOC07 11-point mAP@0.5 (%) on the **synthetic** street test split (5 classes), "
             "the paper's: its own 6-class traffic set. FPS (CPU): 1000 / median batch-1 JAX latency at 1 thread."]
    notes += [f"{PAPER_ROWS[m][0]} mAP: {_source(evals.get((m, 'street')), 'no weights (none shipped, no --weights, no --eval)')}."
              for m in MODELS]
    notes += [f"{PAPER_ROWS[m][0]} FPS: {_source(latency.get((m, 'jax', 1)), 'no 1-thread JAX latency record')}."
              for m in MODELS]
    return {"title": "Table 2: evaluation on the traffic set (ours: synthetic street test split)",
            "header": ["Model", "Backbone", "Input", "Model size (MB)", "mAP", "FPS (CPU)"], "rows": rows,
            "notes": notes}


def _source(found: dict | None, missing: str) -> str:
    if found is None:
        return f"'-': {missing}"
    frames = f", {found['frames']} frames" if "frames" in found else ""
    return f"from {found['source']}{frames}"


def table3(evals: dict, finetune: dict | None) -> dict:
    rows = [[*PAPER_ROWS[m]] + [_paper_map(paper.TABLE3[m][k], TABLE3_TRAINED_ON[m] if k != "coco50" else None)
                                for k, _ in TABLE3_COLUMNS] + ["paper", "-"] for m in (*MODELS, "ssd321_vgg")]
    ours = [(f"{PAPER_ROWS[m][0]} (ours, street-trained)", m, evals.get((m, "voc"))) for m in MODELS]
    ours = [o for o in ours if o[2] is not None or o[1] == OURS]
    if finetune is not None:
        ours.append((f"{PAPER_ROWS.get(finetune['model'], [finetune['model']])[0]} (ours, fine-tuned)", finetune["model"],
                     finetune))
    notes = ["Paper rows: mAP@0.5 (%) with the training data in brackets (07+12: VOC2007+2012 trainval; *: the "
             "paper's YOLOv3 VOC figure is third-party). Ours: the 100 real VOC2012 images "
             "(voc_review_od_metrics), VOC07 11-point mAP@0.5 (all-point in brackets) at the classes the model "
             "and VOC share (a street-trained model: car, bus, person, bicycle; pedestrian -> person, "
             "cyclist -> bicycle); no VOC2007 test or COCO images here, so those cells stay '-'."]
    for label, m, ev in ours:
        cells = "-" if ev is None else f"{fmt(ev['mAP50'], 1)} (all-pt {fmt(ev.get('mAP50_all'), 1)})"
        scored = "-" if ev is None else f"{ev.get('frames', '?')} images: " + ", ".join(ev.get("classes_scored", []))
        per_class = "-" if ev is None else ", ".join(f"{c} {fmt(v, 1)}" for c, v in ev.get("AP50", {}).items())
        rows.append([label, PAPER_ROWS.get(m, ["", "-"])[1], "letterboxed", cells, "-", "-", scored, per_class])
        missing = "no VOC evaluation (no weights shipped or given, --no-eval, or no --voc folder) and no --eval"
        notes.append(f"{label}: {_source(ev, missing)}.")
    return {"title": "Table 3: mAP@0.5 on VOC and COCO (ours: 100 real VOC2012 images)",
            "header": ["Model", "Backbone", "Input", *(t for _, t in TABLE3_COLUMNS), "scored on", "AP50 per class"],
            "rows": rows, "notes": notes}


def _paper_map(value, trained_on: str | None) -> str:
    return "-" if value is None else f"{value:.1f}" + (f" ({trained_on})" if trained_on else "")  # as printed


def table4(latency: dict) -> dict:
    keys = sorted({(rt, t) for (_, rt, t) in latency} | {("jax", 1), ("jax", 2)}, key=lambda k: (k[0] != "jax", k))
    cpu = next((r["cpu"] for r in latency.values() if r.get("cpu")), "this CPU")
    rows = []
    for m in MODELS:
        ref = paper.TABLE4[m]
        rows.append([PAPER_ROWS[m][0]] + [f"{ref[k]:g}" for k, _ in TABLE4_COLUMNS]
                    + [fmt(latency_of(latency, m, rt, t), 1) for rt, t in keys])
    d, s = "yolov3_darknet53", OURS
    rows.append(["Darknet53 / Shuffle"] + [ratio(paper.TABLE4[d][k], paper.TABLE4[s][k]) for k, _ in TABLE4_COLUMNS]
                + [ratio(latency_of(latency, d, rt, t), latency_of(latency, s, rt, t)) for rt, t in keys])
    notes = [f"Paper: single-thread ARM and i7, 1080Ti GPU (Table 4). Ours: batch-1 median ms on {cpu}, "
             "pinned to the thread count; '-': no record at that thread count (add one with `python -m "
             "dsfec_jax.profile --models shuffle_yolov3,yolov3_darknet53 --threads 2 --out FILE` and "
             "--profile FILE, or `dsfec bench --out DIR` and --bench DIR/bench.json)."]
    notes += sorted({f"{rt}, {t} thread{'s' * (t > 1)}: {r['source']}" for (_, rt, t), r in latency.items()})
    return {"title": "Table 4: inference time (ms)",
            "header": ["Model", *(f"{t} (paper)" for _, t in TABLE4_COLUMNS),
                       *(f"ours, {rt}, {t} thread{'s' * (t > 1)}" for rt, t in keys)], "rows": rows, "notes": notes}


def memory_table(fp: dict) -> dict:
    d, s = "yolov3_darknet53", OURS
    mem = {m: fp[m]["paper_memory_mb"] for m in MODELS}
    rows = [[PAPER_ROWS[m][0], f"{mem[m]['all_total_bytes']:.1f} ({paper.MEMORY_MB[m]:g}"
             + (", implied)" if m == d else ")"), f"{mem[m]['conv_total_bytes']:.1f}",
             f"{mem[m]['param_bytes']:.1f} / {mem[m]['all_output_bytes']:.1f}"] for m in MODELS]
    rows.append(["Shuffle / YOLOv3", f"{mem[s]['all_total_bytes'] / mem[d]['all_total_bytes']:.1%} "
                 f"({paper.MEMORY_RATIO:.1%})", f"{mem[s]['conv_total_bytes'] / mem[d]['conv_total_bytes']:.1%}", ""])
    notes = ["Sec. 3.4's formula, one 416x416 image, fp32, MB (1e6): every conv's C_in C_out K^2 + C_out parameters "
             "plus every layer's C_out H W output (convs, shortcuts, concatenations, upsample, route); 'conv "
             "layers only' counts the convs' outputs alone (models/camera/footprint.py). The paper gives "
             f"{paper.MEMORY_MB[s]:g} MB and {paper.MEMORY_RATIO:.1%} of YOLOv3, whose figure is implied "
             f"({paper.MEMORY_MB[s]:g} / {paper.MEMORY_RATIO})."]
    return {"title": "Memory footprint (Sec. 3.4)",
            "header": ["Model", "memory MB, every layer, ours (paper)", "conv layers only", "params / outputs MB"],
            "rows": rows, "notes": notes}


def markdown(tables: dict, command: str, notes: list[str]) -> str:
    parts = [f"Generated by `{command}`.", *notes]
    for t in tables.values():
        lines = ["| " + " | ".join(t["header"]) + " |", "|" + "---|" * len(t["header"])]
        lines += ["| " + " | ".join(r) + " |" for r in t["rows"]]
        parts.append(f"### {t['title']}\n\n" + "\n".join(lines) + "\n\n" + "\n".join(f"- {n}" for n in t["notes"]))
    return "\n\n".join(parts) + "\n"


def build(fp: dict, evals: dict, latency: dict, weights: dict, finetune: dict | None) -> dict:
    return {"table2": table2(fp, evals, latency, weights), "table3": table3(evals, finetune),
            "table4": table4(latency), "memory": memory_table(fp)}


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m experiments.camera_tables", description=__doc__.splitlines()[0])
    p.add_argument("--out", default=DEFAULT_OUT, help=f"folder for camera_tables.md / .json (default {DEFAULT_OUT})")
    p.add_argument("--weights", action="append", default=[], metavar="[MODEL=]PATH",
                   help=f"weights to evaluate (MODEL default {OURS}; default: the shipped weights)")
    p.add_argument("--frames", type=int, default=200, help="street test frames to evaluate (default 200)")
    p.add_argument("--voc", default=str(DEFAULT_VOC), help="the 100 real VOC2012 images' folder")
    p.add_argument("--voc-frames", type=int, default=None, help="first N VOC images only (default all)")
    p.add_argument("--eval", action="append", default=[], metavar="FILE", help="`dsfec eval --json` output")
    p.add_argument("--finetune-eval", default=None, metavar="FILE", help="a fine-tuned run's VOC eval JSON")
    p.add_argument("--profile", action="append", default=None, metavar="FILE",
                   help="profile record (default dsfec_jax/profile/records/zoo_camera.json)")
    p.add_argument("--bench", action="append", default=[], metavar="FILE", help="dsfec bench record (bench.json)")
    p.add_argument("--size", type=int, default=416, help="evaluation size (long side, multiple of 32)")
    p.add_argument("--seed", type=int, default=0, help="street data seed")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE", help="config override for evaluation")
    p.add_argument("--no-eval", action="store_true", help="run no evaluation; read --eval files and manifests only")
    return p


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser().parse_args(argv)
    explicit = parse_weights(args.weights)
    shipped = {m: zoo.shipped_weights(m) for m in MODELS if zoo.shipped_weights(m).is_file()}
    weights = {**shipped, **explicit}
    notes = [] if weights else ["No camera weights are shipped (dsfec_jax/weights/) and none were given (--weights): "
                                "the accuracy cells are '-'."]
    latency = {}
    for flag, paths in (("--profile", args.profile or [CAMERA_TABLE.record]), ("--bench", args.bench)):
        for path in paths:
            latency.update({(r["model"], r["runtime"], r["threads"]): r for r in read_latency(path, flag)})
    finetune = read_eval(args.finetune_eval, "--finetune-eval") if args.finetune_eval else None
    evals = gather_evals(args, weights, set(explicit), notes)
    fp = {m: footprint(zoo.config(m)) for m in MODELS}
    command = ("python -m experiments.camera_tables " + shlex.join(argv)).rstrip()
    tables = build(fp, evals, latency, weights, finetune)
    text = markdown(tables, command, notes)
    record = {"command": command, "seed": args.seed, "environment": environment(),
              "inputs": {"weights": {m: shown(p) for m, p in weights.items()}, "eval": args.eval,
                         "finetune_eval": args.finetune_eval,
                         "profile": [shown(p) for p in args.profile or [CAMERA_TABLE.record]],
                         "bench": args.bench, "voc": args.voc, "frames": args.frames, "size": args.size},
              "evals": {f"{m}/{k}": r for (m, k), r in evals.items()}, "finetune": finetune,
              "latency": list(latency.values()),
              "footprint": {m: {k: fp[m][k] for k in ("params", "size_mb", "paper_memory_mb")} for m in MODELS},
              "notes": notes, "tables": tables}
    write_text(Path(args.out) / "camera_tables.md", text)
    write_json(Path(args.out) / "camera_tables.json", record)
    print(text, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
