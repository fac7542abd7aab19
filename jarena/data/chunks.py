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


def atomic_write(path: str, parts: list) -> None:
    """Writes ``parts`` (bytes-like, one after another) to ``path`` through a temporary file and ``os.replace``."""
    tmp = f"{path}.{uuid.uuid4().hex}{PARTIAL_SUFFIX}"
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(tmp, "wb", buffering=0) as f:
        for part in parts:
            f.write(part)
    os.replace(tmp, path)


def write_rows(array: zarr.Array, start: int, pieces: list[np.ndarray]) -> None:
    """Writes ``pieces`` (arrays of rows, laid end to end) into ``array`` from row ``start`` (it must have room).

    Raw arrays are written chunk file by chunk file straight from the pieces, without joining them first.
    """
    directory = _raw_directory(array)
    if directory is None:
        data = np.concatenate(pieces)
        array[start:start + data.shape[0]] = data
        return
    pieces = [np.ascontiguousarray(p, array.dtype) for p in pieces if p.shape[0]]
    bounds = np.cumsum([0] + [p.shape[0] for p in pieces]) + start
    rows, stop = array.chunks[0], int(bounds[-1])
    tail = (0,) * (array.ndim - 1)
    for c in range(start // rows, (stop - 1) // rows + 1):
        lo, hi = max(start, c * rows), min(stop, (c + 1) * rows)
        # the parts of the pieces that fall in rows lo:hi
        parts = [p[max(lo - b0, 0):min(hi, b1) - b0] for p, b0, b1 in zip(pieces, bounds[:-1], bounds[1:], strict=True)
                 if b0 < hi and b1 > lo]
        path = os.path.join(directory, array.metadata.encode_chunk_key((c,) + tail))
        if lo != c * rows or hi != (c + 1) * rows:  # a partial chunk: keep the rows already there
            chunk = np.zeros((rows,) + array.shape[1:], array.dtype)
            if os.path.exists(path):
                old = np.fromfile(path, np.uint8)
                if old.size != chunk.nbytes:
                    raise ValueError(f"chunk file {path} has {old.size} bytes, expected {chunk.nbytes}: corrupt store")
                chunk.reshape(-1).view(np.uint8)[:] = old
            chunk[lo - c * rows:hi - c * rows] = np.concatenate(parts)
            parts = [chunk]
        atomic_write(path, [memoryview(part).cast("B") for part in parts])


def read_rows(array: zarr.Array, start: int, stop: int) -> np.ndarray:
    """Rows ``start : stop`` of ``array``; raw chunk files are read directly (missing ones are fill, zeros)."""
    directory = _raw_directory(array)
    if directory is None or array.fill_value != 0:
        return np.asarray(array[start:stop])
    out = np.empty((stop - start,) + array.shape[1:], array.dtype)
    rows, tail = array.chunks[0], (0,) * (array.ndim - 1)
    for c in range(start // rows, (stop - 1) // rows + 1) if stop > start else ():
        lo, hi = max(start, c * rows), min(stop, (c + 1) * rows)
        path = os.path.join(directory, array.metadata.encode_chunk_key((c,) + tail))
        target = out[lo - start:hi - start]
        try:
            with open(path, "rb", buffering=0) as f:
                f.seek((lo - c * rows) * target[:1].nbytes)  # rows lo:hi of the chunk, read in place
                read = f.readinto(memoryview(target).cast("B")) if target.size else 0
        except FileNotFoundError:
            target[...] = 0
            continue
        if read != target.nbytes or os.path.getsize(path) != rows * target[:1].nbytes:
            raise ValueError(f"chunk file {path} does not hold {rows} rows: corrupt store")
    return out
