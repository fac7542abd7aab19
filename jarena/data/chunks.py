"""Writing and reading rows of a zarr array chunk file by chunk file, safely against a killed writer.

For uncompressed arrays in a local directory (the dataset's raw fields) chunk files are handled here
directly, in zarr v3's format (the ``bytes`` codec stores a chunk as its C-order little-endian bytes,
full-size even at the array's end). Rows are only ever appended past the rows already there (the
committed ones), so:

- a chunk that already holds rows gets the new rows written in place, at their offsets past the old
  ones (``os.pwrite``): the bytes of earlier rows are never touched, whatever happens to the writer;
- a new chunk file is written whole (the rows, then a sparse tail up to its full size) to a temporary
  file and moved into place with ``os.replace``.

Either way one copy goes from the caller's arrays to the file, where zarr's write path makes several,
and no file is rewritten to append to it. Other arrays (compressed ones, other stores) go through zarr,
which rewrites a chunk to a temporary file and ``os.replace``s it (zarr >= 3.1.3).
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
    endian = getattr(endian, "value", endian)  # an Endian enum in zarr 3.1, a string in 3.4
    if array.dtype.itemsize > 1 and endian != sys.byteorder:
        return None
    return os.path.join(str(array.store_path.store.root), array.store_path.path)


def atomic_write(path: str, parts: list, size: int | None = None, offset: int = 0) -> None:
    """Writes ``parts`` (bytes-like, one after another, from byte ``offset``) to ``path`` through a temporary
    file and ``os.replace``; bytes before ``offset`` and, with ``size``, up to ``size`` are (sparse) zeros."""
    tmp = f"{path}.{uuid.uuid4().hex}{PARTIAL_SUFFIX}"
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(tmp, "wb", buffering=0) as f:
        f.seek(offset)
        for part in parts:
            f.write(part)
        if size is not None and f.tell() < size:
            f.truncate(size)
    os.replace(tmp, path)


def _write_in_place(path: str, offset: int, parts: list, size: int) -> None:
    """Writes ``parts`` into the chunk file ``path`` (of ``size`` bytes) from byte ``offset`` on; a missing
    file (its earlier rows never written: zeros) is created whole instead."""
    try:
        fd = os.open(path, os.O_WRONLY)
    except FileNotFoundError:
        atomic_write(path, parts, size=size, offset=offset)
        return
    try:
        if os.fstat(fd).st_size != size:
            raise ValueError(f"chunk file {path} has {os.fstat(fd).st_size} bytes, expected {size}: corrupt store")
        for part in parts:
            view = memoryview(part).cast("B")
            while view.nbytes:
                written = os.pwrite(fd, view, offset)
                view, offset = view[written:], offset + written
    finally:
        os.close(fd)


def write_rows(array: zarr.Array, start: int, pieces: list[np.ndarray]) -> None:
    """Writes ``pieces`` (arrays of rows, laid end to end) into ``array`` from row ``start`` on.

    The array must have room, and rows from ``start`` on must hold nothing worth keeping (they are
    past the committed ones); rows before ``start`` are never modified.
    """
    directory = _raw_directory(array)
    if directory is None:
        data = np.concatenate(pieces)
        array[start:start + data.shape[0]] = data
        return
    pieces = [np.ascontiguousarray(p, array.dtype) for p in pieces if p.shape[0]]
    bounds = np.cumsum([0] + [p.shape[0] for p in pieces]) + start
    rows, stop = array.chunks[0], int(bounds[-1])
    row_bytes = int(np.prod(array.shape[1:], dtype=np.int64)) * array.dtype.itemsize
    tail = (0,) * (array.ndim - 1)
    for c in range(start // rows, (stop - 1) // rows + 1):
        lo, hi = max(start, c * rows), min(stop, (c + 1) * rows)
        # the parts of the pieces that fall in rows lo:hi
        parts = [p[max(lo - b0, 0):min(hi, b1) - b0] for p, b0, b1 in zip(pieces, bounds[:-1], bounds[1:], strict=True)
                 if b0 < hi and b1 > lo]
        path = os.path.join(directory, array.metadata.encode_chunk_key((c,) + tail))
        if c * rows < start:  # the chunk holds earlier rows: append in place, past them
            _write_in_place(path, (lo - c * rows) * row_bytes, parts, rows * row_bytes)
        else:
            atomic_write(path, parts, size=rows * row_bytes)


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


def is_raw(array: zarr.Array) -> bool:
    """Whether :func:`read_rows` reads ``array``'s chunk files directly (raw bytes in a local store)."""
    return _raw_directory(array) is not None and array.fill_value == 0


def read_row_set(array: zarr.Array, rows: np.ndarray) -> np.ndarray:
    """``array[rows]`` for any int rows, reading each run of consecutive rows once (for raw arrays: only
    those bytes, not whole chunks)."""
    unique, inverse = np.unique(rows, return_inverse=True)
    if unique.size == 0:
        return np.empty((0,) + array.shape[1:], array.dtype)
    breaks = np.flatnonzero(np.diff(unique) != 1) + 1
    runs = np.split(unique, breaks)
    data = np.concatenate([read_rows(array, int(run[0]), int(run[-1]) + 1) for run in runs])
    return data[inverse.reshape(-1)]
