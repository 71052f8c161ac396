"""``depthpose estimate-stereo``: pairs from a .npz, a folder or two images to the
same outputs as ``estimate``; a bad pair is a failed frame, not a failed run."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared
from depthpose.cli import main
from PIL import Image
from test_stereo_pipeline import BASELINE, make_pair


@pytest.fixture(scope="module")
def pair():
    left, right, _, joints, camera, _ = make_pair()
    return left, right, joints, camera


def _save(path, image):
    Image.fromarray(image).save(path)
    return str(path)


def _intrinsics(camera):
    return ["--intrinsics", *(f"{v!r}" for v in camera.intrinsics)]


def _joints_within(out, joints, tol):
    got = np.load(out)["joints"]
    err = np.linalg.norm(got - joints, axis=-1)
    assert np.nanmax(err) < tol, err


def test_two_images_give_the_joints(tmp_path, pair, capsys):
    left, right, joints, camera = pair
    out = tmp_path / "pose.npz"
    args = [_save(tmp_path / "l.png", left), _save(tmp_path / "r.png", right)]
    rc = main(["estimate-stereo", *args, "--out", str(out), "--baseline", str(BASELINE),
               *_intrinsics(camera)])  # fmt: skip
    assert rc == 0
    saved = np.load(out)
    assert set(saved.files) >= {"joints", "pose", "confidence", "shape", "failed_frames"}
    _joints_within(out, joints[None], 0.10)
    assert "1/1 frames estimated" in capsys.readouterr().out


def test_npz_of_pairs_tracked_and_per_frame(tmp_path, pair):
    left, right, joints, camera = pair
    seq = tmp_path / "pairs.npz"
    np.savez(seq, left=np.stack([left, left]), right=np.stack([right, right]),
             intrinsics=np.array(camera.intrinsics), baseline=np.float64(BASELINE),
             joints=np.stack([joints, joints]))  # fmt: skip
    for mode in ("--track", "--no-track"):
        out = tmp_path / f"pose{mode}.npz"
        assert main(["estimate-stereo", str(seq), "--out", str(out), mode]) == 0
        _joints_within(out, np.stack([joints, joints]), 0.10)


def test_folder_keeps_the_good_pairs(tmp_path, pair, capsys):
    left, right, joints, camera = pair
    for side in ("left", "right"):
        (tmp_path / "pairs" / side).mkdir(parents=True)
    folder = tmp_path / "pairs"
    for k in range(2):
        _save(folder / "left" / f"{k}.png", left)
        _save(folder / "right" / f"{k}.png", right)
    (folder / "left" / "1.png").write_bytes(b"not a picture")
    out = tmp_path / "pose.npz"
    viz = tmp_path / "viz"
    rc = main(["estimate-stereo", str(folder), "--out", str(out), "--baseline",
               str(BASELINE), *_intrinsics(camera), "--viz", str(viz)])  # fmt: skip
    assert rc == 1
    saved = np.load(out)
    assert list(saved["failed_frames"]) == [1]
    assert np.isnan(saved["joints"][1]).all()
    _joints_within(out, np.stack([joints, np.full_like(joints, np.nan)]), 0.10)
    assert (viz / "frame_00000.png").exists()
    assert "1.png" in capsys.readouterr().err


def test_side_by_side_folder_and_missing_partner(tmp_path, pair, capsys):
    left, right, joints, camera = pair
    _save(tmp_path / "a_left.png", left)
    _save(tmp_path / "a_right.png", right)
    out = tmp_path / "pose.npz"
    base = ["--out", str(out), "--baseline", str(BASELINE), *_intrinsics(camera)]
    assert main(["estimate-stereo", str(tmp_path), *base]) == 0
    _save(tmp_path / "b_left.png", left)
    assert main(["estimate-stereo", str(tmp_path), *base]) == 2
    assert "b_right.png" in capsys.readouterr().err


@pytest.mark.parametrize(
    "extra, message",
    [
        ([], "baseline"),
        (["--baseline", "-1"], "baseline"),
        (
            ["--baseline", "0.25", "--camera", "kinect-v1", "--intrinsics", "1", "1", "1", "1"],
            "--camera",
        ),
    ],
)
def test_bad_arguments_are_named(tmp_path, pair, capsys, extra, message):
    left, right, _, camera = pair
    args = [_save(tmp_path / "l.png", left), _save(tmp_path / "r.png", right)]
    if "--intrinsics" not in extra:
        extra = [*extra, *_intrinsics(camera)]
    rc = main(["estimate-stereo", *args, "--out", str(tmp_path / "o.npz"), *extra])
    assert rc == 2
    assert message in capsys.readouterr().err


def test_a_missing_image_and_a_wrong_size(tmp_path, pair, capsys):
    left, right, _, camera = pair
    base = ["--out", str(tmp_path / "o.npz"), "--baseline", "0.25", *_intrinsics(camera)]
    lp = _save(tmp_path / "l.png", left)
    assert main(["estimate-stereo", lp, str(tmp_path / "none.png"), *base]) == 2
    assert "none.png" in capsys.readouterr().err
    small = _save(tmp_path / "small.png", right[:100, :100])
    assert main(["estimate-stereo", lp, small, *base]) == 2
    assert "small.png" in capsys.readouterr().err


def test_shared_stereo_person_without_background(tmp_path, capsys):
    """The shared pairs with their background pair left out, tracked."""
    z = np.load(shared("stereo_person", "dm_walk_front.npz"))
    seq = tmp_path / "walk.npz"
    np.savez(seq, **{k: z[k] for k in ("left", "right", "intrinsics", "baseline", "joints")})
    out = tmp_path / "pose.npz"
    assert main(["estimate-stereo", str(seq), "--out", str(out)]) == 0
    err = np.linalg.norm(np.load(out)["joints"] - z["joints"], axis=-1)
    assert (err < 0.10).mean() >= 0.9
