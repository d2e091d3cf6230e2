"""Where a network's time goes against ONNX Runtime, conv by conv (issue 52):

    python -m experiments.conv_gap --model yolov8n [--hw 256,64] [--rounds 7] [--calls 200]
                                   [--record experiments/records/speed/conv_gap_yolov8n.json]
    python -m experiments.conv_gap --model yolov8n --thunks [--calls 100]

Every conv of the runtime form (`zoo.deploy`: BatchNorm folded, the small wide convs as one matrix
product where layers/conv_product.py takes them, a thin stem over blocks of pixels where
layers/conv_space_to_depth.py does, else the conv as it is, which XLA runs in YNNPACK's kernels or
its own) at the network's input size, timed alone at 1
thread with its bias and SiLU: as XLA runs it, and as ONNX Runtime runs the same Conv, Sigmoid and
Mul (NCHW, all graph optimisations). The two sides are interleaved round by round. A call of
either runtime costs a floor that a conv inside the whole network does not pay once more (an
identity call, measured the same way), so each side's floor is subtracted: the table gives the
kernels' own time, sorted by JAX minus ORT, and the sums say how much of the network's gap
the convs hold and which shapes hold most of it.

`--thunks` profiles the whole runtime form instead (jax.profiler, with XLA's per-thunk trace
events on): the time of each kind of XLA thunk a forward runs (`ynn_fusion`: a conv or matrix
product in YNNPACK's kernels; `conv_general_dilated`: a conv XLA keeps on its own kernel;
`divide_multiply_fusion`: a SiLU; ...), summed over its calls and averaged over the forwards.
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    import os
    import sys

    from dsfec_jax.core.host_memory import prepare_xla_process

    if "--thunks" in sys.argv:  # XLA's CPU thunks emit trace events: a flag XLA reads when it starts
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} --xla_cpu_enable_xprof_traceme=true".strip()
    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import os
import shlex
import statistics
import sys
import time

import numpy as np

from dsfec_jax.core import atomic, machine_load, threads
from dsfec_jax.core.environment import environment


def conv_shapes(name: str, hw) -> list[dict]:
    """Each dense conv the runtime form of `name` calls, in call order: input shape, kernel shape,
    stride, pads (None for a 1x1, a matrix product) and the form it runs in."""
    import flax.linen as nn
    import jax

    from dsfec_jax import zoo
    from dsfec_jax.layers import conv_product, conv_space_to_depth

    det = zoo.create(name)
    variables = det.init(jax.random.key(0))
    runtime, folded = zoo.deploy(det, variables)
    inputs = det.config.dummy_inputs(1, hw=hw) if hw else det.dummy_inputs(1)
    found = []

    def spy(next_fun, args, kwargs, context):
        module = context.module
        kernel = module.get_variable("params", "kernel") if isinstance(module, conv_product.DENSE) else None
        if context.method_name == "__call__" and kernel is not None:
            geometry = conv_product.geometry(module, args[0])
            form = "1x1 dot" if geometry is None else (
                "product" if conv_product.fits(args[0], kernel, *geometry) else
                "blocks" if conv_space_to_depth.fits(args[0], kernel, geometry[0]) else "conv")
            found.append({"input": list(args[0].shape), "kernel": list(kernel.shape), "stride": module.stride,
                          "pads": None if geometry is None else [list(p) for p in geometry[1]], "form": form})
        return next_fun(*args, **kwargs)

    with nn.intercept_methods(spy):
        jax.eval_shape(runtime.apply, folded, inputs)
    return found


def jax_call(conv: dict):
    """A zero-argument call of the conv as the runtime form computes it (+ bias, SiLU), jitted."""
    import jax
    import jax.numpy as jnp

    from jax import lax

    from dsfec_jax.layers import conv_product, conv_space_to_depth
    from dsfec_jax.layers.conv import DIMS

    rng = np.random.default_rng(0)
    x = jax.device_put(rng.standard_normal(conv["input"]).astype(np.float32))
    w = jax.device_put(0.1 * rng.standard_normal(conv["kernel"]).astype(np.float32))
    b = jax.device_put(np.zeros(conv["kernel"][-1], np.float32))
    s, pads = conv["stride"], None if conv["pads"] is None else tuple(tuple(p) for p in conv["pads"])
    if pads is None:
        body = lambda x, w: jnp.dot(x[:, ::s, ::s], w[0, 0])  # noqa: E731 (as PaddedConv runs a 1x1)
    elif conv["form"] == "product":
        body = lambda x, w: conv_product.conv_as_product(x, w, s, pads)  # noqa: E731
    elif conv["form"] == "blocks":
        body = lambda x, w: conv_space_to_depth.conv_as_space_to_depth(x, w, s, pads)  # noqa: E731
    else:
        body = lambda x, w: lax.conv_general_dilated(x, w, (s, s), pads, dimension_numbers=DIMS)  # noqa: E731
    fn = jax.jit(lambda x, w, b: jax.nn.silu(body(x, w) + b))
    return lambda: jax.block_until_ready(fn(x, w, b))


def ort_call(conv: dict):
    """The same conv (+ bias, Sigmoid, Mul) as one ONNX Runtime session at 1 thread, NCHW."""
    from onnx import TensorProto, helper

    n, h, w_, c = conv["input"]
    k, _, _, out = conv["kernel"]
    (top, bottom), (left, right) = conv["pads"] or ((0, 0), (0, 0))
    rng = np.random.default_rng(0)
    weight = helper.make_tensor("W", TensorProto.FLOAT, [out, c, k, k],
                                (0.1 * rng.standard_normal((out, c, k, k))).astype(np.float32).ravel())
    bias = helper.make_tensor("B", TensorProto.FLOAT, [out], np.zeros(out, np.float32))
    nodes = [helper.make_node("Conv", ["x", "W", "B"], ["c"], kernel_shape=[k, k], strides=[conv["stride"]] * 2,
                              pads=[top, left, bottom, right]),
             helper.make_node("Sigmoid", ["c"], ["s"]), helper.make_node("Mul", ["c", "s"], ["y"])]
    return _session(nodes, [n, c, h, w_], [weight, bias])


def _session(nodes, input_shape, initializers):
    import onnxruntime as ort
    from onnx import TensorProto, helper

    graph = helper.make_graph(nodes, "conv", [helper.make_tensor_value_info("x", TensorProto.FLOAT, input_shape)],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, None)], initializers)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 9  # the newest onnxruntime 1.31 reads
    options = ort.SessionOptions()
    options.intra_op_num_threads = options.inter_op_num_threads = 1
    session = ort.InferenceSession(model.SerializeToString(), options, providers=["CPUExecutionProvider"])
    feed = {"x": np.ones(input_shape, np.float32)}
    return lambda: session.run(None, feed)


def floors():
    """(JAX, ORT) calls that do next to nothing: what a call costs before any kernel runs."""
    import jax
    import jax.numpy as jnp
    from onnx import helper

    x = jax.device_put(np.ones((1, 4), np.float32))
    fn = jax.jit(lambda x: x + 1.0)
    return (lambda: jax.block_until_ready(fn(x)),
            _session([helper.make_node("Identity", ["x"], ["y"])], [1, 4], []))


def per_call_us(fn, calls: int) -> float:
    start = time.perf_counter()
    for _ in range(calls):
        fn()
    return 1e6 * (time.perf_counter() - start) / calls


def interleaved_us(pairs: list[tuple], rounds: int, calls: int) -> list[tuple[float, float]]:
    """Median per-call microseconds of each (JAX, ORT) pair, the pairs timed round-robin."""
    for pair in pairs:
        for fn in pair:
            for _ in range(3):  # compiled, and past any first-calls' cost
                fn()
    times = [([], []) for _ in pairs]
    for _ in range(rounds):
        for pair, (a, b) in zip(pairs, times):
            a.append(per_call_us(pair[0], calls))
            b.append(per_call_us(pair[1], calls))
    return [(statistics.median(a), statistics.median(b)) for a, b in times]


def measure(name: str, hw, rounds: int, calls: int) -> dict:
    convs = conv_shapes(name, hw)
    pairs = [floors()] + [(jax_call(c), ort_call(c)) for c in convs]
    with machine_load.watch() as load:
        timed = interleaved_us(pairs, rounds, calls)
    (jax_floor, ort_floor), rows = timed[0], []
    for conv, (j, o) in zip(convs, timed[1:]):
        rows.append({**conv, "jax_us": round(j - jax_floor, 1), "ort_us": round(o - ort_floor, 1),
                     "gap_us": round((j - jax_floor) - (o - ort_floor), 1)})
    return {"model": name, "hw": list(hw) if hw else None, "rounds": rounds, "calls": calls,
            "floor_us": {"jax": round(jax_floor, 1), "ort": round(ort_floor, 1)},
            "sum_us": {"jax": round(sum(r["jax_us"] for r in rows), 1), "ort": round(sum(r["ort_us"] for r in rows), 1)},
            "convs": rows, "machine_load": load.verdict}


def thunk_times(name: str, hw, calls: int) -> dict[str, dict]:
    """{thunk kind: {"us": per forward, "count": per forward}} of the runtime form's forward."""
    import collections
    import re
    import tempfile
    from pathlib import Path

    import jax
    from jax.profiler import ProfileData

    from dsfec_jax import zoo

    det = zoo.create(name)
    runtime, folded = zoo.deploy(det, det.init(jax.random.key(0)))
    inputs = jax.device_put(det.config.dummy_inputs(1, hw=hw) if hw else det.dummy_inputs(1))
    forward = jax.jit(runtime.apply)
    # the thunks are the compiled program's instructions; with dispatch inline (the commands' setting)
    # they run on the calling thread, among the Python events
    instructions = set(re.findall(r"%([\w.-]+) = ", forward.lower(folded, inputs).compile().as_text()))
    for _ in range(10):
        jax.block_until_ready(forward(folded, inputs))
    with tempfile.TemporaryDirectory() as out:
        with jax.profiler.trace(out):
            for _ in range(calls):
                jax.block_until_ready(forward(folded, inputs))
        profile = ProfileData.from_file(str(next(Path(out).rglob("*.xplane.pb"))))
    kinds = collections.defaultdict(lambda: [0.0, 0])
    for plane in profile.planes:
        for line in plane.lines:
            for event in line.events:
                if event.name in instructions:
                    kind = kinds[re.sub(r"\.\d+$", "", event.name)]
                    kind[0] += event.duration_ns / 1e3 / calls
                    kind[1] += 1
    return {k: {"us": round(us, 1), "count": n // calls} for k, (us, n) in sorted(kinds.items(), key=lambda kv: -kv[1][0])}


def thunks_markdown(name: str, kinds: dict[str, dict]) -> str:
    total = sum(k["us"] for k in kinds.values())
    lines = [f"{name}: XLA thunks a forward, {total / 1e3:.2f} ms in all", "", "| thunk kind | calls | us | share |",
             "|---|---|---|---|"]
    lines += [f"| {kind} | {k['count']} | {k['us']:.0f} | {100 * k['us'] / total:.0f} % |" for kind, k in kinds.items()
              if k["us"] >= 0.005 * total]
    return "\n".join(lines) + "\n"


def markdown(result: dict, top: int = 12) -> str:
    rows = sorted(result["convs"], key=lambda r: -r["gap_us"])
    total = result["sum_us"]
    lines = [f"{result['model']} at {result['hw']}: {len(rows)} convs; kernels' own time (call floors "
             f"{result['floor_us']['jax']} / {result['floor_us']['ort']} us subtracted): JAX {total['jax'] / 1e3:.2f} ms, "
             f"ORT {total['ort'] / 1e3:.2f} ms, gap {(total['jax'] - total['ort']) / 1e3:+.2f} ms",
             "", "| input (NHWC) | kernel | stride | form | JAX us | ORT us | JAX - ORT us |", "|---|---|---|---|---|---|---|"]
    for r in rows[:top]:
        lines.append(f"| {'x'.join(map(str, r['input']))} | {'x'.join(map(str, r['kernel']))} | {r['stride']} | {r['form']} "
                     f"| {r['jax_us']} | {r['ort_us']} | {r['gap_us']:+} |")
    rest = rows[top:]
    if rest:
        lines.append(f"| the other {len(rest)} | | | | {sum(r['jax_us'] for r in rest):.0f} | "
                     f"{sum(r['ort_us'] for r in rest):.0f} | {sum(r['gap_us'] for r in rest):+.0f} |")
    note = machine_load.note(result["machine_load"])
    return "\n".join(lines) + (f"\n\n{note}" if note else "") + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.conv_gap", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", default="yolov8n")
    p.add_argument("--hw", default="256,64", help="input height,width (default 256,64: the RD maps)")
    p.add_argument("--rounds", type=int, default=7)
    p.add_argument("--calls", type=int, default=200, help="calls per timing (their mean)")
    p.add_argument("--record", default=None, help="write the figures here (JSON, with the command and versions)")
    p.add_argument("--thunks", action="store_true", help="profile the whole forward by XLA thunk kind instead")
    args = p.parse_args(sys.argv[1:] if argv is None else argv)
    threads.pin(1)  # before XLA starts
    hw = tuple(int(v) for v in args.hw.split(",")) if args.hw else None
    if args.thunks:
        if "xprof_traceme=true" not in os.environ.get("XLA_FLAGS", ""):
            raise SystemExit("--thunks needs XLA_FLAGS=--xla_cpu_enable_xprof_traceme=true before XLA starts: run it "
                             "as `python -m experiments.conv_gap --thunks`, which sets it")
        print(thunks_markdown(args.model, thunk_times(args.model, hw, args.calls)))
        return 0
    result = measure(args.model, hw, args.rounds, args.calls)
    machine_load.warn(result["machine_load"], "the conv timings")
    text = markdown(result)
    print(text)
    if args.record:
        command = "python -m experiments.conv_gap " + " ".join(shlex.quote(a) for a in (sys.argv[1:] if argv is None else argv))
        atomic.write_json(args.record, {"command": command, **result, "markdown": text, "environment": environment()})
        print(f"record: {args.record}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
