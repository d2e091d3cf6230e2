"""A latency look-up table for a search space, built with the project's own profiler, and its error.

The table holds a base latency and, for every choice block and option, how much the latency
changes when that block takes that option. They come from whole-network measurements, interleaved
in one run so they share the box's state: the largest subnet and each block alone at each other
option (one-factor-at-a-time: 1 + sum(options - 1), 44 for Table 1), plus `--fit` random subnets,
the entries then being the least-squares fit to all of them. A subnet's predicted latency is the
base plus its blocks' changes. It ignores how blocks interact (a narrower block also makes the next block's input
narrower), so `check` measures sampled subnets whole and reports the prediction's error; the
search then filters on a prediction whose error is stated, as the latency-constrained NAS tools
do (OFA, FBNet: per-op tables summed). The checked subnets are measured in the same interleaved run
as the table's own, and left out of its fit.

Measurements: jitted JAX (`profile.latency`: stand-in weights of the subnet's shapes, batch 1,
the medians of interleaved repeats), on the threads the process is pinned to, or ONNX Runtime on
each subnet's exported network (`--runtime onnx`, the deployment runtime):

    python -m search.nas.latency --space yolov8n_adapter [--runtime jax|onnx] [--threads 1] [--fit 48]
        [--check 8] [--out FILE]
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import dataclasses
import json
import shlex
import sys
from pathlib import Path
from typing import Callable, Sequence

import jax
import numpy as np

from dsfec_jax import zoo
from dsfec_jax.core import atomic
from dsfec_jax.core.environment import environment

from .space import Genes, SearchSpace, key
from .spaces import get_space

Measure = Callable[[list[Genes]], list[float]]  # subnets -> whole-network latency (ms), one interleaved run
RECORDS = Path(__file__).parent / "records"


@dataclasses.dataclass
class LatencyTable:
    space: str
    base_ms: float  # the largest subnet's latency
    deltas: list[list[float]]  # deltas[block][option]: the change when that block alone takes that option
    setup: dict = dataclasses.field(default_factory=dict)  # command, threads, runtime, environment

    def predict(self, genes: Sequence[int]) -> float:
        return self.base_ms + sum(self.deltas[i][int(g)] for i, g in enumerate(genes))

    def save(self, path: str | Path) -> None:
        atomic.write_text(path, json.dumps(dataclasses.asdict(self), indent=1) + "\n")

    @classmethod
    def load(cls, path: str | Path, space: SearchSpace) -> "LatencyTable":
        try:
            table = cls(**json.loads(Path(path).read_text()))
        except (OSError, ValueError, TypeError) as err:
            raise ValueError(f"{path}: not a latency table ({err}); build one with "
                             f"python -m search.nas.latency --space {space.name}") from err
        if table.space != space.name or [len(d) for d in table.deltas] != [len(c.options) for c in space.choices]:
            raise ValueError(f"{path}: a table of space {table.space!r} with {len(table.deltas)} blocks, not of "
                             f"{space.name!r}; build one with python -m search.nas.latency --space {space.name}")
        return table


def one_at_a_time(space: SearchSpace) -> list[Genes]:
    """The largest subnet, then each block at each of its other options, the rest largest."""
    top = space.largest()
    out = [top]
    for i, c in enumerate(space.choices):
        out += [top[:i] + (o,) + top[i + 1:] for o in range(len(c.options)) if o != top[i]]
    return out


def build(space: SearchSpace, measure: Measure, setup: dict | None = None, fit: int = 0, seed: int = 0) -> LatencyTable:
    """The one-factor-at-a-time table; with `fit` > 0, `fit` random subnets are measured in the same
    run and the entries are the least-squares fit to all measurements (the largest option of each
    block fixed at 0): a CPU network's fixed cost (dispatch, memory) does not shrink with its
    widths, so the one-at-a-time changes, summed, overstate what several narrower blocks save."""
    subnets = one_at_a_time(space)
    rng = np.random.default_rng([seed, 1])
    subnets += [s for s in dict.fromkeys(space.sample(rng) for _ in range(fit)) if s not in subnets]
    ms = dict(zip(subnets, measure(subnets)))
    top = space.largest()
    if not fit:
        deltas = [[ms[top[:i] + (o,) + top[i + 1:]] - ms[top] for o in range(len(c.options))]
                  for i, c in enumerate(space.choices)]
        return LatencyTable(space.name, ms[top], deltas, setup or {})
    return _fitted(space, ms, setup or {})


def _fitted(space: SearchSpace, ms: dict, setup: dict) -> LatencyTable:
    """base + deltas by least squares over every measured subnet (one-hot design, largest options as reference)."""
    columns = [(i, o) for i, c in enumerate(space.choices) for o in range(len(c.options) - 1)]
    design = np.array([[1.0] + [float(s[i] == o) for i, o in columns] for s in ms])
    solution = np.linalg.lstsq(design, np.array(list(ms.values())), rcond=None)[0]
    deltas = [[0.0] * len(c.options) for c in space.choices]
    for (i, o), value in zip(columns, solution[1:]):
        deltas[i][o] = float(value)
    return LatencyTable(space.name, float(solution[0]), deltas, {**setup, "fitted_on": len(ms)})


def check(table: LatencyTable, space: SearchSpace, measure: Measure, count: int = 8, seed: int = 0) -> dict:
    """Measure `count` sampled subnets whole against the table: per-subnet rows and the error."""
    subnets = _sampled(space, count, seed)
    return _errors(table, subnets, measure(subnets))


def _sampled(space: SearchSpace, count: int, seed) -> list[Genes]:
    rng = np.random.default_rng(seed)
    return list(dict.fromkeys(space.sample(rng) for _ in range(count)))


def _errors(table: LatencyTable, subnets: list[Genes], measured: list[float]) -> dict:
    rows = [{"subnet": key(g), "measured_ms": m, "predicted_ms": table.predict(g)} for g, m in zip(subnets, measured)]
    errors = np.array([100 * (r["predicted_ms"] - r["measured_ms"]) / r["measured_ms"] for r in rows])
    return {"rows": rows, "mean_abs_error_pct": float(np.mean(np.abs(errors))),
            "max_abs_error_pct": float(np.max(np.abs(errors))), "mean_error_pct": float(np.mean(errors))}


def build_checked(space: SearchSpace, measure: Measure, setup: dict, fit: int, count: int, seed: int = 0) -> LatencyTable:
    """The table fitted as `build` does, and its error on `count` more sampled subnets that the fit
    never saw, all measured in one interleaved run: a CPU's state drifts between runs (a separate
    check run on this box read 30 % below the fit's run), so only one run compares like with like."""
    fitted = one_at_a_time(space)
    rng = np.random.default_rng([seed, 1])
    fitted += [s for s in dict.fromkeys(space.sample(rng) for _ in range(fit)) if s not in fitted]
    held_out = [s for s in _sampled(space, count, seed + 1000) if s not in fitted]
    ms = dict(zip(fitted + held_out, measure(fitted + held_out)))
    top = space.largest()
    if fit:
        table = _fitted(space, {s: ms[s] for s in fitted}, setup)
    else:
        deltas = [[ms[top[:i] + (o,) + top[i + 1:]] - ms[top] for o in range(len(c.options))]
                  for i, c in enumerate(space.choices)]
        table = LatencyTable(space.name, ms[top], deltas, dict(setup))
    table.setup["check"] = {**_errors(table, held_out, [ms[s] for s in held_out]), "same_run": True}
    return table


def jax_measure(space: SearchSpace, repeats: int = 10, warmup: int = 2) -> Measure:
    """Whole-network latency of stand-alone subnets with jitted JAX (profile.latency), interleaved."""
    from dsfec_jax.profile.latency import stage_functions, time_interleaved, timing_variables

    def measure(subnets: list[Genes]) -> list[float]:
        suites = {}
        for genes in subnets:
            det = zoo.create(space.base, **space.overrides(genes))
            suites[key(genes)] = stage_functions(det, timing_variables(det), det.dummy_inputs(1))
        times = time_interleaved(suites, repeats, warmup)
        return [times[key(g)]["total"]["median_ms"] for g in subnets]

    return measure


def onnx_measure(space: SearchSpace, repeats: int = 10, warmup: int = 2, threads: int = 1) -> Measure:
    """Whole-network latency of stand-alone subnets in ONNX Runtime (`threads` intra-op threads),
    interleaved: each subnet's network (stand-in weights of its shapes, batch 1) exported by
    jax2onnx as `dsfec export` writes it (DSFEC's grouped depthwise kernel, YOLO's 1x1 convs as
    MatMul), without the decode."""
    import tempfile

    from dsfec_jax.deploy.export import onnx_model
    from dsfec_jax.deploy.ort import ort_session
    from dsfec_jax.profile.latency import time_interleaved, timing_variables

    def session(genes: Genes, workdir: Path):
        det = zoo.create(space.base, **space.overrides(genes))
        det, matmul_einsums = space.engine.onnx_form(det)
        variables, inputs = timing_variables(det), det.dummy_inputs(1)
        names = list(inputs)
        fn = lambda *x: tuple(jax.tree.leaves(det.apply(variables, dict(zip(names, x)))))  # noqa: E731
        specs = [jax.ShapeDtypeStruct(inputs[k].shape, inputs[k].dtype) for k in names]
        outputs = [f"out{i}" for i in range(len(jax.eval_shape(fn, *specs)))]
        path = workdir / f"{key(genes)}.onnx"
        path.write_bytes(onnx_model(fn, specs, names, outputs, matmul_einsums=matmul_einsums).SerializeToString())
        sess, feeds = ort_session(path, threads), {k: np.asarray(v) for k, v in inputs.items()}
        return lambda: sess.run(None, feeds)

    def measure(subnets: list[Genes]) -> list[float]:
        with tempfile.TemporaryDirectory() as tmp:
            suites = {key(g): {"total": session(g, Path(tmp))} for g in subnets}
            times = time_interleaved(suites, repeats, warmup)
        return [times[key(g)]["total"]["median_ms"] for g in subnets]

    return measure


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    p = argparse.ArgumentParser(prog="python -m search.nas.latency", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--space", required=True)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--runtime", default="jax", choices=("jax", "onnx"),
                   help="jitted JAX (profile.latency) or ONNX Runtime on the exported network")
    p.add_argument("--repeats", type=int, default=10)
    p.add_argument("--check", type=int, default=8, help="sampled subnets measured whole to report the error")
    p.add_argument("--fit", type=int, default=48, help="random subnets measured too; the entries are then "
                   "the least-squares fit to every measurement (0: the plain one-at-a-time table)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="default search/nas/records/latency_SPACE.json")
    args = p.parse_args(argv)
    from dsfec_jax.core import threads

    threads.check(args.threads)
    threads.pin(args.threads)
    space = get_space(args.space)
    measure = (onnx_measure(space, args.repeats, threads=args.threads) if args.runtime == "onnx"
               else jax_measure(space, args.repeats))
    setup = {"command": shlex.join(["python", "-m", "search.nas.latency", *argv]), "runtime": args.runtime,
             "threads": args.threads, "repeats": args.repeats, "environment": environment()}
    table = build_checked(space, measure, setup, args.fit, args.check, args.seed)
    out = Path(args.out) if args.out else RECORDS / f"latency_{space.name}.json"
    table.save(out)
    c = table.setup["check"]
    print(f"{space.name}: largest {table.base_ms:.2f} ms; on {len(c['rows'])} sampled subnets the table's error is "
          f"{c['mean_abs_error_pct']:.1f} % mean absolute, {c['max_abs_error_pct']:.1f} % max, "
          f"{c['mean_error_pct']:+.1f} % mean; table: {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
