"""Pictures: the skeleton drawn where the joints project, unseen joints left out."""

from __future__ import annotations

import depthpose as dp
import numpy as np
import pytest
from depthpose import viz


def _body() -> tuple[np.ndarray, dp.Camera]:
    model = dp.BodyModel()
    pose = model.neutral_pose()
    pose[2] = 3.0
    return np.asarray(model.joints(pose)), dp.Camera.itop()


def test_the_skeleton_is_drawn_where_the_joints_project() -> None:
    joints, camera = _body()
    blank = np.zeros((camera.height, camera.width, 3), np.uint8)
    pic = viz.draw_skeleton(blank, joints, camera)
    uv = np.round(camera.project(joints)).astype(int)
    for u, v in uv:
        assert pic[v, u].any(), (u, v)
    # Nothing is drawn far from the body.
    ys, xs = np.nonzero(pic.any(axis=2))
    assert xs.min() >= uv[:, 0].min() - 5 and xs.max() <= uv[:, 0].max() + 5


def test_joints_of_confidence_zero_are_left_out() -> None:
    joints, camera = _body()
    blank = np.zeros((camera.height, camera.width, 3), np.uint8)
    names = dp.BodyModel().joint_names
    legs = [names.index(n) for n in ("RKnee", "LKnee", "RFoot", "LFoot")]
    confidence = np.ones(15)
    confidence[legs] = 0.0
    all_seen = viz.draw_skeleton(blank, joints, camera, confidence=np.ones(15))
    upper = viz.draw_skeleton(blank, joints, camera, confidence=confidence)
    assert np.array_equal(all_seen, viz.draw_skeleton(blank, joints, camera))
    uv = np.round(camera.project(joints)).astype(int)
    for k in legs:
        u, v = uv[k]
        assert all_seen[v, u].any() and not upper[v - 2 : v + 3, u - 2 : u + 3].any()
    assert not viz.draw_skeleton(blank, joints, camera, confidence=np.zeros(15)).any()


@pytest.mark.parametrize("bad", [np.ones(14), np.ones((15, 1)), np.array(["x"] * 15)])
def test_a_bad_confidence_is_refused_by_name(bad: np.ndarray) -> None:
    joints, camera = _body()
    blank = np.zeros((camera.height, camera.width, 3), np.uint8)
    with pytest.raises(dp.InvalidInputError, match="confidence"):
        viz.draw_skeleton(blank, joints, camera, confidence=bad)
