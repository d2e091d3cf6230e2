"""Where a compiled program's time goes: per HLO instruction, per Flax module and phase, and
per op kind, read from the XLA profiler.

How: `capture` runs a few calls of the program under `jax.profiler.trace`, which writes an XSpace
protobuf (`*.xplane.pb`) holding one line per thread and one event per executed thunk, named
after its HLO instruction ('fusion.12', 'convolution.3', 'ynn_fusion.148'). XLA's CPU runtime
runs thunks on its intra-op pool ('tf_XLAEigen/...' lines) and, inline, on the calling thread,
so every line is read and an event counts when its name is an instruction of the program;
the runtime's own events ('ThunkExecutor::Execute', 'end: fusion.12', Python frames) are not.
Each instruction is then found in the compiled module's text (`compiled.as_text()`), whose
`metadata={op_name="jit(f)/transpose(jvp(Net))/Net.backbone/stage2_block0/dw/..."}` names the
JAX call path: 'transpose(' marks the backward pass, 'jvp(' the forward of differentiated code,
and what lies outside both is the step's update (optimizer, gradient norm).

XLA creates instructions with no metadata (weight-gradient convolutions, layout copies). Those are
attributed through their operands: the nearest operands (breadth first, a few hops) that carry
metadata, preferring a backward one, since an instruction that reads a backward value belongs to
the backward pass. The share of time attributed that way is reported ('operands'), and whatever
stays unattributed is listed with its HLO line so a reader sees what it is.

The trace format is read with `jax.profiler.ProfileData` (jaxlib's reader); see
https://docs.jax.dev/en/latest/profiling.html.
"""

from __future__ import annotations

import collections
import dataclasses
import re
import tempfile
import time
from pathlib import Path
from typing import Callable

MODULE_DEPTH = 2  # module path components kept after the network: 'DSFECNet.backbone/stage2_block0'
OPERAND_HOPS = 4  # how far an instruction without metadata looks through its operands
TOP_ROWS = 15

_INSTRUCTION = re.compile(r"^\s*(?:ROOT\s+)?%([\w.\-]+)\s*=\s*(.*)$")
_OP_NAME = re.compile(r'metadata=\{[^}]*?op_name="([^"]*)"')
_FUSION_KIND = re.compile(r"\bkind=(k\w+)")
_CUSTOM_KIND = re.compile(r'"fusion_config":\{"kind":"_*([\w]+)"')
_OPERAND = re.compile(r"%([\w.\-]+)")
_METHOD_CALL = re.compile(r"^[A-Za-z_]\w*\.[A-Za-z_]\w*$")  # 'adapter.exchange': module.method


@dataclasses.dataclass(frozen=True)
class Instruction:
    """One HLO instruction of a compiled module: its op kind, result shape, operands and JAX path."""

    name: str
    op: str
    shape: str
    operands: tuple[str, ...]
    op_name: str | None
    text: str


def _split_shape(rest: str) -> tuple[str, str]:
    """'f32[8,4]{1,0} add(%a, %b), ...' -> ('f32[8,4]{1,0}', 'add(%a, %b), ...'); tuple shapes
    '(f32[2], s32[])' are matched by their parentheses."""
    if not rest.startswith("("):
        shape, _, tail = rest.partition(" ")
        return shape, tail
    depth = 0
    for i, ch in enumerate(rest):
        depth += (ch == "(") - (ch == ")")
        if depth == 0:
            return rest[: i + 1], rest[i + 1 :].lstrip()
    return rest, ""


def _call_arguments(tail: str) -> str:
    """The text inside the opcode's parentheses: 'add(%a, %b), x=1' -> '%a, %b'."""
    start = tail.find("(")
    if start < 0:
        return ""
    depth = 0
    for i in range(start, len(tail)):
        depth += (tail[i] == "(") - (tail[i] == ")")
        if depth == 0:
            return tail[start + 1 : i]
    return tail[start + 1 :]


def _op_kind(opcode: str, tail: str) -> str:
    """The opcode, with a fusion's kind: 'fusion:kLoop', or a custom fusion's backend
    ('fusion:ynn_fusion', XLA CPU's XNNPACK/YNNPACK-backed dots and convolutions)."""
    if opcode != "fusion":
        return opcode
    custom = _CUSTOM_KIND.search(tail)
    if custom:
        return f"fusion:{custom.group(1)}"
    kind = _FUSION_KIND.search(tail)
    return f"fusion:{kind.group(1)}" if kind else "fusion"


def parse_hlo(text: str) -> dict[str, Instruction]:
    """Every instruction of an HLO module's text (`compiled.as_text()`), by name. Names are unique
    in a module; instructions inside fused computations are listed too (harmless: only the
    executed ones appear in a trace)."""
    table = {}
    for line in text.splitlines():
        m = _INSTRUCTION.match(line)
        if not m:
            continue
        name, rest = m.groups()
        shape, tail = _split_shape(rest)
        opcode = tail.split("(", 1)[0].strip()
        op_name = _OP_NAME.search(tail)
        table[name] = Instruction(name, _op_kind(opcode, tail), shape,
                                  tuple(_OPERAND.findall(_call_arguments(tail))),
                                  op_name.group(1) if op_name else None, line.strip())
    return table


def phase_and_module(op_name: str, depth: int = MODULE_DEPTH) -> tuple[str, str]:
    """('bwd' | 'fwd' | 'update', module) of a JAX op_name.

    'jit(step)/transpose(jvp(DSFECNet))/DSFECNet.backbone/stage2_block0/dw/mul' ->
    ('bwd', 'DSFECNet.backbone/stage2_block0'); differentiated code outside any module (the
    loss: 'jvp()', 'jvp(jit(log_sigmoid))') -> 'loss'; code outside jvp/transpose (optimizer,
    gradient norm, parameter update) -> ('update', 'update'). A module method called inside another
    module's call starts the path: '.../Net.features/backbone/adapter.exchange/exchangers_0/...' ->
    'adapter.exchange/exchangers_0'."""
    parts = [p for p in op_name.split(";")[0].split("/") if p]
    while parts and parts[0].startswith("jit("):  # the program's own jit(...) wrapper(s)
        parts = parts[1:]
    wrapper = _unwrap(parts[0]) if parts else None
    if wrapper is None:
        return "update", "update"
    phase, network = wrapper
    if not network or network.startswith("jit("):
        return phase, "loss"
    path = parts[1:-1]  # the last component is the primitive ('mul', 'conv_general_dilated')
    if path and path[0] == network:  # a module's __call__ repeats the network's name
        path = path[1:]
    # a module's method called from inside another module ('Net.features/backbone/adapter.exchange/...':
    # the Adapter's hook, run inside the backbone's loop) is that module's work: its path starts there
    calls = [i for i, part in enumerate(path) if i > 0 and _METHOD_CALL.match(part)]
    if calls:
        path = path[calls[-1]:]
    return phase, "/".join(path[:depth]) or network


def _unwrap(component: str) -> tuple[str, str] | None:
    """'transpose(jvp(Net))' -> ('bwd', 'Net'); 'jvp(Net)' -> ('fwd', 'Net'); others -> None."""
    phase = "fwd"
    if component.startswith("transpose(") and component.endswith(")"):
        phase, component = "bwd", component[len("transpose("):-1]
    if component.startswith("jvp(") and component.endswith(")"):
        return phase, component[len("jvp("):-1]
    return None


def attribute(name: str, table: dict[str, Instruction], hops: int = OPERAND_HOPS) -> tuple[str | None, str]:
    """(op_name, how) of an instruction: its own metadata ('metadata'); else, through its operands
    ('operands'), the nearest backward op_name within `hops`, or failing that the nearest one (a
    weight gradient reads a forward activation directly and the backward cotangent through
    layout copies without metadata); else (None, 'none'). The search stops at operands that
    carry metadata: what lies behind them belongs to them."""
    inst = table.get(name)
    if inst is None:
        return None, "none"
    if inst.op_name:
        return inst.op_name, "metadata"
    nearest, frontier, seen = None, list(inst.operands), {name}
    for _ in range(hops):  # breadth first: the nearest backward op_name, else the nearest one
        found = [table[o].op_name for o in frontier if o in table and table[o].op_name]
        backward = [f for f in found if "transpose(" in f]
        if backward:
            return backward[0], "operands"
        nearest = nearest or (found[0] if found else None)
        seen.update(frontier)
        frontier = [p for o in frontier if o in table and not table[o].op_name
                    for p in table[o].operands if p not in seen]
    return (nearest, "operands") if nearest else (None, "none")


def xplane_file(directory: str | Path) -> Path:
    found = sorted(Path(directory).rglob("*.xplane.pb"))
    if not found:
        raise FileNotFoundError(f"{directory}: the profiler wrote no *.xplane.pb")
    return found[-1]


def instruction_times(xplane: str | Path, names) -> collections.Counter:
    """Self time (ns, summed over every thread) of each event named in `names`: an event's time
    less that of events of `names` nested inside it on the same thread, so nothing counts twice."""
    from jax.profiler import ProfileData

    data = ProfileData.from_file(str(xplane))
    times: collections.Counter = collections.Counter()
    for plane in data.planes:
        for line in plane.lines:
            events = sorted(((e.start_ns, e.duration_ns, e.name) for e in line.events if e.name in names),
                            key=lambda e: (e[0], -e[1]))
            open_events: list[list] = []  # [end, name, self time] of enclosing events
            for start, duration, event in events:
                while open_events and open_events[-1][0] <= start:
                    _, done, own = open_events.pop()
                    times[done] += own
                if open_events:
                    open_events[-1][2] -= duration
                open_events.append([start + duration, event, duration])
            for _, done, own in open_events:
                times[done] += own
    return times


def capture(run_once: Callable[[], None], steps: int, directory: str | Path | None = None) -> tuple[Path, float]:
    """Trace `steps` calls of `run_once` (each must block until its results are ready) -> (the
    .xplane.pb written, wall seconds of the calls alone: starting and stopping the profiler takes
    about a second, which a tiny program's steps would not amortise). Warm the program up
    before: compiles and first-call allocations would otherwise land in the trace."""
    import jax

    directory = Path(directory or tempfile.mkdtemp(prefix="dsfec-xplane-"))
    with jax.profiler.trace(str(directory)):
        start = time.perf_counter()
        for _ in range(steps):
            run_once()
        seconds = time.perf_counter() - start
    return xplane_file(directory), seconds


def breakdown(hlo_text: str, xplane: str | Path, steps: int, top: int = TOP_ROWS) -> dict:
    """Op time per step of a traced program (`steps` calls), by (phase, module), by op kind, and
    its top instructions, each in ms per step and % of the program's op time. Op time is the
    events' wall time on their threads, summed over threads: on a shared machine it includes
    time a thread was preempted, so it is CPU time only on an idle one."""
    table = parse_hlo(hlo_text)
    times = instruction_times(xplane, table.keys())
    total_ns = sum(times.values())
    if total_ns <= 0:
        raise ValueError(f"{xplane}: no event of the program's {len(table)} HLO instructions was traced")
    by_module, by_submodule = collections.Counter(), collections.Counter()
    by_op, how_ns = collections.Counter(), collections.Counter()
    rows = []
    for name, ns in times.items():
        op_name, how = attribute(name, table)
        phase, module = phase_and_module(op_name) if op_name else ("unattributed", "unattributed")
        by_module[(phase, module)] += ns
        by_submodule[phase_and_module(op_name, MODULE_DEPTH + 1) if op_name else (phase, module)] += ns
        by_op[table[name].op] += ns
        how_ns[how] += ns
        rows.append((ns, name, phase, module, how))

    def ms(ns):
        return round(ns / steps / 1e6, 3)

    def pct(ns):
        return round(100 * ns / total_ns, 2)

    rows.sort(reverse=True)
    unattributed = [r for r in rows if r[4] == "none"]
    return {
        "steps_traced": steps,
        "op_ms_per_step": ms(total_ns),
        "attribution_percent": {k: pct(how_ns[k]) for k in ("metadata", "operands", "none")},
        "by_phase": {p: pct(sum(v for (q, _), v in by_module.items() if q == p))
                     for p in sorted({q for q, _ in by_module})},
        "by_module": [{"phase": p, "module": m, "ms": ms(v), "percent": pct(v)}
                      for (p, m), v in by_module.most_common(top)],
        "by_submodule": [{"phase": p, "module": m, "ms": ms(v), "percent": pct(v)}
                         for (p, m), v in by_submodule.most_common(top)],
        "by_op": [{"op": o, "ms": ms(v), "percent": pct(v)} for o, v in by_op.most_common(top)],
        "top_instructions": [_row(r, table, ms, pct) for r in rows[:top]],
        "top_unattributed": [_row(r, table, ms, pct) for r in unattributed[:5]],
    }


def _row(row: tuple, table: dict[str, Instruction], ms, pct) -> dict:
    ns, name, phase, module, how = row
    inst = table[name]
    return {"instruction": name, "op": inst.op, "shape": inst.shape, "phase": phase, "module": module,
            "attributed_by": how, "ms": ms(ns), "percent": pct(ns), "hlo": _short(inst.text)}


def _short(line: str, limit: int = 240) -> str:
    """An HLO line without its backend config and stack-frame ids, cut to `limit` characters."""
    line = re.sub(r",\s*backend_config=.*", "", line)
    line = re.sub(r"\s*stack_frame_id=\d+", "", line)
    return line if len(line) <= limit else line[: limit - 3] + "..."


def markdown(result: dict, rows: int = 8, full: bool = True) -> str:
    """The top rows by module (two and three path levels) and by op kind as small markdown tables;
    full=False: the summary line and the module table only (the train-bench table's short form, docs/profiler.md)."""
    busy = result.get("busy_percent_of_threads")
    lines = [f"Op time per step {result['op_ms_per_step']:.1f} ms summed over threads"
             + (f" ({busy:.0f} % of the threads' time while traced)" if busy else "") + "; by phase: "
             + ", ".join(f"{p} {v:.0f} %" for p, v in result["by_phase"].items() if v >= 0.5)
             + "; attributed by metadata {metadata:.0f} %, through operands {operands:.0f} %, "
               "unattributed {none:.0f} %".format(**result["attribution_percent"])]
    for key, title in (("by_module", "module"), ("by_submodule", "submodule"))[: 2 if full else 1]:
        lines += ["", f"| phase | {title} | ms/step | % |", "|---|---|---|---|"]
        lines += [f"| {r['phase']} | {r['module']} | {r['ms']:.2f} | {r['percent']:.1f} |" for r in result[key][:rows]]
    if not full:
        return "\n".join(lines)
    lines += ["", "| HLO op | ms/step | % |", "|---|---|---|"]
    lines += [f"| {r['op']} | {r['ms']:.2f} | {r['percent']:.1f} |" for r in result["by_op"][:rows]]
    if result["top_unattributed"]:
        lines += ["", "Unattributed (no metadata on the instruction or its near operands):"]
        lines += [f"- {r['ms']:.2f} ms `{r['hlo']}`" for r in result["top_unattributed"][:3]]
    return "\n".join(lines)
