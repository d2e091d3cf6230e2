"""argparse helpers used by every command line in the package: types for counts (`--frames 0` is
refused with the flag's name instead of quietly meaning a default, or producing a score of
nothing) and the command line as typed, for manifests."""

from __future__ import annotations

import argparse
import shlex


def command_line(args) -> str:
    """The command as the user typed it (or as a caller passed it to main), for manifests."""
    return "dsfec " + " ".join(shlex.quote(a) for a in args.argv)


def positive_int(text: str) -> int:
    """A count that must be at least 1 (frames, steps, batch size, ...)."""
    value = _int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def non_negative_int(text: str) -> int:
    """A count where 0 has a documented meaning (e.g. `--window 0` = the whole grid)."""
    value = _int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {value}")
    return value


def positive_int_list(text: str) -> list[int]:
    """'12,24' -> [12, 24]: a comma-separated list of counts, each at least 1."""
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        values = []
    if not values or min(values) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected comma-separated integers >= 1, e.g. 24,48")
    return values


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def add_parallel_flags(p: argparse.ArgumentParser) -> None:
    """Data-parallel training (dsfec_jax.train.parallel): devices of this process, and the processes of a
    run on several hosts."""
    p.add_argument("--devices", type=positive_int, default=None,
                   help="local devices to train on, the global batch split across them (default: all of this "
                        "process's devices; on the CPU, N > 1 makes N host devices)")
    p.add_argument("--coordinator", default=None, metavar="HOST:PORT",
                   help="train on several processes/hosts (jax.distributed): process 0's address, or 'auto' for "
                        "a cluster launcher JAX detects (SLURM, Open MPI); only process 0 writes the run directory")
    p.add_argument("--num-processes", type=positive_int, default=None, help="with --coordinator: processes in the run")
    p.add_argument("--process-id", type=non_negative_int, default=None, help="with --coordinator: this process, 0 .. N-1")
