"""The public API used as the README shows it, for ``mypy --strict`` (run by .ci/run).

Not a test module (pytest collects ``test_*.py`` only) and not run: it only has to
type-check, so that the annotations users see hold together.
"""

from __future__ import annotations

import depthpose as dp
import numpy as np
import numpy.typing as npt
from depthpose.pipeline import FramesResult, estimate_frames


def readme_example(
    frames: npt.NDArray[np.float32],
    background: npt.NDArray[np.float32],
    left: npt.NDArray[np.uint8],
    right: npt.NDArray[np.uint8],
) -> None:
    camera = dp.Camera(525.0, 525.0, 319.5, 239.5, 640, 480)
    cameras: list[dp.Camera] = [dp.Camera.kinect_v1(), dp.Camera.itop(), camera.scaled(0.5)]
    depth: np.ndarray = dp.read_depth("frame.png")

    result: dp.PoseResult = dp.PoseEstimator(camera).estimate(depth)
    names: list[str] = result.joint_names
    joints: npt.NDArray[np.float64] = result.joints
    confidence: npt.NDArray[np.float64] = result.confidence
    timings: dict[str, float] = result.timings
    print(names, joints, confidence, timings, cameras)

    tracker = dp.PoseTracker(camera, background=background)
    poses: list[npt.NDArray[np.float64]] = [tracker.update(frame).pose for frame in frames]
    seq: FramesResult = estimate_frames(frames, camera)
    print(len(poses), seq.joints.shape, seq.errors)

    seg: dp.Segmentation = dp.segment_person(depth, camera)
    planes: list[dp.Plane] = seg.planes
    others: list[dp.Cluster] = seg.others
    mask: np.ndarray = dp.foreground_mask(depth, background)
    config = dp.PipelineConfig(recheck_every=0)
    disparity: npt.NDArray[np.float32] = dp.stereo.match(left, right)
    disparity, correlation = dp.stereo.match(left, right, return_confidence=True)
    print(planes, others, mask.sum(), config.as_dict(), disparity, correlation)
    stereo = dp.StereoPoseTracker(camera, baseline=0.12)
    paired: dp.PoseResult = stereo.update(left, right)
    last: npt.NDArray[np.float32] | None = stereo.disparity
    once: dp.PoseResult = dp.estimate_stereo(left, right, camera, 0.12)
    print(paired.joints, last, once.pose)


def fitting_example(depth: npt.NDArray[np.float32], camera: dp.Camera) -> float:
    model = dp.BodyModel()
    config = dp.FitConfig(max_iterations=5, stride=2)
    fit: dp.FitResult = dp.fit_pose(depth, camera, model.neutral_pose(), config=config)
    starts = np.stack([fit.pose, model.neutral_pose()])
    fits: list[dp.FitResult] = dp.fit_poses(depth, camera, starts, resume=None)
    best = min(fits, key=lambda f: f.energy)
    pose = dp.pose_from_joints(best.joints, model)
    candidates: list[dp.Candidate] = dp.TemplateDatabase.default().match(depth, camera)
    return float(pose[0]) + candidates[0].cost


def errors_example(path: str) -> str:
    try:
        dp.read_depth(path)
    except dp.MissingFileError as e:
        return f"missing: {e.filename}"
    except dp.DepthPoseError as e:
        return str(e)
    return "ok"
