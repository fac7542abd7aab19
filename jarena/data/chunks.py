"""Writing rows of a zarr array chunk by chunk, each chunk file replaced atomically.

For uncompressed arrays in a local directory (the dataset's raw fields) the chunk files are written
here directly, in zarr v3's format (the ``bytes`` codec stores a chunk as its C-order little-endian bytes,
full-size even at the array's end): one copy from the caller's array to the file, where zarr's own
write path makes several. Every file goes through a temporary file and ``os.replace``, so a killed writer
leaves each chunk old or new. Other arrays (compressed ones, other stores) are written through zarr,
which does the same for local stores (zarr >= 3.1.3).
"""

from __future__ import annotations

import os
import sys
import uuid

import numpy as np
import zarr
from zarr.codecs import BytesCodec
from zarr.storage import LocalStore

PARTIAL_SUFFIX = ".partial"


def _raw_directory(array: zarr.Array) -> str | None:
    """The array's directory when its chunks are raw bytes in a local store, else ``None``."""
    codecs = array.metadata.codecs
    if len(codecs) != 1 or not isinstance(codecs[0], BytesCodec) or not isinstance(array.store_path.store, LocalStore):
        return None
    endian = codecs[0].endian
    if array.dtype.itemsize > 1 and (endian is None or endian.value != sys.byteorder):
        return None
    return os.path.join(str(array.store_path.store.root), array.store_path.path)


def atomic_write(path: str, data) -> None:
    """Writes ``data`` (bytes-like) to ``path`` through a temporary file and ``os.replace``."""
    tmp = f"{path}.{uuid.uuid4().hex}{PARTIAL_SUFFIX}"
    try:
        with open(tmp, "wb") as f:
            f.write(data)
    except FileNotFoundError:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(tmp, "wb") as f:
            f.write(data)
    os.replace(tmp, path)


def write_rows(array: zarr.Array, start: int, data: np.ndarray) -> None:
    """Writes ``data`` into rows ``start : start + len(data)`` of ``array`` (which must have room)."""
    directory = _raw_directory(array)
    if directory is None:
        array[start:start + data.shape[0]] = data
        return
    data = np.ascontiguousarray(data, array.dtype)
    rows, stop = array.chunks[0], start + data.shape[0]
    tail = (0,) * (array.ndim - 1)
    for c in range(start // rows, (stop - 1) // rows + 1):
        lo, hi = max(start, c * rows), min(stop, (c + 1) * rows)
        path = os.path.join(directory, array.metadata.encode_chunk_key((c,) + tail))
        if lo == c * rows and hi == (c + 1) * rows:
            chunk = data[lo - start:hi - start]
        else:  # a partial chunk: keep the rows already there
            chunk = np.zeros((rows,) + array.shape[1:], array.dtype)
            if os.path.exists(path):
                chunk.reshape(-1).view(np.uint8)[:] = np.fromfile(path, np.uint8)
            chunk[lo - c * rows:hi - c * rows] = data[lo - start:hi - start]
        atomic_write(path, memoryview(chunk).cast("B"))
