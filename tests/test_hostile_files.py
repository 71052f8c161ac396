"""Files: corrupt, truncated, random and missing files give a FileFormatError (a missing
one a MissingFileError, also a FileNotFoundError), never another exception; valid
files of every documented kind read back; ``write_depth`` stores each format in its
one unit and refuses what a format cannot store."""

from __future__ import annotations

import errno

import depthpose as dp
import numpy as np
import pytest
from depthpose import io as dpio
from hostile import fuzz, outcome, refused
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

DEPTH = np.round(np.random.default_rng(3).uniform(0.5, 4.0, (6, 8)), 3).astype(np.float32)
DEPTH[2, 3] = 0.0


def _readers():
    """Every reader of files, by name."""
    from depthpose.sequence import open_sequence
    from depthpose.stereo_sequence import open_stereo

    def open_pairs(path):
        seq = open_stereo(path, baseline=0.1, intrinsics=[60, 60, 3.5, 2.5])
        for _, pair in seq.iter_pairs():
            if isinstance(pair, Exception):
                raise pair

    return {
        "read_depth": dp.read_depth,
        "read_image": dp.read_image,
        "read_float_image": dpio.read_float_image,
        "read_pfm": dpio.read_pfm,
        "read_npz": dpio.read_npz,
        "TemplateDatabase.load": dp.TemplateDatabase.load,
        "open_sequence": lambda p: open_sequence(p, intrinsics=[60, 60, 3.5, 2.5]),
        "open_stereo": open_pairs,
    }


@pytest.mark.parametrize("name", sorted(_readers()))
def test_a_missing_file_is_a_file_not_found_error(tmp_path, name):
    read = _readers()[name]
    for suffix in (".png", ".npz", ".npy", ".pfm", ".tif"):
        path = tmp_path / f"missing{suffix}"
        e = refused(lambda p=path: read(p), FileNotFoundError)
        assert isinstance(e, dp.MissingFileError) and e.errno == errno.ENOENT
        assert isinstance(e, dp.FileFormatError) and e.filename == str(path)


def _seed_files(tmp_path) -> dict[str, bytes]:
    """Valid files of every kind the readers take."""
    from PIL import Image

    out = {}
    for suffix in (".png", ".npy", ".pfm"):
        dpio.write_depth(tmp_path / f"d{suffix}", DEPTH)
        out[suffix] = (tmp_path / f"d{suffix}").read_bytes()
    Image.fromarray(DEPTH).save(tmp_path / "f.tif")
    out[".tif"] = (tmp_path / "f.tif").read_bytes()
    np.savez(tmp_path / "s.npz", depth=DEPTH[None], intrinsics=np.array([60.0, 60, 3.5, 2.5]))
    out[".npz"] = (tmp_path / "s.npz").read_bytes()
    return out


@fuzz(40)
@given(
    st.sampled_from([".png", ".npy", ".pfm", ".tif", ".npz"]),
    st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 255)), max_size=8),
    st.one_of(st.none(), st.integers(0, 10**6)),
    st.one_of(st.none(), st.binary(max_size=200)),
)
def test_corrupt_and_random_files_give_file_format_errors(
    tmp_path_factory, suffix, edits, cut, junk
):
    tmp = tmp_path_factory.mktemp("files")
    data = bytearray(junk if junk is not None else _seed_files(tmp)[suffix])
    for at, value in edits:
        if data:
            data[at % len(data)] = value
    if cut is not None:
        del data[cut % (len(data) + 1) :]
    for read_suffix in {suffix, ".npz"}:
        path = tmp / f"x{read_suffix}"
        path.write_bytes(bytes(data))
        for name, read in _readers().items():
            r = outcome(lambda read=read, p=path: read(p))
            if isinstance(r, dp.DepthPoseError):
                assert "pickle" not in str(r).lower()
                if name not in ("open_sequence", "open_stereo"):  # these check the camera
                    assert isinstance(r, (dp.FileFormatError, dp.ResourceLimitError)), (name, r)
                    assert "x" + read_suffix in str(r), (name, r)


def test_a_random_npz_is_not_a_pickle_error(tmp_path):
    import pickle

    (tmp_path / "p.npz").write_bytes(pickle.dumps({"depth": [1, 2, 3]}))
    np.savez(tmp_path / "o.npz", depth=np.array([{"a": 1}], dtype=object))
    np.savez(tmp_path / "other.npz", something=np.ones(3))
    for f in ("p.npz", "o.npz"):
        for read in (dp.TemplateDatabase.load, dpio.read_npz):
            e = refused(lambda f=f, read=read: read(tmp_path / f), dp.FileFormatError, f)
            assert "pickle" not in str(e).lower()
    e = refused(lambda: dp.TemplateDatabase.load(tmp_path / "other.npz"), dp.FileFormatError)
    assert "not a template database" in str(e)


def test_float_tiff_depth_is_read_by_every_reader(tmp_path):
    from PIL import Image

    Image.fromarray(DEPTH).save(tmp_path / "d.tif")  # 32-bit float, one channel
    for read in (dp.read_depth, dpio.read_float_image, dp.read_image):
        np.testing.assert_array_equal(read(tmp_path / "d.tif"), DEPTH)
    Image.fromarray(-DEPTH).save(tmp_path / "neg.tif")
    refused(lambda: dp.read_depth(tmp_path / "neg.tif"), dp.FileFormatError, "neg.tif")


def test_each_depth_format_has_one_unit(tmp_path):
    mm = np.round(DEPTH * 1000).astype(np.uint16)
    for suffix in (".png", ".npy", ".pfm"):
        for given_depth in (DEPTH, mm, DEPTH.astype(np.float64), np.asfortranarray(DEPTH)):
            dpio.write_depth(tmp_path / f"d{suffix}", given_depth)
            np.testing.assert_allclose(dp.read_depth(tmp_path / f"d{suffix}"), DEPTH, atol=1e-6)
    # Float formats store float32 metres; PNG uint16 units of scale.
    assert np.load(tmp_path / "d.npy").dtype == np.float32
    dpio.write_depth(tmp_path / "cm.png", DEPTH, scale=np.float32(0.01))
    np.testing.assert_allclose(dp.read_depth(tmp_path / "cm.png", scale=0.01), DEPTH, atol=0.005)


def test_write_depth_refuses_what_a_format_cannot_store(tmp_path):
    far = DEPTH.copy()
    far[0, 0] = 70.0
    e = refused(lambda: dpio.write_depth(tmp_path / "f.png", far), dp.InvalidInputError, "depth")
    assert "65.535" in str(e) and not (tmp_path / "f.png").exists()
    dpio.write_depth(tmp_path / "f.png", far, scale=0.002)  # a larger unit stores it
    dpio.write_depth(tmp_path / "f.npy", far)  # float formats store any finite depth
    tiny = DEPTH.copy()
    tiny[0, 0] = 1e-4
    refused(lambda: dpio.write_depth(tmp_path / "t.png", tiny), dp.InvalidInputError, "depth")
    nan = DEPTH.copy()
    nan[0, 0] = np.nan
    for suffix in (".png", ".npy", ".pfm"):
        dpio.write_depth(tmp_path / f"n{suffix}", nan)
    assert dp.read_depth(tmp_path / "n.png")[0, 0] == 0  # PNG: NaN is 0, no reading
    assert np.isnan(dp.read_depth(tmp_path / "n.npy")[0, 0])  # float formats keep NaN
    assert np.isnan(dp.read_depth(tmp_path / "n.pfm")[0, 0])
    for bad in (np.where(DEPTH > 1, np.inf, DEPTH), -DEPTH, DEPTH.astype(np.int32), DEPTH[0]):
        for suffix in (".png", ".npy", ".pfm"):
            refused(
                lambda b=bad, s=suffix: dpio.write_depth(tmp_path / f"b{s}", b), dp.DepthPoseError
            )
    for scale in (0, -1, 1e-9, 1000.0, np.nan, 10**400):
        refused(
            lambda s=scale: dpio.write_depth(tmp_path / "s.png", DEPTH, s), dp.InvalidInputError
        )
        refused(lambda s=scale: dp.read_depth(tmp_path / "f.png", s), dp.InvalidInputError, "scale")
    refused(lambda: dp.read_depth(tmp_path / "f.png", scale="0.001"), dp.InvalidTypeError, "scale")
    refused(lambda: dpio.write_depth(tmp_path / "x.bmp", DEPTH), dp.InvalidInputError, "path")
    refused(lambda: dpio.write_depth(3, DEPTH), dp.InvalidTypeError, "path")


@fuzz(40)
@given(
    hnp.arrays(
        np.float32,
        st.tuples(st.integers(1, 5), st.integers(1, 5)),
        elements=st.floats(0, 80, width=16) | st.just(np.nan),
    ),
    st.sampled_from([np.float32, np.float64, np.uint16]),
    st.sampled_from([".png", ".npy", ".pfm"]),
    st.sampled_from([0.001, 0.0001, 0.01]),
)
def test_write_depth_round_trips_or_refuses(tmp_path_factory, depth, dtype, suffix, scale):
    if dtype == np.uint16:
        depth = (np.nan_to_num(depth) * 800).astype(np.uint16)
    else:
        depth = depth.astype(dtype)
    path = tmp_path_factory.mktemp("w") / f"d{suffix}"
    r = outcome(lambda: dpio.write_depth(path, depth, scale), ("depth",))
    metres = depth.astype(np.float64) * (0.001 if depth.dtype == np.uint16 else 1.0)
    if isinstance(r, dp.DepthPoseError):
        assert suffix == ".png" and isinstance(r, dp.InvalidInputError)
        units = np.round(metres / scale)
        assert ((metres > 0) & ((units < 1) | (units > 65535))).any()
        return
    back = dp.read_depth(path, scale=scale)
    if suffix == ".png":
        want = np.nan_to_num(metres)
        np.testing.assert_allclose(back, want, atol=0.5 * scale + 1e-6 * want.max())
    else:  # float32 metres (uint16 millimetres converted in float32)
        np.testing.assert_allclose(back, metres.astype(np.float32), rtol=2e-7, equal_nan=True)


@fuzz(30)
@given(
    st.binary(max_size=64),
    st.integers(-5, 5),
    st.integers(-5, 5),
    st.sampled_from([b"Pf", b"PF", b"P6"]),
)
def test_pfm_headers_of_any_content(tmp_path_factory, tail, w, h, magic):
    path = tmp_path_factory.mktemp("pfm") / "x.pfm"
    path.write_bytes(magic + b"\n%d %d\n-1.0\n" % (w, h) + tail)
    r = outcome(lambda: dpio.read_pfm(path), ("x.pfm",))
    if not isinstance(r, dp.DepthPoseError):
        assert r.shape == (h, w) and r.dtype == np.float32


def test_raw_u16_frames_are_checked_before_reading(tmp_path):
    (DEPTH * 1000).astype("<u2").tofile(tmp_path / "d.u16")
    np.testing.assert_allclose(dp.read_depth(tmp_path / "d.u16", shape=(6, 8)), DEPTH, atol=1e-6)
    for shape in ((6,), (0, 8), (-6, -8), ("6", 8), (6.0, 8), 48):
        refused(
            lambda s=shape: dp.read_depth(tmp_path / "d.u16", shape=s), dp.DepthPoseError, "shape"
        )
    e = refused(
        lambda: dp.read_depth(tmp_path / "d.u16", shape=(2**40, 2**40)), dp.ResourceLimitError
    )
    assert "MAX_IMAGE_PIXELS" in str(e)
    refused(lambda: dp.read_depth(tmp_path / "d.u16", shape=(5, 8)), dp.FileFormatError, "shape")


def test_every_reader_reports_a_missing_file_alike(tmp_path):
    from depthpose import synth
    from depthpose.sequence import open_sequence

    missing = tmp_path / "nothing.npz"
    for read in (synth.load, open_sequence, dp.read_depth):
        with pytest.raises(FileNotFoundError) as e:
            read(missing)
        assert isinstance(e.value, dp.DepthPoseError), read


def test_scores_of_mismatched_shapes_are_a_clear_error():
    from depthpose.metrics import evaluate

    with pytest.raises(dp.InvalidInputError, match="pred"):
        evaluate(np.zeros((3, 15, 3)), np.zeros((4, 15, 3)))


def test_a_batch_with_a_corrupt_template_file_fails_once_and_clearly(tmp_path):
    from depthpose.batch import run

    bad = tmp_path / "templates.npz"
    bad.write_bytes(b"not a zip file")
    with pytest.raises(dp.FileFormatError, match="templates"):
        run([tmp_path / "seq.npz"], tmp_path / "out", templates=bad, progress=False)
