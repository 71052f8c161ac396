"""Person segmentation (``segment_person``, ``foreground_mask``), with and without a frame
of the empty scene."""

from __future__ import annotations

import json

import depthpose as dp
import numpy as np
import pytest
from conftest import shared


def _sequence(name: str):
    d = np.load(shared("synth", f"{name}.npz"))
    fx, fy, cx, cy = d["intrinsics"]
    depth = d["depth"]
    camera = dp.Camera(fx, fy, cx, cy, depth.shape[2], depth.shape[1])
    return d, camera


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def test_every_shared_sequence_is_segmented_without_a_background():
    """Mask IoU against the ground truth over every frame of every sequence, each
    sequence as a video (the previous frame's result passed on)."""
    means = {}
    for f in sorted(shared("synth").glob("*.npz")):
        d, camera = _sequence(f.stem)
        previous, ious = None, []
        for t in range(d["depth"].shape[0]):
            seg = dp.segment_person(d["depth"][t], camera, previous=previous)
            assert seg.method == "planes"
            ious.append(_iou(seg.mask, d["mask"][t]))
            previous = seg
        means[f.stem] = np.mean(ious)
    assert len(means) >= 19
    assert np.mean(list(means.values())) >= 0.95, means
    assert min(means.values()) >= 0.90, means


def test_the_floor_and_the_wall_are_found_where_the_scene_puts_them():
    d, camera = _sequence("dm_walk_front")
    meta = json.loads(str(d["meta"]))
    seg = dp.segment_person(d["depth"][0], camera)
    floors = [p for p in seg.planes if p.normal[1] > 0.9]
    walls = [p for p in seg.planes if p.normal[2] > 0.9]
    assert len(floors) == 1 and len(walls) >= 1, seg.planes
    # The floor lies the camera's height below it, the wall as far as the scene says.
    assert floors[0].offset == pytest.approx(meta["camera"]["height_m"], abs=0.03)
    assert walls[0].offset == pytest.approx(meta["back_wall_z_m"], abs=0.05)
    assert floors[0].area > 1.0 and floors[0].inliers > 1000
    # A standing adult, measured in metres.
    assert 1.4 < seg.person.height < 2.0
    assert 0.2 < seg.person.area < 1.0
    assert seg.person.person_like
    assert seg.others == []


def test_a_background_frame_is_used_when_given():
    d, camera = _sequence("dm_walk_front")
    seg = dp.segment_person(d["depth"][5], camera, d["background"])
    assert seg.method == "background" and seg.planes == []
    assert np.array_equal(seg.mask, dp.foreground_mask(d["depth"][5], d["background"]))


def test_with_a_background_frame_a_side_views_far_leg_stays_in_the_mask():
    """At noise level 2 a dropout seam separates the far leg from the body, more than
    0.5 m behind the body's median when it steps back, and breaks it into small pieces:
    background subtraction keeps them (by the median and size rules alone: recall down
    to 0.89)."""
    d, _ = _sequence("dm_zombie_walk_left_noise2")
    ious, recalls = [], []
    for depth, truth in zip(d["depth"], d["mask"], strict=True):
        mask = dp.foreground_mask(depth, d["background"])
        seen = truth & (depth > 0)
        ious.append(_iou(mask, truth))
        recalls.append((mask & seen).sum() / seen.sum())
    assert min(recalls) >= 0.95, np.argmin(recalls)
    assert np.mean(ious) >= 0.9


def test_the_empty_scene_has_no_body_and_says_what_was_seen():
    d, camera = _sequence("dm_walk_front")
    with pytest.raises(dp.NoBodyError, match="support plane"):
        dp.segment_person(d["background"], camera)


def test_a_camera_of_another_size_is_refused():
    d, _ = _sequence("dm_walk_front")
    with pytest.raises(dp.InvalidInputError, match="camera"):
        dp.segment_person(d["depth"][0], dp.Camera.kinect_v1())


def test_foreground_mask_without_a_background_segments_the_person():
    d, camera = _sequence("cmu131_01_walk_front")
    for t in (0, 20, 40):
        auto = dp.foreground_mask(d["depth"][t], camera=camera)
        assert _iou(auto, d["mask"][t]) > 0.93
        # Without intrinsics a nominal camera is assumed: planes are planes whatever the
        # focal length, so the person is still found.
        nominal = dp.foreground_mask(d["depth"][t])
        assert _iou(nominal, d["mask"][t]) > 0.9


def test_the_tracker_without_a_background_follows_the_person():
    """The README's tracker example, with no frame of the empty scene."""
    d, camera = _sequence("dm_walk_front")
    tracker = dp.PoseTracker(camera)
    errors = []
    for t in range(12):
        r = tracker.update(d["depth"][t])
        errors.append(np.linalg.norm(r.joints - d["joints"][t], axis=1))
    pck = float((np.concatenate(errors) <= 0.1).mean())
    assert pck >= 0.95, pck
