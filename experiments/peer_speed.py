"""The project's jitted JAX against its PyTorch peer (ultralytics' YOLOv8), interleaved in one run.

    python -m experiments.peer_speed train --peer-python PEER/bin/python            # batch 16, 2 threads
    python -m experiments.peer_speed forward --peer-python PEER/bin/python --model yolov8s --hw 640,640
    python -m experiments.peer_speed forward --peer-python PEER/bin/python --model baseline   # a PyTorch twin

PEER is any environment with torch and ultralytics (`pip install torch ultralytics`); neither is a
dependency of the project and nothing here runs in CI. Each side is a worker process pinned to the
same CPUs (`--threads`), built once; then, round after round, each worker runs `--steps` timed
calls while the others wait, with the order rotated every round, so the box's noise hits every side
alike. The figures: each side's median time, and per round the peer's median over each JAX
variant's, summarised as median (p10-p90) across rounds.

JAX variants (`--variants`):
- command: started as the project's commands start (glibc tunables, calls inline: core/host_memory);
- library: a user's own script, no settings;
- tuned: a user's script that calls `api.tune_host()` first.
`--xla-flags FLAGS` adds a side started as a command with those XLA_FLAGS; without `--peer-python`
the first JAX side is the reference (an A/B of flags or settings alone).

train: the project's YOLOv8n train step on its own augmented RD batches (profile/training.py's
step, the family's quick schedule), and ultralytics' step on the same batches (experiments/peer_torch.py).
forward: the jitted inference network as a deployed predictor runs it (`zoo.deploy`'s inference form,
the weights compiled in as constants: modalities/inference.py) and
ultralytics' fused, frozen TorchScript network, on one image of `--hw`. For a model of a family
with a PyTorch twin (DSFEC's: Baseline, DSFEC-S/M/L; the camera YOLOv3s), the peer is the twin
with the same weights (experiments/twin_export.py, peer_twins.py), frozen TorchScript, and both
sides run the same network on the same input: DSFEC's 2D network (backbone and detect, after the
pillar scatter; `--hw` does not apply) or the whole camera network (`--hw`, default 256,416). The
peer checks its outputs against JAX's before timing; the record keeps that check.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from . import twin_export

PEER_SCRIPT = Path(__file__).with_name("peer_torch.py")
VARIANTS = ("command", "library", "tuned")


# ---- the JAX worker -----------------------------------------------------------------------------

def jax_train(model: str, batch: int, batches_out: str):
    """fn() running the project's train step; the batches it cycles go to `batches_out` for the peer."""
    import jax
    import numpy as np

    from dsfec_jax.modalities.registry import modality_of
    from dsfec_jax import zoo
    from dsfec_jax.profile.training import Settings, build_workload

    settings = Settings(batch=batch, breakdown=False)
    work = build_workload(model, model, {}, settings, modality_of(zoo.config(model)))
    host = [jax.device_get(b) for b in work.batches]
    np.savez(batches_out, images=np.stack([b["inputs"]["heat"] for b in host]),
             boxes=np.stack([b["targets"]["gt_boxes"] for b in host]),
             labels=np.stack([b["targets"]["gt_labels"] for b in host]),
             mask=np.stack([b["targets"]["gt_mask"] for b in host]), classes=len(work.detector.config.classes))
    state = {"rep": 0}

    def step():
        work.run("step", state["rep"])
        state["rep"] += 1

    return step


def jax_forward(model: str, hw: tuple[int, int]):
    """fn() running the jitted inference network on one map or image of `hw` (a twinned model:
    the network its twin mirrors, on the case's input), its weights constants of the program as in
    a predictor made with constant_weights=True (arguments over its size cap, as there)."""
    import jax
    import numpy as np

    from dsfec_jax import zoo

    if twin_export.family(model):
        twin = twin_export.case(model, hw)
        image = jax.device_put(twin.input)
        return _deployed_call(twin.run, twin.variables, image)

    detector = zoo.create(model)
    detector, variables = zoo.deploy(detector, detector.init(jax.random.key(0)))
    variables = jax.device_put(variables)
    shapes = jax.eval_shape(lambda: detector.dummy_inputs(1))
    rng = np.random.default_rng(0)
    inputs = jax.device_put({k: rng.random((1, *hw, s.shape[-1]), np.float32) for k, s in shapes.items()})
    return _deployed_call(jax.jit(detector.apply), variables, inputs)


def _deployed_call(network, variables, inputs):
    """fn() running the jitted network(variables, inputs) as a deployed predictor runs it."""
    import jax

    from dsfec_jax.modalities.inference import jit_with_weights

    net = jit_with_weights(network, variables)
    return lambda: jax.block_until_ready(net(inputs))


def jax_worker(args) -> int:
    from dsfec_jax.core import host_memory, threads

    threads.pin(args.threads)
    if args.variant == "command":
        host_memory.dispatch_inline()  # the tunables came with the environment the lead started it in
    elif args.variant == "tuned":
        from dsfec_jax import api

        api.tune_host()
    with contextlib.redirect_stdout(sys.stderr):  # stdout carries the protocol alone
        if args.mode == "train":
            fn = jax_train(args.model, args.batch, args.batches_out)
        else:
            fn = jax_forward(args.model, _hw(args))
    sys.path.insert(0, str(PEER_SCRIPT.parent))
    from peer_torch import serve  # the same protocol as the peer

    serve(fn)
    return 0


# ---- the lead -----------------------------------------------------------------------------------

class Worker:
    """A worker process speaking peer_torch's protocol."""

    def __init__(self, label: str, command: list[str], env: dict):
        self.label = label
        self.proc = subprocess.Popen(command, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self.ready = self._answer()

    def _answer(self) -> dict:
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"{self.label} worker exited ({self.proc.wait()}) before answering")
        return json.loads(line)

    def time(self, steps: int) -> list[float]:
        self.proc.stdin.write(f"{steps}\n")
        self.proc.stdin.flush()
        return self._answer()["ms"]

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.stdin.write("quit\n")
            self.proc.stdin.close()
            self.proc.wait(timeout=60)


def _jax_command(args, variant: str, batches: str, xla_flags: str = "") -> tuple[list[str], dict]:
    from dsfec_jax.core import host_memory

    command = [sys.executable, "-m", "experiments.peer_speed", args.mode, "--worker", "--variant", variant, "--model", args.model, "--threads", str(args.threads), "--batch", str(args.batch),
               "--hw", args.hw, "--batches-out", batches]
    env = {k: v for k, v in os.environ.items() if k != "GLIBC_TUNABLES"}
    if variant == "command":
        tunables = host_memory.relaunch_tunables(env, host_memory.glibc_version(), host_memory.thp_mode())
        if tunables:
            env["GLIBC_TUNABLES"] = tunables
    env["PYTHONPATH"] = os.pathsep.join([str(PEER_SCRIPT.parents[1]), env.get("PYTHONPATH", "")])
    if xla_flags:
        env["XLA_FLAGS"] = " ".join([env.get("XLA_FLAGS", ""), xla_flags]).strip()
    return command, env


def _peer_command(args, batches: str, twin_case: str | None) -> list[str]:
    command = [args.peer_python, str(PEER_SCRIPT), "--mode", args.mode, "--model", args.model,
               "--threads", str(args.threads), "--hw", args.hw]
    if twin_case:
        command += ["--twin", twin_case, "--twin-layout", args.twin_layout]
    return command + (["--batches", batches] if args.mode == "train" else [])


def _twin_case(args, folder: str) -> str | None:
    """Forward on a twinned model: its case written for the peer (the JAX workers rebuild the same
    network and weights from the same seed); the input's size becomes the record's `hw`."""
    if args.mode != "forward" or not twin_export.family(args.model):
        return None
    twin = twin_export.case(args.model, _hw(args))
    path = str(Path(folder) / "twin.npz")
    twin_export.write(twin, path)
    args.hw = ",".join(str(v) for v in twin.input.shape[1:3])
    return path


def _hw(args) -> tuple[int, int] | None:
    return tuple(int(v) for v in args.hw.split(",")) if args.hw else None


def run(args) -> dict:
    """Build every worker, then time them round-robin; -> the record."""
    import numpy as np

    from dsfec_jax.core import spread

    workers: list[Worker] = []
    with tempfile.TemporaryDirectory() as tmp:
        batches = str(Path(tmp) / "batches.npz")
        twin_case = _twin_case(args, tmp)
        try:
            for variant in args.variants:
                workers.append(Worker(f"jax-{variant}", *_jax_command(args, variant, batches)))
            for flags in args.xla_flags:
                workers.append(Worker(f"jax-command {flags}", *_jax_command(args, "command", batches, flags)))
            reference, check = ("torch", None) if args.peer_python else (workers[0].label, None)
            if args.peer_python:
                workers.append(Worker("torch", _peer_command(args, batches, twin_case), dict(os.environ)))
                check = workers[-1].ready.get("check")
            samples: dict[str, list[list[float]]] = {w.label: [] for w in workers}
            for r in range(args.rounds):
                for w in workers[r % len(workers):] + workers[:r % len(workers)]:
                    samples[w.label].append(w.time(args.steps))
        finally:
            for w in workers:
                w.close()
    rounds = {label: [float(np.median(s)) for s in rows] for label, rows in samples.items()}
    per_step = args.batch if args.mode == "train" else 1
    sides = {label: {"median_ms": float(np.median(np.concatenate(rows))),
                     "per_s": per_step * 1e3 / float(np.median(np.concatenate(rows)))} for label, rows in samples.items()}
    ratios = {f"{reference} / {label}": spread.percentiles(np.array(rounds[reference]) / np.array(rounds[label]))
              for label in rounds if label != reference}
    peer = None if not args.peer_python else "torch twin" if check else "ultralytics"
    return {"mode": args.mode, "model": args.model, "peer": peer,
            "twin_check": check, "threads": args.threads, "batch": per_step, "hw": args.hw,
            "rounds": args.rounds, "steps_per_round": args.steps, "sides": sides, "ratios": ratios,
            "command": "python -m experiments.peer_speed " + " ".join(sys.argv[1:]), "versions": _versions(args)}


def _versions(args) -> dict:
    import jax

    if not args.peer_python:
        return {"jax": jax.__version__}
    peer = subprocess.run([args.peer_python, "-c", "import torch, ultralytics; print(torch.__version__, "
                           "ultralytics.__version__)"], capture_output=True, text=True, timeout=120).stdout.split()
    return {"jax": jax.__version__, "torch": peer[0] if peer else None, "ultralytics": peer[1] if len(peer) > 1 else None}


def markdown(record: dict) -> str:
    unit = "img/s" if record["mode"] == "train" else "calls/s"
    lines = [f"{record['model']} {record['mode']}, {record['threads']} thread(s), batch {record['batch']}, "
             f"input {record['hw']}; {record['rounds']} interleaved rounds of {record['steps_per_round']}",
             "", f"| side | median ms | {unit} |", "|---|---|---|"]
    lines += [f"| {k} | {v['median_ms']:.2f} | {v['per_s']:.1f} |" for k, v in record["sides"].items()]
    lines += ["", "| ratio of times (> 1: the side after / is faster) | median | p10-p90 |", "|---|---|---|"]
    lines += [f"| {k} | {v['median']:.3f} | {v['p10']:.3f}-{v['p90']:.3f} |" for k, v in record["ratios"].items()]
    if record.get("twin_check"):
        check = record["twin_check"]
        lines += ["", f"twin ({check['layout']}) check: max |torch - JAX| / max |JAX| = {check['worst_relative']:.2e} "
                      f"over {len(check['outputs'])} outputs (tolerance {check['tolerance']:.0e})"]
    return "\n".join(lines)


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m experiments.peer_speed", description=__doc__.splitlines()[0])
    p.add_argument("mode", choices=("train", "forward"))
    p.add_argument("--peer-python", help="an interpreter with torch and ultralytics")
    p.add_argument("--model", default="yolov8n")
    p.add_argument("--threads", type=int, default=None, help="default: 2 for train, 1 for forward")
    p.add_argument("--batch", type=int, default=16, help="train: images per step")
    p.add_argument("--hw", default=None, help="input height,width (default 256,64; camera twins 256,416; "
                   "DSFEC twins: the grid)")
    p.add_argument("--twin-layout", default="channels_last", choices=("channels_last", "contiguous"),
                   help="a PyTorch twin's memory format (experiments/peer_twins.py)")
    p.add_argument("--rounds", type=int, default=8)
    p.add_argument("--steps", type=int, default=5, help="timed calls per worker per round")
    p.add_argument("--variants", default="command,library,tuned", type=lambda s: s.split(","))
    p.add_argument("--xla-flags", action="append", default=[], metavar="FLAGS",
                   help="also a JAX side started as a command with these XLA_FLAGS (repeatable): a flag's A/B")
    p.add_argument("--out", help="write the record (JSON) here")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--variant", choices=VARIANTS, help=argparse.SUPPRESS)
    p.add_argument("--batches-out", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.threads is None:
        args.threads = 2 if args.mode == "train" else 1
    if args.hw is None and not args.worker and not twin_export.family(args.model):
        args.hw = "256,64"
    if not args.worker:
        if not args.peer_python and len(args.variants) + len(args.xla_flags) < 2:
            p.error("--peer-python (an interpreter with torch and ultralytics), or at least two JAX sides to compare")
        unknown = sorted(set(args.variants) - set(VARIANTS))
        if unknown:
            p.error(f"--variants: unknown {unknown}; expected some of {list(VARIANTS)}")
    return args


def main(argv=None) -> int:
    args = parse(argv)
    if args.worker:
        return jax_worker(args)
    start = time.time()
    record = run(args)
    record["seconds"] = round(time.time() - start, 1)
    if args.out:
        from dsfec_jax.core import atomic

        atomic.write_text(args.out, json.dumps(record, indent=2) + "\n")
    print(markdown(record))
    return 0


if __name__ == "__main__":
    sys.exit(main())
