"""One checked `.npy` array from a dataset file: header first, then exactly the bytes it announces.

RADDet's RAD cubes and CARRADA's processed RD maps are plain `.npy` files. `np.load` would happily
return an object array through pickle (allow_pickle), a zip archive, or whatever shape the header
claims; a dataset reader wants one array of a known shape and kind, and a clear error naming the
file otherwise. Reading the header ourselves (numpy.lib.format) lets us check shape, dtype and the
file's length before allocating anything, so a corrupt header cannot ask for terabytes.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.lib import format as npy_format

HEADER_READERS = {(1, 0): npy_format.read_array_header_1_0, (2, 0): npy_format.read_array_header_2_0}
KIND_NAMES = {"f": "float", "c": "complex", "i": "int", "u": "uint", "b": "bool"}


def _fail(path, what: str) -> ValueError:
    return ValueError(f"{path}: {what}")


def _header(path: Path, f) -> tuple[tuple, bool, np.dtype]:
    try:
        version = npy_format.read_magic(f)
        if version not in HEADER_READERS:
            raise ValueError(f"format version {version}; expected 1.0 or 2.0")
        return HEADER_READERS[version](f)
    except Exception as e:  # noqa: BLE001 - numpy parses an untrusted header: any failure means "corrupt"
        raise _fail(path, f"not a .npy array ({type(e).__name__}: {str(e)[:160]})") from None


def npy_header(path) -> tuple[tuple[int, ...], np.dtype]:
    """(shape, dtype) a `.npy` file announces, read without its data (ValueError naming the file)."""
    path = Path(path)
    with path.open("rb") as f:
        shape, _, dtype = _header(path, f)
    return tuple(shape), dtype


def read_npy(path, what: str, kinds: str, shape: tuple[int, ...]) -> np.ndarray:
    """The array in `path` (native byte order, C order), which must have dtype kind in `kinds` and
    exactly `shape`; FileNotFoundError if missing, ValueError naming the file and what was expected."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: {what} not found")
    expected = f"{what} of shape {tuple(shape)} and dtype {'/'.join(KIND_NAMES[k] for k in kinds)}"
    with path.open("rb") as f:
        got_shape, fortran, dtype = _header(path, f)
        if dtype.kind not in kinds or dtype.hasobject or dtype.names is not None or dtype.subdtype is not None:
            raise _fail(path, f"dtype {dtype}; expected a {expected}")
        if tuple(got_shape) != tuple(shape):
            raise _fail(path, f"shape {tuple(got_shape)}; expected a {expected}")
        count = math.prod(shape)
        available = path.stat().st_size - f.tell()
        if available < count * dtype.itemsize:
            raise _fail(path, f"truncated: {available} data bytes for {count * dtype.itemsize} "
                              f"({count} x {dtype}); expected a {expected}")
        buffer = bytearray(count * dtype.itemsize)  # writable, so the array we return is too
        f.readinto(buffer)
    array = np.frombuffer(buffer, dtype, count).reshape(shape, order="F" if fortran else "C")
    return np.require(array.astype(dtype.newbyteorder("="), copy=False), requirements="C")
