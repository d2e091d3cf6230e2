"""The project's commands restart once with glibc tunables and async dispatch off (core/host_memory.py);
library users and the test runner are never re-executed."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from dsfec_jax.core import host_memory as hm

GLIBC = (2, 36)


KEEP = ":".join(f"{k}={v}" for k, v in hm.KEEP_BUFFERS.items())
ALL = f"{hm.SETTING}:{KEEP}"
TRIM = f"glibc.malloc.trim_threshold={hm.KEEP_BUFFERS['glibc.malloc.trim_threshold']}"


@pytest.mark.parametrize("env,glibc,thp,expected", [
    ({}, GLIBC, "madvise", ALL),
    ({}, GLIBC, "always", ALL),
    ({"GLIBC_TUNABLES": "glibc.malloc.arena_max=2"}, GLIBC, "madvise", "glibc.malloc.arena_max=2:" + ALL),
    # the user's own choices stand; only what they left out is added
    ({"GLIBC_TUNABLES": "glibc.malloc.hugetlb=0"}, GLIBC, "madvise", "glibc.malloc.hugetlb=0:" + KEEP),
    ({"GLIBC_TUNABLES": "glibc.malloc.mmap_max=4"}, GLIBC, "madvise", f"glibc.malloc.mmap_max=4:{hm.SETTING}:{TRIM}"),
    ({"GLIBC_TUNABLES": ALL}, GLIBC, "madvise", None),  # already relaunched: no loop
    ({"GLIBC_TUNABLES": KEEP}, GLIBC, "never", None),  # already relaunched without THP
    ({hm.OPT_OUT: "0"}, GLIBC, "madvise", None),
    ({}, GLIBC, "never", KEEP),  # no huge pages, buffers still kept
    ({}, GLIBC, None, KEEP),
    ({}, (2, 34), "madvise", None),  # before the huge-page tunable existed
    ({}, None, "madvise", None),  # musl, or not Linux
])
def test_tunables_value(env, glibc, thp, expected):
    assert hm.relaunch_tunables(env, glibc, thp) == expected


@pytest.mark.parametrize("tunables,expected", [
    (ALL, True), (KEEP, True), (hm.SETTING, False), ("glibc.malloc.mmap_max=0", False),
    ("glibc.malloc.mmap_max=4:glibc.malloc.trim_threshold=1099511627776", False),
])
def test_heap_keeps_buffers_needs_both_tunables(monkeypatch, tunables, expected):
    monkeypatch.setenv("GLIBC_TUNABLES", tunables)
    assert hm.heap_keeps_buffers() is expected


def test_dispatch_cannot_be_changed_once_xla_has_started():
    import jax.numpy as jnp

    jnp.zeros(1).block_until_ready()  # the test process's CPU client exists now
    with pytest.raises(RuntimeError, match="before XLA's CPU client"):
        hm.dispatch_inline()


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


def test_a_project_command_restarts_with_the_settings_and_its_arguments():
    """`python -m dsfec_jax.core.host_memory --probe 'a b' c` runs (after one exec, where glibc >=
    2.35 allows it; else as started) with the tunables in GLIBC_TUNABLES, async dispatch off where
    the heap keeps buffers, the same arguments, and its exit code. A user's own mmap_max keeps
    dispatch asynchronous; DSFEC_HUGEPAGES=0 keeps every default."""
    expected = hm.relaunch_tunables({}, hm.glibc_version(), hm.thp_mode())
    env = {k: v for k, v in os.environ.items() if k not in ("GLIBC_TUNABLES", hm.OPT_OUT)}
    root = Path(__file__).resolve().parents[2]
    command = [sys.executable, "-m", "dsfec_jax.core.host_memory", "--probe", "a b", "c"]
    run = lambda extra: subprocess.run(command, env={**env, **extra}, cwd=root, capture_output=True, text=True,
                                       timeout=120)
    out = run({})
    assert out.returncode == 3, out.stderr
    assert out.stdout.split("\n")[:3] == [expected or "", "['--probe', 'a b', 'c']", "False" if expected else "True"]
    mine = run({"GLIBC_TUNABLES": "glibc.malloc.mmap_max=4"})
    assert mine.returncode == 3 and mine.stdout.split("\n")[2] == "True", mine.stderr
    off = run({hm.OPT_OUT: "0"})
    assert off.returncode == 3 and off.stdout.split("\n")[0] == "" and off.stdout.split("\n")[2] == "True"
