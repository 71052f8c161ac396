"""``open_stereo``: what a .npz, a folder or two images of pairs give, and a clear
error for each malformed input."""

from __future__ import annotations

import depthpose as dp
import numpy as np
import pytest
from depthpose.stereo_sequence import open_stereo
from PIL import Image

INTRINSICS = np.array([60.0, 60.0, 3.5, 2.5])
IMAGE = (np.arange(48).reshape(6, 8) * 5).astype(np.uint8)


def test_npz_gives_camera_baseline_background_and_joints(tmp_path):
    p = tmp_path / "s.npz"
    np.savez(p, left=np.stack([IMAGE] * 3), right=np.stack([IMAGE] * 3), intrinsics=INTRINSICS,
             baseline=np.float64(0.12), doffs=np.float64(1.5), left_bg=IMAGE, right_bg=IMAGE,
             joints=np.zeros((3, 15, 3)))  # fmt: skip
    seq = open_stereo(p)
    assert (seq.n_frames, seq.baseline, seq.doffs) == (3, 0.12, 1.5)
    assert seq.camera.shape == (6, 8) and list(seq.camera.intrinsics) == list(INTRINSICS)
    assert seq.background is not None and seq.gt_joints is not None
    pairs = list(seq.iter_pairs())
    assert [k for k, _ in pairs] == [0, 1, 2]
    assert all(np.array_equal(pair[0], IMAGE) for _, pair in pairs)  # type: ignore[index]
    # Arguments override the file.
    assert open_stereo(p, baseline=0.3, doffs=0.0).baseline == 0.3


@pytest.mark.parametrize(
    "arrays, error, words",
    [
        ({"right": IMAGE}, dp.FileFormatError, "'left'"),
        ({"left": IMAGE, "right": IMAGE[:3]}, dp.FileFormatError, "one shape"),
        ({"left": IMAGE.ravel(), "right": IMAGE.ravel()}, dp.FileFormatError, "one shape"),
        (
            {"left": IMAGE, "right": IMAGE, "baseline": np.array([1.0, 2.0])},
            dp.FileFormatError,
            "baseline",
        ),
        (
            {"left": IMAGE, "right": IMAGE, "baseline": np.float64(np.nan)},
            dp.InvalidInputError,
            "baseline",
        ),
        (
            {"left": IMAGE, "right": IMAGE, "baseline": np.float64(0.1)},
            dp.InvalidInputError,
            "intrinsics",
        ),
        (
            {"left": IMAGE, "right": IMAGE, "baseline": np.float64(0.1), "intrinsics": np.ones(3)},
            dp.InvalidInputError,
            "intrinsics",
        ),
    ],
)
def test_malformed_npz_is_refused_by_name(tmp_path, arrays, error, words):
    p = tmp_path / "s.npz"
    np.savez(p, **arrays)
    with pytest.raises(error, match=words):
        open_stereo(p)


def test_folder_layouts_and_errors(tmp_path):
    (tmp_path / "left").mkdir()
    (tmp_path / "right").mkdir()
    for side in ("left", "right"):
        for name in ("b.png", "a.png", "background.png"):
            Image.fromarray(IMAGE).save(tmp_path / side / name)
    seq = open_stereo(tmp_path, baseline=0.1, intrinsics=INTRINSICS)
    assert [a.name for a, _ in seq.files] == ["a.png", "b.png"]
    assert seq.background is not None
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(dp.FileFormatError, match="no stereo pairs"):
        open_stereo(empty, baseline=0.1, intrinsics=INTRINSICS)
    with pytest.raises(dp.MissingFileError):
        open_stereo(tmp_path / "nowhere", baseline=0.1)
    with pytest.raises(dp.InvalidTypeError, match="path"):
        open_stereo(3, baseline=0.1)  # type: ignore[arg-type]
