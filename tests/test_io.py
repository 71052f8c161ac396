"""``depthpose.io``: the native ``.npy``/``.npz``/PFM readers and writers agree with numpy
and the PFM format byte for byte, and refuse what they cannot read by name."""

from __future__ import annotations

import depthpose as dp
import numpy as np
import pytest
from depthpose import io as dpio
from hostile import refused

ARRAYS = {
    "f4": np.arange(6, dtype="<f4").reshape(2, 3),
    "f8_big": np.linspace(0, 1, 5).astype(">f8"),
    "u2": np.array([[0, 1000], [65535, 7]], "<u2"),
    "u1": np.arange(4, dtype=np.uint8),
    "b1": np.array([True, False, True]),
    "i4": np.array([-3, 4], "<i4"),
    "i8_scalar": np.int64(-7),
    "text": np.array("0123abcd"),
    "names": np.array(["head", "l_hand"]),
    "fortran": np.asfortranarray(np.arange(12.0).reshape(3, 4)),
    "empty": np.zeros((0, 3), np.float32),
}


@pytest.mark.parametrize("compressed", [False, True])
def test_npz_reads_what_numpy_writes(tmp_path, compressed):
    save = np.savez_compressed if compressed else np.savez
    save(tmp_path / "a.npz", **ARRAYS)
    back = dpio.read_npz(tmp_path / "a.npz")
    assert list(back) == list(ARRAYS)
    for key, want in ARRAYS.items():
        got = back[key]
        assert got.dtype == np.asarray(want).dtype and got.shape == np.shape(want), key
        np.testing.assert_array_equal(got, want, err_msg=key)
    assert back["fortran"].flags.f_contiguous
    some = dpio.read_npz(tmp_path / "a.npz", keys=["u2", "nothing"])
    assert list(some) == ["u2"]


def test_npz_written_natively_reads_back_in_numpy(tmp_path):
    dpio.write_npz(tmp_path / "n.npz", **ARRAYS)
    assert [p.name for p in tmp_path.iterdir()] == ["n.npz"]  # no temporary file left
    with np.load(tmp_path / "n.npz", allow_pickle=False) as d:
        for key, want in ARRAYS.items():
            np.testing.assert_array_equal(d[key], want, err_msg=key)
            assert (d[key].dtype, d[key].shape) == (np.asarray(want).dtype, np.shape(want)), key
    refused(
        lambda: dpio.write_npz(tmp_path / "o.npz", bad=np.array([{}], dtype=object)),
        dp.InvalidTypeError,
        "bad",
    )
    refused(lambda: dpio.write_npz(3, a=np.ones(2)), dp.InvalidTypeError, "path")


def test_npz_entries_are_checked_by_name(tmp_path):
    np.savez(tmp_path / "s.npz", rec=np.zeros(2, dtype=[("a", "<f4"), ("b", "<i4")]))
    e = refused(lambda: dpio.read_npz(tmp_path / "s.npz", "a test file"), dp.FileFormatError)
    assert "'rec'" in str(e) and "structured" in str(e) and "not a test file" in str(e)
    (tmp_path / "d").mkdir()
    refused(lambda: dpio.read_npz(tmp_path / "d"), dp.FileFormatError, "directory")
    refused(lambda: dpio.read_npz(tmp_path / "s.npz", keys="rec"), dp.InvalidTypeError, "keys")


def test_npy_depth_of_every_layout_and_byte_order(tmp_path):
    depth = np.array([[0.5, 1.0, 0.0], [2.0, np.nan, 3.25]])
    for name, a in {
        "c.npy": depth.astype("<f4"),
        "big.npy": depth.astype(">f8"),
        "fortran.npy": np.asfortranarray(depth),
        "half.npy": depth.astype("<f2"),
    }.items():
        np.save(tmp_path / name, a)
        np.testing.assert_array_equal(dp.read_depth(tmp_path / name), depth.astype(np.float32))
    np.save(tmp_path / "mm.npy", np.array([[1000, 0]], ">u2"))
    np.testing.assert_allclose(dp.read_depth(tmp_path / "mm.npy"), [[1.0, 0.0]])
    np.save(tmp_path / "i.npy", np.ones((2, 2), np.int32))
    refused(lambda: dp.read_depth(tmp_path / "i.npy"), dp.FileFormatError, "int32")
    header = b"{'descr': '<f4', 'fortran_order': False, 'shape': (100000, 100000), }\n"
    (tmp_path / "huge.npy").write_bytes(
        b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header
    )
    e = refused(lambda: dp.read_depth(tmp_path / "huge.npy"), dp.ResourceLimitError)
    assert "MAX_IMAGE_PIXELS" in str(e)


def test_pfm_round_trip_is_exact_and_nan_can_be_inf(tmp_path):
    image = np.array([[1.5, np.nan], [np.inf, -2.0], [0.0, 1e-30]], np.float32)
    dpio.write_pfm(tmp_path / "a.pfm", image)
    assert (tmp_path / "a.pfm").read_bytes().startswith(b"Pf\n2 3\n-1.0\n")
    np.testing.assert_array_equal(dpio.read_pfm(tmp_path / "a.pfm"), image)
    dpio.write_pfm(tmp_path / "b.pfm", image.astype(np.float64), nan_as_inf=True)
    assert np.isposinf(dpio.read_pfm(tmp_path / "b.pfm")[0, 1])
    refused(lambda: dpio.write_pfm(tmp_path / "c.pfm", image[0]), dp.InvalidInputError, "image")


def test_raw_frames_report_a_missing_file_before_the_shape(tmp_path):
    refused(lambda: dp.read_depth(tmp_path / "none.u16", shape=(0, 3)), dp.MissingFileError)
    (tmp_path / "d.u16").write_bytes(bytes(12))
    refused(lambda: dp.read_depth(tmp_path / "d.u16", shape=(0, 3)), dp.InvalidInputError, "shape")
    np.testing.assert_array_equal(dp.read_depth(tmp_path / "d.u16", shape=[2, 3]), np.zeros((2, 3)))
