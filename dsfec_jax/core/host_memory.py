"""How the project's commands set up the host memory XLA's CPU client runs in: they restart
once with glibc tunables (and JAX's CPU dispatch mode) that suit a training step's buffers.

Why: XLA's CPU client allocates each call's temporary buffer afresh (over a gigabyte for a
DSFEC-L training step at batch 8 on 96-cell windows) and frees it after. With glibc's defaults that is
an mmap and a munmap a call, so every step first-touches fresh pages (the kernel zeroes each in a
page fault, inside whatever op writes it first), and the unmap holds the address-space lock the
next call's mmap waits on. Two settings answer it:
- `glibc.malloc.hugetlb=1`: glibc advises the kernel (madvise MADV_HUGEPAGE) to back such
  mappings with 2 MiB pages, 512x fewer faults and cheaper unmaps.
- Keeping the buffer in the process: `glibc.malloc.mmap_max=0` (large blocks come from the heap,
  not from mmap) with a trim threshold no heap reaches (freed memory stays), and JAX's
  `jax_cpu_enable_async_dispatch` off, so that XLA runs each call inline on the calling thread.
  Both are needed: an asynchronous call runs on a pool thread, whose glibc arena cannot hold a
  block that large and maps it afresh anyway. The step's inputs must also be ready when it is
  called (train.step.batch_on_device), or XLA defers the call to a pool thread. Then the main
  thread's heap hands the same pages back every call. The cost: the process keeps its peak heap
  until it exits, as a caching allocator would.
The gains and the cost, measured on `dsfec train` and `dsfec bench --train`, are in
docs/profiler.md ("huge pages", "XLA's temporary buffer kept between steps"); re-measure by
alternating a command with and without DSFEC_HUGEPAGES=0.

glibc reads its tunables only at start-up, so the settings can only come from the environment
the process starts with. `relaunch_with_host_settings` execs the same command line again with
GLIBC_TUNABLES extended. The commands that run XLA call `prepare_xla_process` when they start
(each such module in an `if __name__ == "__main__"` guard above its imports, so the first
process execs before it loads JAX; `dsfec` after parsing its arguments, for every subcommand
but `serve`), which relaunches where the process was started as that command
(`dsfec ...`, `python -m dsfec_jax... | search... | experiments...`) and then turns async
dispatch off where the heap keeps buffers. Nothing happens at import: the map service (a
long-lived server that must give memory back and start fast), `dsfec --help`, library users and
the test runner are never re-executed and keep the defaults. A tunable the user
already gave stands (and where it is one of KEEP_BUFFERS, dispatch stays asynchronous).
DSFEC_HUGEPAGES=0 leaves all of it at the defaults. Glibc >= 2.35 on Linux; huge pages only
with THP not set to 'never'. jax is imported only to set its dispatch, before XLA starts.

A library user's process (their own script, a notebook) is never re-executed. `tune_in_process`
is its one-call opt-in, to call before anything runs JAX: glibc's `mallopt` sets the two
KEEP_BUFFERS limits at run time (M_MMAP_MAX, M_TRIM_THRESHOLD; glibc has no run-time switch for
huge pages, so only they are left to the relaunch) and async dispatch goes off as in a command.
Called after XLA's CPU client has started, only the mallopt part can still apply; it says so.
"""

from __future__ import annotations

import os
import platform
import sys
import warnings
from pathlib import Path

TUNABLE = "glibc.malloc.hugetlb"
SETTING = f"{TUNABLE}=1"
KEEP_BUFFERS = {"glibc.malloc.mmap_max": "0", "glibc.malloc.trim_threshold": str(1 << 40)}  # 1 TiB: never trimmed
ASYNC_DISPATCH = "jax_cpu_enable_async_dispatch"  # jax's config option (it reads no env variable for it)
OPT_OUT = "DSFEC_HUGEPAGES"  # "0": leave glibc's and JAX's defaults
MIN_GLIBC = (2, 35)  # the first glibc with glibc.malloc.hugetlb
THP_MODE = Path("/sys/kernel/mm/transparent_hugepage/enabled")
COMMAND_PACKAGES = ("dsfec_jax", "search", "experiments")  # python -m <these>: the project's commands
CONSOLE_SCRIPTS = ("dsfec",)


def glibc_version() -> tuple[int, int] | None:
    """(major, minor) of the C library this Python runs on, None where it is not glibc."""
    name, version = platform.libc_ver()
    if name != "glibc":
        return None
    try:
        major, minor = version.split(".")[:2]
        return int(major), int(minor)
    except ValueError:
        return None


def thp_mode(path: Path = THP_MODE) -> str | None:
    """The kernel's THP mode, the bracketed word of 'always [madvise] never'; None if unreadable."""
    try:
        text = path.read_text()
    except OSError:
        return None
    start, end = text.find("["), text.find("]")
    return text[start + 1:end] if 0 <= start < end else None


def _tunables(value: str) -> dict[str, str]:
    """GLIBC_TUNABLES 'name=value:name=value' -> {name: value}."""
    return dict(item.partition("=")[::2] for item in value.split(":") if item)


def relaunch_tunables(env: dict[str, str], glibc: tuple[int, int] | None, thp: str | None) -> str | None:
    """The GLIBC_TUNABLES value to restart with, or None where nothing should change: opted out,
    not glibc >= 2.35 on Linux, or every setting already there (given by the user, whatever its
    value, or by a first relaunch). Huge pages only where THP is on ('always' or 'madvise')."""
    if env.get(OPT_OUT, "1") == "0" or glibc is None or glibc < MIN_GLIBC:
        return None
    wanted = {**({TUNABLE: "1"} if thp in ("always", "madvise") else {}), **KEEP_BUFFERS}
    current = env.get("GLIBC_TUNABLES", "")
    added = [f"{name}={value}" for name, value in wanted.items() if name not in _tunables(current)]
    if not added:
        return None
    return ":".join([current, *added] if current else added)


def is_project_command(orig_argv: list[str]) -> bool:
    """Whether the interpreter was started as one of the project's commands: `python -m <module
    of dsfec_jax, search or experiments>` or a console script named in CONSOLE_SCRIPTS. Reads the
    interpreter's own options up to the module or script, as Python does."""
    args = iter(orig_argv[1:])
    for arg in args:
        if arg == "-m":
            return next(args, "").split(".")[0] in COMMAND_PACKAGES
        if arg == "-c" or arg == "-":
            return False
        if arg in ("-X", "-W"):
            next(args, None)  # the option's value
        elif not arg.startswith("-"):
            return Path(arg).name in CONSOLE_SCRIPTS
    return False


def relaunch_with_host_settings() -> None:
    """Exec this interpreter again with the same arguments and GLIBC_TUNABLES extended
    (`relaunch_tunables`); return without doing anything where that does not apply."""
    if platform.system() != "Linux":
        return
    value = relaunch_tunables(dict(os.environ), glibc_version(), thp_mode())
    if value is None:
        return
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(sys.executable, [sys.executable, *sys.orig_argv[1:]], {**os.environ, "GLIBC_TUNABLES": value})


def prepare_xla_process() -> None:
    """First thing in a command that runs XLA: where the process was started as one of the
    project's commands (`is_project_command`), `relaunch_with_host_settings`, then (in the
    process that goes on) async dispatch off where the heap keeps buffers. Elsewhere (a library
    user or the test runner calling the command's main) it does nothing."""
    if is_project_command(sys.orig_argv):
        relaunch_with_host_settings()
        if heap_keeps_buffers():
            try:
                dispatch_inline()
            except RuntimeError as err:  # slower, not wrong: the command goes on
                warnings.warn(f"{err}; XLA's calls stay asynchronous")


def dispatch_inline() -> None:
    """Turn JAX's async dispatch off for the CPU. XLA reads the option when it makes its CPU
    client, and JAX has no public way to ask whether it has: so this runs first thing in a
    command (prepare_xla_process), before anything can run XLA; a test holds every entry point
    to that (tests/core/test_host_memory.py)."""
    import jax

    jax.config.update(ASYNC_DISPATCH, False)


M_TRIM_THRESHOLD, M_MMAP_MAX = -1, -4  # glibc's malloc.h parameter numbers
MALLOPT_TRIM_THRESHOLD = 2**31 - 1  # mallopt takes a C int: the largest it holds
_kept_by_mallopt = False  # set once mallopt_keep_buffers succeeded (what the benchmarks record)


def mallopt_keep_buffers() -> bool:
    """KEEP_BUFFERS through glibc's mallopt in this running process: large blocks from the heap,
    never trimmed. False where this is not glibc on Linux (nothing changed)."""
    if platform.system() != "Linux" or glibc_version() is None:
        return False
    import ctypes

    global _kept_by_mallopt
    libc = ctypes.CDLL(None)  # the C library this interpreter already runs on
    # mallopt returns 1 on success; both are plain integer settings every glibc accepts.
    _kept_by_mallopt = bool(libc.mallopt(M_MMAP_MAX, 0)) and bool(libc.mallopt(M_TRIM_THRESHOLD, MALLOPT_TRIM_THRESHOLD))
    return _kept_by_mallopt


def tune_in_process() -> dict:
    """The commands' host settings for a process that was not started as one (a library user's
    script): `mallopt_keep_buffers`, then async dispatch off where XLA's CPU client has not started
    yet (its pool threads do not exist). -> what applied: {'keep_buffers': bool, 'inline_dispatch':
    bool}. DSFEC_HUGEPAGES=0 leaves everything at the defaults, as for the commands."""
    from . import threads

    if os.environ.get(OPT_OUT, "1") == "0":
        return {"keep_buffers": False, "inline_dispatch": False}
    kept = mallopt_keep_buffers()
    inline = False
    if kept and not threads.eigen_threads():
        dispatch_inline()
        inline = True
    elif kept:
        warnings.warn("dsfec_jax tune_in_process: XLA's CPU client has already started, so its calls stay "
                      "asynchronous; call it before anything runs JAX to get the commands' speed")
    return {"keep_buffers": kept, "inline_dispatch": inline}


def active() -> bool:
    """Whether this process started with glibc's huge-page tunable on (recorded with benchmarks)."""
    return _tunables(os.environ.get("GLIBC_TUNABLES", "")).get(TUNABLE) == "1"


def heap_keeps_buffers() -> bool:
    """Whether this process keeps large blocks on its heap: started with glibc's KEEP_BUFFERS
    tunables, or set them at run time (`mallopt_keep_buffers`)."""
    if _kept_by_mallopt:
        return True
    tunables = _tunables(os.environ.get("GLIBC_TUNABLES", ""))
    return all(tunables.get(k) == v for k, v in KEEP_BUFFERS.items())


def keeps_buffers() -> bool:
    """Whether this process keeps XLA's temporary buffers between calls: the heap's tunables and
    async dispatch off (recorded with benchmarks)."""
    import jax

    return heap_keeps_buffers() and not jax.config.read(ASYNC_DISPATCH)


if __name__ == "__main__":
    # `python -m dsfec_jax.core.host_memory --probe ...`: a command that runs XLA; prints what
    # the (relaunched) process started with and exits 3, for tests/core/test_host_memory.py
    prepare_xla_process()
    print(os.environ.get("GLIBC_TUNABLES", ""))
    print(sys.argv[1:])
    import jax

    print(jax.config.read(ASYNC_DISPATCH))
    sys.exit(3)
