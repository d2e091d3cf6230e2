"""The commands that run XLA restart once with glibc tunables and async dispatch off
(core/host_memory.py); the map service, `dsfec --help`, library users and the test runner are never
re-executed, and nothing happens at import."""

import ast
import os
import socket
import subprocess
import sys
import time
import urllib.request
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


ROOT = Path(__file__).resolve().parents[2]
# the entry points (`if __name__ == "__main__"`) that run no XLA and so keep glibc's and JAX's defaults
LIGHT_ENTRY_POINTS = {
    "dsfec_jax/service/__main__.py",  # the map service
    "dsfec_jax/edge/loadtest.py",  # HTTP clients against a service it starts
    "experiments/edge_uplink.py",  # the uplink's queue timings against a service it starts
    "dsfec_jax/data/__main__.py", "dsfec_jax/data/camera/street/__main__.py",  # numpy data tools
    "dsfec_jax/data/points/synthetic/__main__.py", "dsfec_jax/data/rd/synthetic/__main__.py",
    "dsfec_jax/metrics/nuscenes.py", "dsfec_jax/metrics/voc.py",  # numpy scorers of files
    "search/report.py", "search/compare.py", "experiments/radarnext_accuracy.py",  # read records, write reports
    # the peer comparison's lead and workers: each JAX worker gets its side's settings itself (the
    # "library" side must run without them), and the torch worker imports no JAX
    "experiments/peer_speed.py", "experiments/peer_torch.py", "experiments/peer_twins.py",
}

PREPARED_ELSEWHERE = {
    "dsfec_jax/cli.py",  # dsfec: main() prepares every subcommand but `serve`, after parsing (the next test)
    "dsfec_jax/core/host_memory.py",  # the probe: its own stdlib-only module, prepared in its __main__ block
}


def _main_guards(tree: ast.Module) -> list[int]:
    """Indices in the module's body of its `if __name__ == "__main__"` blocks."""
    return [i for i, node in enumerate(tree.body) if isinstance(node, ast.If) and "__main__" in ast.unparse(node.test)]


def _first_statement(tree: ast.Module) -> int:
    """Index of the module's first statement after its docstring and `from __future__` imports."""
    i = int(isinstance(tree.body[0], ast.Expr) and isinstance(tree.body[0].value, ast.Constant))
    while isinstance(tree.body[i], ast.ImportFrom) and tree.body[i].module == "__future__":
        i += 1
    return i


def test_every_entry_point_that_runs_xla_prepares_its_process_before_its_imports():
    """The relaunch is no longer at the package's import: each entry point that runs XLA calls
    prepare_xla_process in a `__main__` guard above all its other statements (so the first
    process execs before it loads JAX), and every other entry point is listed as light."""
    heavy, light = {}, set()
    for path in sorted(p for d in ("dsfec_jax", "search", "experiments") for p in (ROOT / d).rglob("*.py")):
        tree = ast.parse(path.read_text())
        guards = _main_guards(tree)
        if not guards:
            continue
        name = path.relative_to(ROOT).as_posix()
        if name in PREPARED_ELSEWHERE:
            continue
        if name in LIGHT_ENTRY_POINTS:
            light.add(name)
            assert "prepare_xla_process" not in ast.unparse(tree), name
        else:
            heavy[name] = guards[0] == _first_statement(tree) and ast.unparse(tree.body[guards[0]]).endswith(
                "prepare_xla_process()")
    assert light == LIGHT_ENTRY_POINTS  # the list names no module that is gone
    assert len(heavy) >= 20 and all(heavy.values()), [name for name, ok in heavy.items() if not ok]


class _Prepared(Exception):
    pass


def test_dsfec_prepares_every_subcommand_but_serve_and_only_after_parsing(monkeypatch, tmp_path, capsys):
    from dsfec_jax import cli, cli_edge

    def prepared():
        raise _Prepared

    monkeypatch.setattr(hm, "prepare_xla_process", prepared)
    monkeypatch.setattr(cli_edge, "main", lambda args: 0)  # `serve` would serve forever
    for argv in (["eval", "--model", "dsfec_s"], ["train", "--model", "dsfec_s", "--run-dir", str(tmp_path)],
                 ["edge", "--out", str(tmp_path)], ["bench"], ["depth", "eval"]):
        with pytest.raises(_Prepared):
            cli.main(argv)
    assert cli.main(["serve", "--db", str(tmp_path / "map.db")]) == 0
    for argv in (["--help"], ["train", "--help"], ["train", "--no-such-flag"]):
        with pytest.raises(SystemExit):
            cli.main(argv)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_service(command: list[str], tmp_path: Path, name: str) -> tuple[subprocess.Popen, int, Path]:
    port = _free_port()
    env = {k: v for k, v in os.environ.items() if k not in ("GLIBC_TUNABLES", hm.OPT_OUT)}
    env["PYTHONPROFILEIMPORTTIME"] = "1"  # the process reports every module it imports on stderr
    log = tmp_path / f"{name}.imports"
    with open(log, "w") as err:
        proc = subprocess.Popen([*command, "--db", str(tmp_path / f"{name}.db"), "--port", str(port)], env=env,
                                cwd=ROOT, stdout=subprocess.DEVNULL, stderr=err)
    return proc, port, log


def _wait_until_serving(proc: subprocess.Popen, port: int) -> None:
    deadline = time.monotonic() + 60
    while True:
        assert proc.poll() is None, f"the service exited with {proc.returncode}"
        try:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/health", timeout=2).read()
            return
        except OSError:
            assert time.monotonic() < deadline, "the service did not answer /health within 60 s"
            time.sleep(0.05)


def test_the_map_service_process_starts_light(tmp_path):
    """`python -m dsfec_jax.service` and `dsfec serve`, started as a user would, serving: their
    process was not restarted with glibc's tunables (its environment), imported no JAX (its own
    import log) and has no XLA library mapped (/proc/PID/maps)."""
    dsfec = Path(sys.executable).with_name("dsfec")
    if not dsfec.exists():
        pytest.skip(f"no dsfec console script beside {sys.executable}")
    commands = {"module": [sys.executable, "-m", "dsfec_jax.service"], "cli": [str(dsfec), "serve"]}
    started = {name: _start_service(command, tmp_path, name) for name, command in commands.items()}
    try:
        for name, (proc, port, log) in started.items():
            _wait_until_serving(proc, port)
            environ = Path(f"/proc/{proc.pid}/environ").read_bytes().split(b"\0")
            assert not any(item.startswith(b"GLIBC_TUNABLES=") for item in environ), name
            imported = {line.rsplit("|", 1)[-1].strip() for line in log.read_text().splitlines() if "|" in line}
            assert "dsfec_jax.service.server" in imported and "uvicorn" in imported, name  # the log is the server's
            assert not {"jax", "jaxlib", "flax"} & imported, (name, sorted({"jax", "jaxlib", "flax"} & imported))
            maps = Path(f"/proc/{proc.pid}/maps").read_text()
            assert "jaxlib" not in maps and "xla_extension" not in maps, name
    finally:
        for proc, _, _ in started.values():
            proc.terminate()
            proc.wait(30)


MALLINFO_PROBE = """
import ctypes, json, os, sys
class Mallinfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]
libc = ctypes.CDLL(None)
libc.mallinfo2.restype = Mallinfo2
libc.malloc.restype = ctypes.c_void_p
from dsfec_jax import api
if sys.argv[1] == "after_jax":
    import jax.numpy as jnp
    (jnp.ones(4) + 1).block_until_ready()
applied = api.tune_host() if sys.argv[1] != "untuned" else {}
before = libc.mallinfo2().hblkhd
block = libc.malloc(256 << 20)  # an XLA-sized temporary: glibc's default serves it with mmap
mapped = libc.mallinfo2().hblkhd - before
libc.free(ctypes.c_void_p(block))
import jax
print(json.dumps({"applied": applied, "mmapped_bytes": mapped, "async": jax.config.read("jax_cpu_enable_async_dispatch"),
                  "heap_keeps": __import__("dsfec_jax.core.host_memory", fromlist=["x"]).heap_keeps_buffers()}))
"""


def _tune_probes(*modes: str) -> list[dict]:
    """Run the probe once per mode, all at once (each is a fresh interpreter importing JAX)."""
    import json

    env = {k: v for k, v in os.environ.items() if k not in ("GLIBC_TUNABLES", hm.OPT_OUT)}
    procs = [subprocess.Popen([sys.executable, "-c", MALLINFO_PROBE, mode], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, cwd=ROOT) for mode in modes]
    results = []
    for proc in procs:
        out, err = proc.communicate(timeout=180)
        assert proc.returncode == 0, err[-2000:]
        results.append(json.loads(out.strip().splitlines()[-1]))
    return results


@pytest.mark.skipif(hm.glibc_version() is None, reason="mallopt is glibc's")
def test_a_library_process_gets_the_commands_host_settings_in_one_call():
    """api.tune_host keeps large blocks on the heap (no mmap) and turns async dispatch off, without a
    restart; after JAX has started, only the heap part can apply."""
    untuned, tuned, late = _tune_probes("untuned", "first", "after_jax")
    assert untuned["mmapped_bytes"] >= 256 << 20 and untuned["async"] and not untuned["heap_keeps"]
    assert tuned["applied"] == {"keep_buffers": True, "inline_dispatch": True}
    assert tuned["mmapped_bytes"] == 0 and tuned["async"] is False and tuned["heap_keeps"]
    assert late["applied"] == {"keep_buffers": True, "inline_dispatch": False}
    assert late["mmapped_bytes"] == 0 and late["async"] is True
