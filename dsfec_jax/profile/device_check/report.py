"""The device check's record (one JSON file: versions, backend, device kind, command, seed,
settings and each model's figures and verdict) and its printed lines."""

from __future__ import annotations

import dataclasses

from ...core.provenance import jsonable, versions
from ...layers import kernels as kernel_choice
from .sides import SideResult
from .verdict import kernel_path
from .workload import Workload

FORMAT = "dsfec_jax.device_check/1"
MIB = 2**20


def reference_text(device_platform: str, reference_platform: str) -> str:
    """What the reference is, said plainly: on a host with no other backend it is the same one."""
    if device_platform == reference_platform:
        return (f"the same {reference_platform} backend (no other backend is compared on this host): the device "
                "side's kernels against the textbook ones (kernels='plain') on one backend, not two backends")
    return f"the {reference_platform} backend, textbook kernels (kernels='plain'), same inputs and weights"


def side_record(side: SideResult) -> dict:
    return {"platform": side.platform, "device_kind": side.device_kind, "kernels_override": side.kernels,
            "kernel_path": kernel_path(side), "compile_s": round(side.compile_s, 3)}


def model_record(workload: Workload, device: SideResult, reference: SideResult, verdict: dict) -> dict:
    return {"model": workload.model, "family": workload.family, "config_kernels": workload.kernels,
            "input": workload.input_shapes(), "device": side_record(device), "reference": side_record(reference),
            "train_steps_per_s": _rounded(device.steps_per_s, 3), "infer_ms": _rounded(device.infer_ms, 3),
            "peak_memory": device.memory, **verdict}


def payload(command: str, seed: int, settings: dict, device, reference, models: list[dict], precision: str) -> dict:
    """The whole record. `device`, `reference`: the jax devices of the two sides."""
    return {"format": FORMAT, "command": command, "seed": seed, "settings": jsonable(settings),
            "backend": device.platform, "device_kind": device.device_kind, "device": str(device),
            "reference_backend": reference.platform, "reference_device": str(reference),
            "reference": reference_text(device.platform, reference.platform),
            "same_backend": device.platform == reference.platform, "matmul_precision": precision,
            "kernels_measured_on": kernel_choice.MEASURED_ON, "versions": versions(),
            "passed": all(m["pass"] for m in models), "models": models}


def settings_dict(settings) -> dict:
    return dataclasses.asdict(settings) if dataclasses.is_dataclass(settings) else dict(settings)


def lines(record: dict) -> list[str]:
    """The report a person reads: the sides, then one block per model, then the verdict."""
    out = [f"device check: {record['backend']} ({record['device_kind']}) against {record['reference']}",
           f"hand-written kernels measured on {record['kernels_measured_on']}; matmul precision "
           f"{record['matmul_precision']}; seed {record['seed']}"]
    for m in record["models"]:
        dev, ref = m["device"]["kernel_path"], m["reference"]["kernel_path"]
        losses, outputs = m["losses"], m["outputs"]
        memory = m["peak_memory"] or {}
        out += [f"{m['model']} ({m['family']}, input {_shapes(m['input'])}): {'PASS' if m['pass'] else 'FAIL'}",
                f"  kernels: device {_path(dev, m['config_kernels'])}; reference {_path(ref, m['reference']['kernels_override'])}",
                f"  losses device {_floats(losses['device'])} reference {_floats(losses['reference'])}: max |diff| "
                f"{losses['max_abs_diff']:.3g} (rel {losses['max_rel_diff']:.2g}) {'ok' if losses['pass'] else 'FAIL'}",
                "  inference: " + (outputs["error"] if "error" in outputs else
                                   f"max |diff| {outputs['max_abs_diff']:.3g} <= tol {outputs['tolerance']:.3g} "
                                   f"(max |ref| {outputs['reference_max_abs']:.3g}) {'ok' if outputs['pass'] else 'FAIL'}"),
                f"  {_rate(m['train_steps_per_s'])} train steps/s, inference {_rate(m['infer_ms'])} ms, compile "
                f"{m['device']['compile_s']:.1f} s; peak memory {_mib(memory.get('bytes'))} MiB: {memory.get('source', '-')}"]
        out += [f"  failure: {f}" for f in m["failures"]]
    failed = [m["model"] for m in record["models"] if not m["pass"]]
    out.append("device check: PASS" if not failed else f"device check: FAIL ({', '.join(failed)})")
    return out


def _path(path: dict, asked) -> str:
    kernels = f"kernels={asked!r}" if asked is not None else "no kernels field"
    if path["path"] == "none":
        return f"none ({kernels}: no layer asks for hand-written kernels)"
    return (f"{path['path']} ({kernels}: {path['layers_fast']} of {path['layers_asked']} layer choices fast, "
            f"{path['platform']} program, backend read {','.join(path['backend_read'])})")


def _shapes(shapes: dict) -> str:
    return ", ".join(f"{k} {'x'.join(map(str, v))}" for k, v in shapes.items())


def _floats(values: list[float]) -> str:
    return "[" + ", ".join(f"{v:.5g}" for v in values) + "]"


def _rate(value) -> str:
    return "-" if value is None else f"{value:.3g}"


def _mib(value) -> str:
    return "-" if value is None else f"{value / MIB:.0f}"


def _rounded(value, digits: int):
    return None if value is None else round(value, digits)
