"""The device check (`python -m dsfec_jax.profile.device_check`): on this CPU every family trains
and infers as the reference does and the record says so; perturbed weights on one side fail the
check; "auto" having taken the hand-written kernels for a program of another backend fails it."""

import dataclasses
import json

import jax
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.layers import kernels
from dsfec_jax.profile.device_check import __main__ as device_check
from dsfec_jax.profile.device_check import check, sides, verdict

# the smallest sizes the check takes: one frame a step, two compared steps, one timed call of each;
# the networks with their fewest blocks and narrowest layers (the same layers, quick to compile)
DSFEC = ("stage_blocks=(1,1,1,1),stage_widths=(8,8,8,8),neck_widths=(8,),head_convs=1,head_width=8,"
         "fec_filters=(8,16,8),stem_filters=8,pointpillars_filters=8")
SMALLEST = ["--batch", "1", "--steps", "2", "--timed-steps", "1", "--repeats", "1", "--window", "16",
            "--pillars", "16", "--image-size", "32",
            "--set", f"dsfec_s:{DSFEC}", "--set", f"baseline:{DSFEC}",
            "--set", "radarnext_fpn:layer_nums=(1,1,1),channels=(8,16,32),fpn_channels=8,head_width=8,pillar_filters=8",
            "--set", "shuffle_yolov3:widths=(16,16,32,32,64),repeats=(1,1,1,1,1),head_widths=(16,32,64),head_units=1"]


def run(tmp_path, models: str | None = None) -> tuple[int, dict]:
    """The check at the smallest sizes, on every model or on `models`."""
    out = tmp_path / "record.json"
    only = [] if models is None else ["--models", models]
    sets = [a for k, a in zip(SMALLEST, SMALLEST[1:]) if k == "--set" and (models is None or a.split(":")[0] in models)]
    sizes = SMALLEST[:SMALLEST.index("--set")]
    code = device_check.main([*sizes, *[x for a in sets for x in ("--set", a)], *only, "--out", str(out)])
    return code, json.loads(out.read_text())


# one model of each family (and the depth net): what the command checks by default, less the second
# DSFEC and YOLO models, which are their families' same programs at other widths (each compile costs)
ONE_A_FAMILY = ("dsfec_s", "radarnext_fpn", "yolov8n", "shuffle_yolov3", "monodepth_tiny")


@pytest.fixture(scope="module")
def every_family(tmp_path_factory):
    return run(tmp_path_factory.mktemp("device_check"), ",".join(ONE_A_FAMILY))


def test_every_family_passes_on_the_cpu(every_family, capsys):
    code, record = every_family
    assert code == 0 and record["passed"]
    assert [m["model"] for m in record["models"]] == list(ONE_A_FAMILY)
    assert set(ONE_A_FAMILY) <= set(device_check.MODELS)
    assert {m["family"] for m in record["models"]} == set(zoo.FAMILIES) | set(zoo.AUXILIARIES)
    assert all(m["pass"] and m["losses"]["pass"] and m["outputs"]["pass"] and m["kernels_rule"]["pass"]
               for m in record["models"])
    # a CPU-only host: the reference is the same backend, and the record says so
    assert record["backend"] == record["reference_backend"] == "cpu" and record["same_backend"]
    assert "same cpu backend" in record["reference"]
    for key in ("versions", "device_kind", "command", "seed", "settings"):
        assert record[key] is not None, key
    for m in record["models"]:
        assert m["train_steps_per_s"] > 0 and m["infer_ms"] > 0 and m["peak_memory"]["bytes"] > 0, m["model"]
        assert len(m["losses"]["device"]) == 2 and m["reference"]["kernel_path"]["path"] in ("plain", "none")
    paths = {m["model"]: m["device"]["kernel_path"]["path"] for m in record["models"]}
    assert paths["dsfec_s"] == paths["shuffle_yolov3"] == "fast"  # "auto" on the backend they were measured on


def perturbed(workload):
    """The workload with every float parameter scaled by 1.2: wrong weights."""
    params = jax.tree.map(lambda x: x * 1.2 if x.dtype.kind == "f" else x, workload.initial_state["params"])
    return dataclasses.replace(workload, initial_state={**workload.initial_state, "params": params})


def test_wrong_weights_on_one_side_fail_the_check(tmp_path, monkeypatch):
    real = check.run_side

    def device_side_wrong(workload, device, kernels_asked, *args):
        return real(perturbed(workload) if kernels_asked is None else workload, device, kernels_asked, *args)

    monkeypatch.setattr(check, "run_side", device_side_wrong)
    code, record = run(tmp_path, "dsfec_s")
    (model,) = record["models"]
    assert code == 1 and not record["passed"] and not model["pass"]
    assert not model["outputs"]["pass"] and not model["losses"]["pass"], model


def test_auto_taking_the_fast_kernels_on_another_backend_fails(tmp_path, monkeypatch):
    """The device side's program reported as a GPU's: its "auto" layers read the CPU backend and
    took the hand-written kernels, which were not measured there."""
    monkeypatch.setattr(sides, "platform_of", lambda device: "gpu")
    code, record = run(tmp_path, "dsfec_s")
    (model,) = record["models"]
    assert code == 1 and model["losses"]["pass"] and not model["kernels_rule"]["pass"]
    assert 'kernels="auto" took the hand-written kernels for a gpu program' in model["failures"][0]
    assert kernels.MEASURED_ON == "cpu"


def test_observed_decisions_hold_each_choice_and_the_backend_read(monkeypatch):
    monkeypatch.setattr(kernels.jax, "default_backend", lambda: "gpu")
    monkeypatch.delenv("DSFEC_KERNELS", raising=False)
    with kernels.observed_decisions() as log:
        kernels.hand_written("auto")
        kernels.hand_written("fast")
    kernels.hand_written("plain")  # after the block: not collected
    assert log == [kernels.Decision("auto", "gpu", False), kernels.Decision("fast", "gpu", True)]


def side(platform, decisions=(), losses=(2.0, 1.5), outputs=(np.linspace(-3, 3, 7),)):
    return sides.SideResult(platform, "test", None, list(losses), [np.asarray(o) for o in outputs], list(decisions), 0.0)


def test_the_verdict_holds_the_tolerance_and_the_kernels_rule():
    tol = verdict.Tolerance(rtol=1e-2, atol=0.0)
    assert verdict.judge(side("gpu"), side("cpu"), tol)["pass"]
    off = verdict.judge(side("gpu", outputs=(np.linspace(-3, 3, 7) * 1.02,)), side("cpu"), tol)
    assert not off["pass"] and off["losses"]["pass"] and not off["outputs"]["pass"]
    assert not verdict.judge(side("gpu", losses=(2.0, float("nan"))), side("cpu"), tol)["losses"]["pass"]
    auto_fast = [kernels.Decision("auto", "cpu", True)]
    assert verdict.kernels_rule_broken(side(kernels.MEASURED_ON, auto_fast)) == []
    assert "for a gpu program" in verdict.kernels_rule_broken(side("gpu", auto_fast))[0]
    assert verdict.kernels_rule_broken(side("gpu", [kernels.Decision("fast", "cpu", True)])) == []  # asked for by name
