"""The edge device's disk spool: frame batches waiting for the map service, one JSON file each.

QUEUE_DIR/
  <12-digit sequence>_<batch id, percent-encoded>.json   a batch not yet acknowledged; the sequence
                          orders them (oldest first) and continues after the largest one found at
                          start, in the queue and in the set-aside folders, so order survives restarts
  .<name>.<random>.tmp    an atomic write (core/atomic.py) killed before its rename: removed at start.
                          Its write() never returned, so its caller never recorded the batch as done
                          (edge.run recomputes the frame); keeping it would need its caller's word.
  rejected/, conflicts/   batches the server will never take, each beside <name>.reason.json

The folder is listed once, when the spool opens; after that an in-memory index (a deque, oldest
first) answers every question, so queueing a frame costs its write and two fsyncs, whatever the
backlog (listing and sorting the folder on every frame grew with it: docs/edge-and-map-service.md;
re-measure: `python -m experiments.edge_uplink`).

The spool holds at most `max_files` batches and `max_bytes` bytes. At the cap write() refuses the
batch (SpoolFull) rather than dropping an older one: nothing already queued is ever lost, and the
caller decides (dsfec edge stops before the frame, which a resumed run recomputes).

Not thread-safe: the Uplink guards it with its lock, except write(), which only its one producer
calls (the sequence counter is the producer's alone).
"""

from __future__ import annotations

import collections
import json
import os
import re
import urllib.parse
from pathlib import Path

from ..core.atomic import is_temporary, sync_dir, write_bytes, write_json

_QUEUED = re.compile(r"^(\d{12})_(.+)\.json$")
SET_ASIDE = ("rejected", "conflicts")


class SpoolFull(RuntimeError):
    """The spool is at its cap: the batch was not queued (and not recorded as done)."""


def batch_id_of(path: Path) -> str:
    """The batch id a queued file's name carries (no need to read the file)."""
    match = _QUEUED.match(path.name)
    if match is None:
        raise ValueError(f"{path}: not a queued batch file (<12 digits>_<batch id>.json)")
    return urllib.parse.unquote(match.group(2))


class Spool:
    def __init__(self, folder: str | Path, max_files: int = 100_000, max_bytes: int = 1 << 30):
        if max_files < 1 or max_bytes < 1:
            raise ValueError(f"spool cap: max_files and max_bytes must be >= 1, got {max_files}, {max_bytes}")
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.max_files, self.max_bytes = max_files, max_bytes
        self.removed_temporaries: list[str] = []
        queued = sorted(self._open_folder(self.folder))  # names sort as their sequence numbers
        self._index: collections.deque[tuple[str, int]] = collections.deque(queued)  # (file name, size)
        self.nbytes = sum(size for _, size in queued)
        numbers = [int(name[:12]) for name, _ in queued]
        for name in SET_ASIDE:  # a reused number could overwrite an earlier set-aside batch of that name
            if (self.folder / name).is_dir():
                numbers += [int(found[:12]) for found, _ in self._open_folder(self.folder / name)]
        self._seq = max(numbers, default=-1) + 1

    def _open_folder(self, folder: Path) -> list[tuple[str, int]]:
        """One pass over a folder, the only listing of it: removes temporaries, returns the names
        and sizes of the queued (or set-aside) batch files."""
        found, removed = [], False
        with os.scandir(folder) as entries:
            for entry in entries:
                if not entry.is_file():
                    continue
                if is_temporary(entry.name):
                    os.unlink(entry.path)
                    self.removed_temporaries.append(os.path.relpath(entry.path, self.folder))
                    removed = True
                elif _QUEUED.match(entry.name):
                    found.append((entry.name, entry.stat().st_size))
        if removed:
            sync_dir(folder)
        return found

    # -- the producer --------------------------------------------------------------------------
    def has_room(self, size: int) -> bool:
        return len(self._index) + 1 <= self.max_files and self.nbytes + size <= self.max_bytes

    def room_check(self, size: int) -> None:
        if not self.has_room(size):
            raise SpoolFull(f"{self.folder}: the queue is at its cap ({len(self._index)} batches of {self.max_files}, "
                            f"{self.nbytes / 1e6:.1f} MB of {self.max_bytes / 1e6:.1f} MB): the batch was not queued")

    def fullness(self) -> float:
        return max(len(self._index) / self.max_files, self.nbytes / self.max_bytes)

    def write(self, batch_id: str, body: bytes) -> tuple[Path, int]:
        """Write one batch durably (file and folder fsynced) but do not index it yet: append() does,
        once the caller has recorded it. Raises SpoolFull at the cap."""
        self.room_check(len(body))
        path = self.folder / f"{self._seq:012d}_{urllib.parse.quote(batch_id, safe='')}.json"
        write_bytes(path, body)
        self._seq += 1
        return path, len(body)

    def append(self, path: Path, size: int) -> None:
        self._index.append((path.name, size))
        self.nbytes += size

    # -- the consumer: always the oldest ---------------------------------------------------------
    def __len__(self) -> int:
        return len(self._index)

    def oldest(self) -> Path | None:
        return self.folder / self._index[0][0] if self._index else None

    def paths(self) -> list[Path]:
        return [self.folder / name for name, _ in self._index]

    def pop_oldest(self, path: Path) -> None:
        """Drop the oldest entry from the index, which must be `path` (its file is gone already)."""
        head, size = self._index[0]
        if head != path.name:
            raise RuntimeError(f"spool: {path.name} is not the oldest queued batch ({head})")
        self._index.popleft()
        self.nbytes -= size

    def set_aside(self, path: Path, folder: str, reason: dict) -> None:
        """Move a queued file the server will never take into `folder`, its reason beside it."""
        target = self.folder / folder
        target.mkdir(exist_ok=True)
        write_json(target / f"{path.stem}.reason.json", reason)
        path.replace(target / path.name)
        sync_dir(target)
        sync_dir(self.folder)

    def set_aside_count(self) -> dict[str, int]:
        """Batches in rejected/ and conflicts/, this run's and earlier ones' (lists those folders)."""
        return {name: sum(1 for p in (self.folder / name).iterdir()
                          if _QUEUED.match(p.name) and not p.name.endswith(".reason.json"))
                if (self.folder / name).is_dir() else 0 for name in SET_ASIDE}


def read_queued(path: Path) -> dict:
    """A queued batch (written atomically, so whole unless changed by hand: then a clear error)."""
    try:
        batch = json.loads(path.read_bytes())
    except ValueError as e:
        raise ValueError(f"{path}: not a JSON frame batch ({e})") from None
    if not isinstance(batch, dict) or batch.get("batch_id") != batch_id_of(path) or "frame" not in batch:
        raise ValueError(f"{path}: expected the frame batch {batch_id_of(path)!r} its name says")
    return batch
