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
