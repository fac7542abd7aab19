import os

import numpy as np
import pytest
import zarr

from jarena.data.chunks import write_rows


@pytest.mark.parametrize("compressors", [None, [zarr.codecs.ZstdCodec()]])
def test_write_rows_from_pieces_keeps_earlier_rows_and_reads_back_through_zarr(tmp_path, compressors):
    array = zarr.create_array(tmp_path / "a", shape=(40, 2), chunks=(4, 2), dtype="float32", fill_value=0,
                              compressors=compressors, chunk_key_encoding={"name": "default", "separator": "."})
    rows = np.arange(80, dtype=np.float32).reshape(40, 2)
    write_rows(array, 0, [rows[:3]])  # a partial first chunk
    write_rows(array, 3, [rows[3:6], rows[6:7], rows[7:17]])  # completes it, two full chunks, a partial one
    write_rows(array, 17, [rows[17:40]])
    np.testing.assert_array_equal(zarr.open_array(tmp_path / "a", mode="r")[:], rows)
    assert not [f for f in os.listdir(tmp_path / "a") if f.endswith(".partial")]
    if compressors is None:
        assert sorted(f for f in os.listdir(tmp_path / "a") if f.startswith("c")) == sorted(
            f"c.{i}.0" for i in range(10))


def test_a_chunk_of_the_wrong_size_is_an_error(tmp_path):
    array = zarr.create_array(tmp_path / "a", shape=(8,), chunks=(4,), dtype="int64", fill_value=0, compressors=None)
    write_rows(array, 0, [np.arange(2)])
    (tmp_path / "a" / "c" / "0").write_bytes(b"torn")
    with pytest.raises(ValueError, match="corrupt store"):
        write_rows(array, 2, [np.arange(2)])


def test_read_rows_reads_raw_chunks_and_missing_ones_as_zeros(tmp_path):
    from jarena.data.chunks import read_rows

    array = zarr.create_array(tmp_path / "a", shape=(20, 3), chunks=(4, 3), dtype="uint8", fill_value=0,
                              compressors=None)
    rows = np.arange(60, dtype=np.uint8).reshape(20, 3)
    write_rows(array, 2, [rows[2:9]])
    write_rows(array, 14, [rows[14:18]])
    want = np.zeros_like(rows)
    want[2:9], want[14:18] = rows[2:9], rows[14:18]
    np.testing.assert_array_equal(read_rows(array, 1, 19), want[1:19])
    np.testing.assert_array_equal(read_rows(array, 5, 5), want[5:5])


def test_read_row_set_reads_any_rows_in_any_order(tmp_path):
    from jarena.data.chunks import read_row_set

    array = zarr.create_array(tmp_path / "a", shape=(30, 2), chunks=(4, 2), dtype="int32", fill_value=0,
                              compressors=None)
    rows = np.arange(60, dtype=np.int32).reshape(30, 2)
    write_rows(array, 0, [rows])
    wanted = np.array([7, 3, 4, 5, 29, 3, 0, 8, 9, 10, 11, 12])
    np.testing.assert_array_equal(read_row_set(array, wanted), rows[wanted])
