"""Paths read from data files (dataset tables, cache manifests) must stay inside their root.

A table is data, not code: a `filename` of "/etc/passwd" or "../../secret" would make a reader
open files the dataset does not own. Checked lexically, never by resolving links, so a dataroot
whose samples/ or sweeps/ folders are symlinks to another disk (common for nuScenes) still works.
"""

from __future__ import annotations

from pathlib import Path, PurePosixPath, PureWindowsPath


def path_problem(value) -> str | None:
    """Why `value` is not a non-empty relative path without '..' (either separator), or None."""
    if not isinstance(value, str) or not value.strip() or "\0" in value:
        return "must be a non-empty relative path"
    win = PureWindowsPath(value)  # splits on both '/' and '\\', and sees drive letters
    if PurePosixPath(value).is_absolute() or win.is_absolute() or win.drive or win.root:
        return "is absolute; paths in data files must be relative to their root"
    if ".." in win.parts:
        return "climbs out of its root with '..'"
    return None


def inside(root, value, source, field: str) -> Path:
    """root / value for a relative `value` read from file `source`; ValueError naming both otherwise."""
    problem = path_problem(value)
    if problem is not None:
        raise ValueError(f"{source}: field {field!r} = {value!r:.120} {problem}")
    return Path(root) / value
