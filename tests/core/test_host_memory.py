"""The project's commands restart once with glibc's huge-page tunable (core/host_memory.py);
library users and the test runner are never re-executed."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from dsfec_jax.core import host_memory as hm

GLIBC = (2, 36)


@pytest.mark.parametrize("env,glibc,thp,expected", [
    ({}, GLIBC, "madvise", hm.SETTING),
    ({}, GLIBC, "always", hm.SETTING),
    ({"GLIBC_TUNABLES": "glibc.malloc.arena_max=2"}, GLIBC, "madvise", "glibc.malloc.arena_max=2:" + hm.SETTING),
    ({"GLIBC_TUNABLES": "glibc.malloc.hugetlb=0"}, GLIBC, "madvise", None),  # the user's own choice stands
    ({"GLIBC_TUNABLES": hm.SETTING}, GLIBC, "madvise", None),  # already relaunched: no loop
    ({hm.OPT_OUT: "0"}, GLIBC, "madvise", None),
    ({}, GLIBC, "never", None),
    ({}, GLIBC, None, None),
    ({}, (2, 34), "madvise", None),  # before the tunable existed
    ({}, None, "madvise", None),  # musl, or not Linux
])
def test_tunables_value(env, glibc, thp, expected):
    assert hm.tunables_with_hugepages(env, glibc, thp) == expected


@pytest.mark.parametrize("argv,expected", [
    (["python", "-m", "search.blocks", "--stage", "2"], True),
    (["python", "-X", "dev", "-m", "dsfec_jax", "train"], True),
    (["python", "-u", "-m", "experiments.table1"], True),
    (["/venv/bin/python", "/venv/bin/dsfec", "bench", "--train"], True),
    (["python", "-m", "pytest", "-m", "search"], False),  # the test runner, even with a marker named like a package
    (["python", "-c", "import dsfec_jax", "-m", "search"], False),
    (["python", "my_script.py", "-m", "search"], False),
    (["python"], False),
])
def test_which_processes_are_project_commands(argv, expected):
    assert hm.is_project_command(argv) is expected


def test_thp_mode_reads_the_bracketed_word(tmp_path):
    (tmp_path / "enabled").write_text("always [madvise] never\n")
    assert hm.thp_mode(tmp_path / "enabled") == "madvise"
    assert hm.thp_mode(tmp_path / "missing") is None


def test_a_project_command_restarts_with_the_tunable_and_its_arguments():
    """`python -m dsfec_jax.core.host_memory --probe 'a b' c` runs (after one exec, where glibc >=
    2.35 with THP allows it; else as started) with hugetlb=1 in GLIBC_TUNABLES, the same
    arguments, and its exit code; DSFEC_HUGEPAGES=0 keeps the defaults."""
    expected = hm.tunables_with_hugepages({}, hm.glibc_version(), hm.thp_mode()) or ""
    env = {k: v for k, v in os.environ.items() if k not in ("GLIBC_TUNABLES", hm.OPT_OUT)}
    root = Path(__file__).resolve().parents[2]
    command = [sys.executable, "-m", "dsfec_jax.core.host_memory", "--probe", "a b", "c"]
    out = subprocess.run(command, env=env, cwd=root, capture_output=True, text=True, timeout=120)
    assert out.returncode == 3, out.stderr
    assert out.stdout.split("\n")[:2] == [expected, "['--probe', 'a b', 'c']"]
    off = subprocess.run(command, env={**env, hm.OPT_OUT: "0"}, cwd=root, capture_output=True, text=True, timeout=120)
    assert off.returncode == 3 and off.stdout.split("\n")[0] == ""
