"""depthpose.stereo: Growing Correspondence Seeds through the Python API."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import shared
from depthpose import _core
from depthpose.stereo import cli_stereo, depth_from_disparity, match

InvalidInputError = _core.InvalidInputError

CONES = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "stereo" / "cones"

# What the matcher reaches on cones (disparities 0..63), with a little slack; measured
# with scripts/eval_stereo.py (see docs/design.md).
CONES_MIN_DENSITY = 0.83
CONES_MAX_BAD2 = 0.04


def random_dots(h: int = 60, w: int = 90, d_back: int = 4, d_front: int = 12, seed: int = 1):
    """A random-dot pair: background at d_back, a square at d_front. Returns left (uint8),
    right (uint8) and the true disparity (NaN where it is not defined)."""
    rng = np.random.default_rng(seed)
    right = rng.integers(0, 256, size=(h, w)).astype(np.uint8)
    left = rng.integers(0, 256, size=(h, w)).astype(np.uint8)
    truth = np.full((h, w), np.nan, np.float32)
    d = np.full((h, w), d_back)
    d[20:45, 40:70] = d_front
    for y in range(h):
        for x in range(w):
            xr = x - d[y, x]
            hidden = d[y, x] == d_back and 20 <= y < 45 and 40 <= xr + d_front < 70
            if xr >= 0 and not hidden:
                left[y, x] = right[y, xr]
                truth[y, x] = d[y, x]
    return left, right, truth


def test_random_dots_recovered_from_uint8_and_float_and_rgb():
    left, right, truth = random_dots()
    disp = match(left, right, max_disparity=20)
    assert disp.dtype == np.float32 and disp.shape == left.shape
    known = np.isfinite(truth) & np.isfinite(disp)
    assert known.sum() > 0.85 * np.isfinite(truth)[2:-2, 20:-2].sum()
    err = np.abs(disp[known] - truth[known])
    assert np.mean(err > 1) < 0.02
    # Same pair as floats and as RGB: the correlation does not care about scale.
    disp_f = match(left / 255.0, right / 255.0, max_disparity=20)
    np.testing.assert_allclose(disp_f, disp, atol=1e-3, equal_nan=True)
    rgb = lambda g: np.repeat(g[:, :, None], 3, axis=2)  # noqa: E731
    disp_rgb = match(rgb(left), rgb(right), max_disparity=20)
    np.testing.assert_allclose(disp_rgb, disp, atol=1e-3, equal_nan=True)


def test_confidence_and_seeds():
    left, right, truth = random_dots()
    disp, conf = match(left, right, max_disparity=20, return_confidence=True, threshold=0.7)
    assert np.array_equal(np.isnan(disp), np.isnan(conf))
    assert np.nanmin(conf) >= 0.7 and np.nanmax(conf) <= 1.0 + 1e-5
    # Two user seeds alone grow over the whole textured pair.
    only = match(left, right, max_disparity=20, num_seeds=0, seeds=[[30, 10, 4], [55, 30, 12]])
    inner = np.isfinite(truth)[2:-2, 2:-2]
    assert np.isfinite(only)[2:-2, 2:-2][inner].mean() > 0.9


def test_uniform_images_give_an_empty_result():
    flat = np.full((40, 50), 128, np.uint8)
    disp = match(flat, flat)
    assert disp.shape == (40, 50) and np.isnan(disp).all()


def test_bad_input_names_the_argument():
    left, right, _ = random_dots()
    with pytest.raises(InvalidInputError, match="right"):
        match(left, right[:, :-1])
    with pytest.raises(InvalidInputError, match="left"):
        match(left[0], right[0])
    with pytest.raises(InvalidInputError, match="left"):
        match(np.zeros((2, 3, 4, 5)), np.zeros((2, 3, 4, 5)))
    bad = left.astype(np.float32)
    bad[3, 3] = np.nan
    with pytest.raises(InvalidInputError, match="left"):
        match(bad, right)
    with pytest.raises(InvalidInputError, match="window"):
        match(left, right, window=4)
    with pytest.raises(InvalidInputError, match="threshold"):
        match(left, right, threshold=2.0)
    with pytest.raises(InvalidInputError, match="num_seeds"):
        match(left, right, num_seeds=0)
    with pytest.raises(InvalidInputError, match="max_disparity"):
        match(left, right, max_disparity=1000)
    with pytest.raises(InvalidInputError, match="seeds"):
        match(left, right, seeds=np.zeros((2, 2)))
    with pytest.raises(InvalidInputError, match="similarity"):
        match(left, right, similarity="sad")
    with pytest.raises(InvalidInputError, match="max_disparity.*-3"):
        match(left, right, max_disparity=-3)
    # A seed count that could only be an allocation failure (it aborted the process).
    with pytest.raises(InvalidInputError, match="num_seeds"):
        match(left, right, num_seeds=10**12)


def test_depth_from_disparity():
    disp = np.array([[10.0, np.nan], [0.0, -50.0]], np.float32)
    z = depth_from_disparity(disp, focal=1000.0, baseline=0.2, doffs=30.0)
    np.testing.assert_allclose(z, [[5.0, 0.0], [200 / 30, 0.0]], rtol=1e-6)
    with pytest.raises(InvalidInputError, match="focal"):
        depth_from_disparity(disp, focal=-1.0, baseline=0.2)
    with pytest.raises(InvalidInputError, match="disparity"):
        depth_from_disparity(disp[0], focal=1.0, baseline=0.2)


def test_cli_writes_disparity_and_depth(tmp_path):
    left, right, _ = random_dots()
    paths = []
    for name, img in (("l.png", left), ("r.png", right)):
        p = tmp_path / name
        _core.write_rgb_png(str(p), np.repeat(img[:, :, None], 3, axis=2))
        paths.append(str(p))
    out, depth = tmp_path / "d.npy", tmp_path / "z.png"
    argv = [*paths, "--out", str(out), "--max-disparity", "20"]
    assert (
        cli_stereo([*argv, "--depth-out", str(depth), "--focal", "500", "--baseline", "0.1"]) == 0
    )
    disp = np.load(out)
    assert disp.shape == left.shape and np.isfinite(disp).mean() > 0.7
    z = _core.read_depth(depth)
    ok = np.isfinite(disp) & (disp > 1)
    np.testing.assert_allclose(z[ok], 50.0 / disp[ok], atol=2e-3)
    pfm = tmp_path / "d.pfm"
    assert cli_stereo([*paths, "--out", str(pfm)]) == 0
    assert pfm.read_bytes().startswith(b"Pf\n90 60\n")
    with pytest.raises(SystemExit):
        cli_stereo([*paths, "--out", str(out), "--depth-out", str(depth)])


@pytest.mark.skipif(not CONES.is_dir(), reason=f"shared stereo data not found at {CONES}")
def test_cones_density_and_accuracy():
    left = _core.read_image(str(CONES / "cones_left.tif"))
    right = _core.read_image(str(CONES / "cones_right.tif"))
    image = pytest.importorskip("PIL.Image", reason="Pillow reads the float ground truth")
    gt = np.array(image.open(CONES / "cones_gt_disp_left.tif"), dtype=np.float32)
    disp = match(left, right, max_disparity=63)
    known = gt > 0
    got = known & np.isfinite(disp)
    density = got.sum() / known.sum()
    bad2 = np.mean(np.abs(disp[got] - gt[got]) > 2)
    assert density >= CONES_MIN_DENSITY, density
    assert bad2 <= CONES_MAX_BAD2, bad2


def test_half_occlusion_removes_the_band_a_hand_spreads_to():
    """A hand held in front of the thigh (the shared rendered pairs): left of it the
    thigh is hidden from the right camera, and windows there take the hand's
    disparity. Dropping those matches leaves fewer person pixels off by more than
    2 px, for under a point of density."""
    data = np.load(shared("stereo_person", "dm_jump_front.npz"))
    bad, density = {}, {}
    for on in (False, True):
        wrong, matched, person = 0, 0, 0
        for k in (4, 5, 6):
            d = match(data["left"][k], data["right"][k], half_occlusion=on)
            mask = data["mask"][k]
            got, want = d[mask], data["disparity"][k][mask]
            ok = np.isfinite(got)
            wrong += int(np.sum(np.abs(got[ok] - want[ok]) > 2))
            matched += int(ok.sum())
            person += int(mask.sum())
        bad[on], density[on] = wrong / matched, matched / person
    assert bad[True] < 0.95 * bad[False], bad
    assert density[True] > density[False] - 0.01, density
