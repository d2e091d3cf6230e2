"""The verdict on one model: the device side against the reference side, and the kernels rule.

A difference passes when |device - reference| <= atol + rtol * scale, the scale being the
reference loss of that step (losses) or the largest |reference output| (the inference's maps,
whose small entries are noise next to that). Both sides must be finite and of the same shapes.
The kernels rule: a layer left on "auto" must not have taken the hand-written kernels for a
program that runs on another backend than the one they were measured on (kernels.MEASURED_ON).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...layers import kernels as kernel_choice
from .sides import SideResult


@dataclasses.dataclass(frozen=True)
class Tolerance:
    rtol: float = 1e-2
    atol: float = 1e-5

    def __post_init__(self):
        for field in ("rtol", "atol"):
            value = getattr(self, field)
            if not (isinstance(value, (int, float)) and 0 <= value < 1):
                raise ValueError(f"device check: {field}={value!r}; expected a number in [0, 1)")

    def allows(self, difference: float, scale: float) -> bool:
        return bool(np.isfinite(difference)) and difference <= self.atol + self.rtol * abs(scale)


def kernel_path(side: SideResult) -> dict:
    """Which formulations a side's programs took: 'fast' (every layer that asked took the
    hand-written ones), 'plain' (none did), 'mixed', or 'none' (no layer of the network asks)."""
    fast = sum(d.fast for d in side.decisions)
    path = "none" if not side.decisions else "fast" if fast == len(side.decisions) else "plain" if not fast else "mixed"
    return {"path": path, "requested": sorted({d.kernels for d in side.decisions}), "layers_fast": fast,
            "layers_asked": len(side.decisions), "backend_read": sorted({d.backend for d in side.decisions}),
            "platform": side.platform}


def kernels_rule_broken(side: SideResult) -> list[str]:
    """What breaks the rule on `side`: "auto" decisions that took the fast kernels for a program
    on another backend than MEASURED_ON ([] when none)."""
    wrong = [d for d in side.decisions if d.kernels == "auto" and d.fast and side.platform != kernel_choice.MEASURED_ON]
    if not wrong:
        return []
    return [f'{len(wrong)} layer(s) on kernels="auto" took the hand-written kernels for a {side.platform} program '
            f"(they were measured on {kernel_choice.MEASURED_ON}; hand_written read backend "
            f"{sorted({d.backend for d in wrong})})"]


def compare_losses(device: SideResult, reference: SideResult, tol: Tolerance) -> dict:
    a, b = np.asarray(device.losses), np.asarray(reference.losses)
    diff = np.abs(a - b)
    finite = bool(np.all(np.isfinite(a)) and np.all(np.isfinite(b)))
    ok = finite and all(tol.allows(d, s) for d, s in zip(diff, b))
    return {"device": device.losses, "reference": reference.losses, "max_abs_diff": float(np.max(diff)),
            "max_rel_diff": float(np.max(diff / np.maximum(np.abs(b), 1e-12))), "pass": ok}


def compare_outputs(device: SideResult, reference: SideResult, tol: Tolerance) -> dict:
    shapes = [x.shape for x in device.outputs], [x.shape for x in reference.outputs]
    if shapes[0] != shapes[1]:
        return {"pass": False, "error": f"output shapes differ: device {shapes[0]}, reference {shapes[1]}"}
    diff = max((float(np.max(np.abs(a - b))) if a.size else 0.0 for a, b in zip(device.outputs, reference.outputs)),
               default=0.0)
    scale = max((float(np.max(np.abs(b))) if b.size else 0.0 for b in reference.outputs), default=0.0)
    finite = all(np.all(np.isfinite(x)) for x in device.outputs + reference.outputs)
    return {"max_abs_diff": diff, "reference_max_abs": scale, "tolerance": tol.atol + tol.rtol * scale,
            "pass": bool(finite and tol.allows(diff, scale))}


def judge(device: SideResult, reference: SideResult, tol: Tolerance) -> dict:
    """The model's verdict: {'losses', 'outputs', 'kernels_rule', 'pass', 'failures'}."""
    losses, outputs = compare_losses(device, reference, tol), compare_outputs(device, reference, tol)
    rule = kernels_rule_broken(device) + kernels_rule_broken(reference)
    failures = ([] if losses["pass"] else [f"losses differ beyond rtol {tol.rtol}, atol {tol.atol}"]) + (
        [] if outputs["pass"] else [outputs.get("error", f"inference outputs differ beyond rtol {tol.rtol}, atol {tol.atol}")]
    ) + rule
    return {"losses": losses, "outputs": outputs, "kernels_rule": {"pass": not rule, "broken": rule},
            "pass": not failures, "failures": failures}
