"""A user's own files as a model's input: `dsfec predict --input PATH...` and `api.read_files`.

Every modality reads its own kind of file (modalities/<name>/files.py, `Modality.files`); what they
share lives here: PATH arguments (files, folders, globs, expanded here too so a quoted glob works)
become a sorted, de-duplicated list of at most MAX_INPUT_FILES files with the modality's suffixes,
every file is read and checked before anything is written (a bad one stops the command with its
name and nothing half-written), and the detections go out as one JSON document, one entry per file.
"""

from __future__ import annotations

import dataclasses
import glob
import itertools
import sys
from pathlib import Path
from typing import Any, Callable, Sequence

from tqdm import tqdm

from ..core import atomic
from ..core.progress import quiet

# A command reads every file before it predicts (so a bad one stops it before anything is written):
# the bound keeps that pass, and a mistyped glob such as `/**`, from walking a whole disk.
MAX_INPUT_FILES = 2000
GLOB_CHARACTERS = set("*?[")


class InputFileError(ValueError):
    """A PATH that names no usable file, or a file that is not a valid input; the message names it."""


@dataclasses.dataclass(frozen=True)
class FileReader:
    """How a modality reads a user's file. `suffixes` (lower case, with the dot) are the files it
    takes; `read(path, cfg, columns)` -> one input item (a Frame, an RDSample, a CameraImage) whose id
    is the path, or InputFileError naming the file; `columns` is the `--columns` layout of point
    files (None: the model's); `entry(item, detections)` -> the file's JSON entry (boxes in the
    modality's units); `ident(item)` -> its id (the path); `kinds` says in words what files it takes;
    `lazy`: the checked items are read again on access rather than held."""

    suffixes: tuple[str, ...]
    read: Callable[[Path, Any, str | None], Any]
    entry: Callable[[Any, Any], dict]
    ident: Callable[[Any], str]
    kinds: str
    lazy: bool = False  # items decoded again on access (photos: 2000 held at once could fill memory)


def expand(patterns: Sequence[str], suffixes: Sequence[str], limit: int | None = None) -> list[Path]:
    """PATH arguments -> sorted unique files. A file must have one of `suffixes` (any case); a folder
    gives its files with those suffixes (not its subfolders); a glob gives its matches with those
    suffixes. InputFileError when a PATH gives nothing, a named file has another suffix, or there are
    more than `limit` (default MAX_INPUT_FILES) files."""
    limit = MAX_INPUT_FILES if limit is None else limit
    found: set[Path] = set()
    for pattern in patterns:
        for path in _paths_of(pattern, tuple(s.lower() for s in suffixes), limit):
            found.add(path.resolve())
            if len(found) > limit:
                raise InputFileError(f"--input: more than {limit} files (at {path}); pass fewer files or a "
                                     "narrower folder or glob")
    return sorted(found)


def _paths_of(pattern: str, suffixes: tuple[str, ...], limit: int) -> list[Path]:
    path = Path(pattern)
    accepted = " / ".join(suffixes)
    if path.is_file():
        if path.suffix.lower() not in suffixes:
            raise InputFileError(f"{path}: extension {path.suffix or '(none)'!r}; expected {accepted}")
        return [path]
    if path.is_dir():
        matches = (p for p in sorted(path.iterdir()) if p.is_file() and p.suffix.lower() in suffixes)
        where = f"folder {path}"
    elif GLOB_CHARACTERS & set(pattern):
        matches = (Path(p) for p in glob.iglob(pattern, recursive=True)
                   if Path(p).is_file() and Path(p).suffix.lower() in suffixes)
        where = f"glob {pattern!r}"
    else:
        raise InputFileError(f"{path}: no such file or folder")
    chosen = list(itertools.islice(matches, limit + 1))  # a huge folder is not listed past the bound
    if not chosen:
        raise InputFileError(f"--input {where}: no {accepted} file")
    return chosen


def read_all(reader: FileReader, paths: Sequence[Path], cfg, columns: str | None = None) -> Sequence:
    """Every file read and checked, in order (InputFileError names the first bad one); each item's
    id is its path (str), the key its detections come back under."""
    checking = tqdm(paths, desc="reading --input", unit="file", disable=quiet())
    if not reader.lazy:
        return [reader.read(Path(p), cfg, columns) for p in checking]
    for p in checking:
        reader.read(Path(p), cfg, columns)  # checked now, so a bad file stops the command before any write
    return LazyItems(reader, [Path(p) for p in paths], cfg, columns)


class LazyItems:
    """Checked files read again on access: a sequence of items that holds one at a time."""

    def __init__(self, reader: FileReader, paths: list[Path], cfg, columns: str | None):
        self.reader, self.paths, self.cfg, self.columns = reader, paths, cfg, columns

    def __len__(self) -> int:
        return len(self.paths)

    def __getitem__(self, index: int):
        return self.reader.read(self.paths[index], self.cfg, self.columns)

    def __iter__(self):
        return (self[i] for i in range(len(self)))


def read_files(reader: FileReader, patterns: Sequence[str], cfg, columns: str | None = None,
               limit: int | None = None) -> Sequence:
    """`expand` then `read_all`."""
    return read_all(reader, expand(patterns, reader.suffixes, limit), cfg, columns)


def detections_document(model: str, reader: FileReader, items: Sequence, detections: dict, **fields) -> dict:
    """What `--out` holds for --input: the model, then one entry per file in input order."""
    entries = [{"file": reader.ident(item), **reader.entry(item, detections[reader.ident(item)])} for item in items]
    return {"model": model, **fields, "inputs": entries}


def fail(path, what: str) -> InputFileError:
    return InputFileError(f"{path}: {what}")


def refuse_with_input(args) -> None:
    """Exit when --input is combined with a flag that reads a data source (or --columns without it)."""
    given = set(a.split("=")[0] for a in getattr(args, "argv", []))
    if not getattr(args, "input", None):
        if getattr(args, "columns", None):
            sys.exit("dsfec predict: --columns says the layout of --input .bin files; give --input")
        return
    if Path(args.out).is_dir():
        sys.exit(f"dsfec predict: --out {args.out} is a folder; give the JSON file to write")
    clashing = sorted(given & {"--data", "--split", "--frames", "--gt-out"})
    if clashing:
        sys.exit(f"dsfec predict: {', '.join(clashing)} read a data source; --input files are read as they are "
                 "(and have no ground truth): drop one or the other")


def items_or_exit(args, reader: FileReader, cfg) -> Sequence:
    """The --input files read by `reader`, or exit with the message naming the bad one."""
    try:
        return read_files(reader, args.input, cfg, args.columns)
    except InputFileError as err:
        sys.exit(f"dsfec predict: {err}")


def write_document(args, reader: FileReader, items: Sequence, detections: dict, **fields) -> None:
    atomic.write_json(args.out, detections_document(args.model, reader, items, detections, **fields))
