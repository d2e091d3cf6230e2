"""Set-up as a new user meets it: a coherent environment, and a clear message from a Python
that lacks the project's dependencies."""

import subprocess
import sys
import tomllib
from importlib.metadata import requires, version
from pathlib import Path

import pytest
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[1]


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def _pins(requirements: list[str]) -> dict[str, Requirement]:
    return {Requirement(r).name: Requirement(r) for r in requirements}


def test_the_base_install_and_the_dev_install_resolve_the_same_orbax():
    """flax leaves orbax-checkpoint unbounded while jax2onnx (export, in dev) caps it: without a
    pin in the base dependencies, `pip install -e .[dev]` downgrades what `pip install -e .` put in."""
    base = _pins(_pyproject()["project"]["dependencies"])
    assert "orbax-checkpoint" in base, "orbax-checkpoint is not pinned in [project] dependencies"
    pinned = next(iter(base["orbax-checkpoint"].specifier)).version
    capped = [Requirement(r) for r in requires("jax2onnx") if Requirement(r).name == "orbax-checkpoint"]
    assert all(pinned in r.specifier for r in capped), (pinned, capped)
    assert version("orbax-checkpoint") == pinned


def test_every_installed_requirement_is_satisfied():
    check = subprocess.run([sys.executable, "-m", "pip", "check"], capture_output=True, text=True)
    if "No module named pip" in check.stderr:
        pytest.skip("this environment has no pip")
    assert check.returncode == 0, check.stdout + check.stderr


def test_a_python_without_jax_is_told_how_to_run_the_project():
    """sys.modules[name] = None makes find_spec see the package as absent, as a bare python does."""
    code = "import sys; sys.modules['jax'] = None; import dsfec_jax"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert run.returncode != 0
    last = run.stderr.strip().splitlines()[-1]
    assert last.startswith("ImportError: dsfec_jax needs jax,"), last
    assert sys.executable in last and ".venv/bin/activate" in last
