"""The whole pipeline in one call (:class:`PoseEstimator`), a video in one loop
(:class:`PoseTracker`), and sequences of frames (:func:`estimate_frames`).

From scratch: foreground → surface-context template search → hard EM (CRF labels +
Levenberg–Marquardt) from the best few candidates, keeping the lowest energy. Tracking:
each frame starts from the previous pose extrapolated by a damped constant-velocity
model, with a prior toward it; a lost track (too few points explained) is
re-initialised from the templates. Subject shape calibration is not built yet: the body
shape is the model's, scaled from its height.

Two people in view: the foreground stage keeps the nearest large body (see
``foreground_mask``), so the nearest person is estimated.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._core import Camera, DepthPoseError, InvalidInputError, NoBodyError
from .cloud import foreground_mask

__all__ = [
    "JOINT_NAMES",
    "PoseResult",
    "PoseEstimator",
    "PoseTracker",
    "PipelineConfig",
    "estimate_frames",
    "estimate_stereo",
    "FramesResult",
]

JOINT_NAMES = [
    "Head", "Neck", "RShoulder", "LShoulder", "RElbow", "LElbow", "RHand", "LHand",
    "Torso", "RHip", "LHip", "RKnee", "LKnee", "RFoot", "LFoot",
]  # fmt: skip


@dataclass
class PipelineConfig:
    """Settings of the estimator and the tracker."""

    #: Template candidates refined by EM when estimating from scratch.
    candidates: int = 3
    #: EM iterations for each candidate before choosing, and for the winner after.
    candidate_iterations: int = 3
    #: Tracking: weight of the prior toward the predicted pose (see ``fit_pose``).
    prior_weight: float = 100.0
    #: Tracking: EM iterations per tracked frame.
    track_iterations: int = 4
    #: Tracking: share of the previous velocity carried into the prediction.
    velocity_damping: float = 0.5
    #: Tracking: a frame is lost when fewer than this share of the foreground points
    #: are explained by the body (not outliers) ...
    min_inlier_share: float = 0.75
    #: Fitting settings passed to ``fit_pose`` as ``FitConfig`` keywords (None = defaults).
    fit: dict[str, Any] | None = None


@dataclass
class PoseResult:
    """The pose of one frame."""

    pose: np.ndarray  # (22,)
    joints: np.ndarray  # (15, 3) camera frame, metres
    labels: np.ndarray  # (H, W) int16, -1 = not body
    energy: float
    iterations: int
    converged: bool
    confidence: np.ndarray  # (15,) in [0, 1]
    timings: dict[str, float] = field(default_factory=dict)
    source: str = "templates"  # how the start pose was found: templates | tracking
    joint_names: list[str] = field(default_factory=lambda: list(JOINT_NAMES))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (labels left out; they are an image)."""
        return {
            "pose": self.pose.tolist(),
            "joints": self.joints.tolist(),
            "joint_names": list(self.joint_names),
            "energy": float(self.energy),
            "iterations": int(self.iterations),
            "converged": bool(self.converged),
            "confidence": self.confidence.tolist(),
            "timings": dict(self.timings),
            "source": self.source,
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict())


# Segments whose points witness each joint (part indices of the body model).
_JOINT_PARTS: list[tuple[str, ...]] = [
    ("head",), ("neck", "torso"), ("torso", "r_upper_arm"), ("torso", "l_upper_arm"),
    ("r_upper_arm", "r_forearm"), ("l_upper_arm", "l_forearm"), ("r_forearm", "r_hand"),
    ("l_forearm", "l_hand"), ("torso", "pelvis"), ("pelvis", "r_thigh"),
    ("pelvis", "l_thigh"), ("r_thigh", "r_shin"), ("l_thigh", "l_shin"),
    ("r_shin", "r_foot"), ("l_shin", "l_foot"),
]  # fmt: skip


def _model(model):
    from .body import BodyModel

    return BodyModel() if model is None else model


def joint_confidence(model, pose, labels: np.ndarray, camera: Camera) -> np.ndarray:
    """Per-joint confidence: the share of the model's visible surface around the joint
    that the data labelled as that part (from a render of the fitted pose), zero for a
    joint outside the image."""
    _, rendered = model.render_depth(pose, camera)
    names = list(model.part_names)
    n_parts = len(names)
    seen = np.bincount(labels[labels >= 0].ravel(), minlength=n_parts)[:n_parts]
    expect = np.bincount(rendered[rendered >= 0].ravel(), minlength=n_parts)[:n_parts]
    joints = model.joints(pose)
    uv = camera.project(joints)
    inside = (
        np.isfinite(uv).all(1)
        & (uv[:, 0] >= 0) & (uv[:, 0] < camera.width)
        & (uv[:, 1] >= 0) & (uv[:, 1] < camera.height)
    )  # fmt: skip
    conf = np.zeros(len(JOINT_NAMES))
    for j, parts in enumerate(_JOINT_PARTS):
        idx = [names.index(p) for p in parts if p in names]
        e = expect[idx].sum()
        s = seen[idx].sum()
        conf[j] = min(1.0, s / e) if e > 0 else 0.3  # hidden: only the kinematic chain
    return np.where(inside, conf, 0.0)


class PoseEstimator:
    """Pose from scratch, one frame at a time.

    ``templates``: a :class:`~depthpose.templates.TemplateDatabase` (default: the cached
    default database, built on first use). ``background``: the empty scene, for
    background subtraction (else the nearest large body in range is the person).
    """

    def __init__(
        self,
        camera: Camera,
        *,
        model=None,
        templates=None,
        config: PipelineConfig | None = None,
        background: np.ndarray | None = None,
    ) -> None:
        if not isinstance(camera, Camera):
            raise InvalidInputError(
                f"camera: expected a depthpose.Camera, got {type(camera).__name__}"
            )
        self.camera = camera
        self.model = _model(model)
        self.config = config or PipelineConfig()
        self.background = background
        self._templates = templates

    @property
    def templates(self):
        if self._templates is None:
            from .templates import TemplateDatabase

            self._templates = TemplateDatabase.default()
        return self._templates

    def _mask(self, depth: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
        if mask is not None:
            return np.ascontiguousarray(mask, dtype=bool)
        return foreground_mask(depth, self.background)

    def _fit(self, depth, mask, init, *, iterations=None, prior=None):
        from .fit import FitConfig, fit_pose

        kwargs = dict(self.config.fit or {})
        if iterations is not None:
            kwargs["max_iterations"] = iterations
        return fit_pose(
            depth,
            self.camera,
            init,
            model=self.model,
            mask=mask,
            config=FitConfig(**kwargs),
            prior=prior,
            prior_weight=self.config.prior_weight,
        )

    def _result(self, fit, timings, source) -> PoseResult:
        conf = joint_confidence(self.model, fit.pose, fit.labels, self.camera)
        return PoseResult(
            pose=np.asarray(fit.pose),
            joints=np.asarray(fit.joints),
            labels=np.asarray(fit.labels, np.int16),
            energy=float(fit.energy),
            iterations=int(fit.iterations),
            converged=bool(fit.converged),
            confidence=conf,
            timings=timings,
            source=source,
        )

    def estimate(self, depth: np.ndarray, mask: np.ndarray | None = None) -> PoseResult:
        """Foreground → template search → EM from the best candidates."""
        t = {"start": time.perf_counter()}
        mask = self._mask(depth, mask)
        t["foreground"] = time.perf_counter()
        cands = self.templates.match(depth, self.camera, mask=mask, top_k=self.config.candidates)
        t["templates"] = time.perf_counter()
        if not cands:
            raise NoBodyError("depth: no template matched the foreground")
        fits = [
            self._fit(depth, mask, c.pose, iterations=self.config.candidate_iterations)
            for c in cands
        ]
        best = min(fits, key=lambda f: f.energy)
        final = self._fit(depth, mask, best.pose)
        t["fit"] = time.perf_counter()
        timings = _stage_times(t)
        return self._result(final if final.energy <= best.energy else best, timings, "templates")


def _stage_times(t: dict[str, float]) -> dict[str, float]:
    keys = list(t)
    out = {k: 1000 * (t[k] - t[p]) for p, k in zip(keys, keys[1:], strict=False)}
    out["total"] = 1000 * (t[keys[-1]] - t[keys[0]])
    return out  # milliseconds


class PoseTracker:
    """Pose through a depth video: each :meth:`update` starts from the previous pose."""

    def __init__(
        self,
        camera: Camera,
        *,
        model=None,
        templates=None,
        config: PipelineConfig | None = None,
        background: np.ndarray | None = None,
    ) -> None:
        self.estimator = PoseEstimator(
            camera, model=model, templates=templates, config=config, background=background
        )
        self.reset()

    @property
    def model(self):
        return self.estimator.model

    @property
    def config(self) -> PipelineConfig:
        return self.estimator.config

    def reset(self) -> None:
        """Forget the track."""
        self._prev: np.ndarray | None = None
        self._prev2: np.ndarray | None = None
        self.lost_frames = 0

    def _lost(self, fit, mask: np.ndarray) -> bool:
        n = int(mask.sum())
        inliers = int((np.asarray(fit.labels) >= 0).sum())
        return n == 0 or inliers / n < self.config.min_inlier_share

    def _predict(self) -> np.ndarray:
        assert self._prev is not None
        if self._prev2 is None:
            return self._prev.copy()
        pred = self._prev + self.config.velocity_damping * (self._prev - self._prev2)
        lo, hi = np.asarray(self.model.lower_bounds), np.asarray(self.model.upper_bounds)
        return np.clip(pred, lo, hi)

    def update(self, depth: np.ndarray, mask: np.ndarray | None = None) -> PoseResult:
        """The pose of the next frame."""
        est = self.estimator
        if self._prev is None:
            res = est.estimate(depth, mask)
        else:
            t = {"start": time.perf_counter()}
            m = est._mask(depth, mask)
            t["foreground"] = time.perf_counter()
            pred = self._predict()
            fit = est._fit(depth, m, pred, iterations=self.config.track_iterations, prior=pred)
            t["fit"] = time.perf_counter()
            if self._lost(fit, m):
                self.lost_frames += 1
                res = est.estimate(depth, m)
                res.timings["tracking_failed_ms"] = _stage_times(t)["total"]
            else:
                res = est._result(fit, _stage_times(t), "tracking")
            mask = m
        self._prev2, self._prev = self._prev, res.pose.copy()
        return res


@dataclass
class FramesResult:
    """Per-frame results of a sequence; failed frames are NaN with their error."""

    joints: np.ndarray  # (T, 15, 3)
    pose: np.ndarray  # (T, 22)
    confidence: np.ndarray  # (T, 15)
    errors: list[dict[str, Any]]  # {"frame": index, "error": message}
    seconds: list[float] = field(default_factory=list)


def estimate_frames(
    frames: np.ndarray,
    camera: Camera,
    *,
    background: np.ndarray | None = None,
    track: bool = True,
    templates=None,
    model=None,
    config: PipelineConfig | None = None,
    warmup: int = 0,
    first_frame: int = 0,
    on_frame=None,
) -> FramesResult:
    """Poses of frames (T, H, W); the first ``warmup`` frames only prime the tracker and
    are not returned. A frame that raises is recorded as NaN and the loop goes on."""
    frames = np.asarray(frames)
    if frames.ndim != 3:
        raise InvalidInputError(f"frames: expected (T, H, W), got shape {frames.shape}")
    n = frames.shape[0] - warmup
    if n < 0:
        raise InvalidInputError(f"warmup: {warmup} exceeds the {frames.shape[0]} frames")
    out = FramesResult(np.full((n, 15, 3), np.nan), np.full((n, 22), np.nan), np.zeros((n, 15)), [])
    if track:
        tracker = PoseTracker(camera, model=model, templates=templates, config=config,
                              background=background)  # fmt: skip
        step = tracker.update
    else:
        estimator = PoseEstimator(camera, model=model, templates=templates, config=config,
                                  background=background)  # fmt: skip
        step = estimator.estimate
    for k in range(frames.shape[0]):
        t0 = time.perf_counter()
        try:
            res = step(np.ascontiguousarray(frames[k]))
        except DepthPoseError as e:
            if track:
                tracker.reset()
            if k >= warmup:
                out.errors.append({"frame": first_frame + k, "error": f"{type(e).__name__}: {e}"})
            continue
        if k >= warmup:
            out.joints[k - warmup] = res.joints
            out.pose[k - warmup] = res.pose
            out.confidence[k - warmup] = res.confidence
            out.seconds.append(time.perf_counter() - t0)
            if on_frame is not None:
                on_frame(first_frame + k, res)
    return out


def estimate_stereo(
    left: np.ndarray,
    right: np.ndarray,
    camera: Camera,
    baseline: float,
    *,
    doffs: float = 0.0,
    estimator: PoseEstimator | None = None,
    max_disparity: int | None = None,
) -> PoseResult:
    """The paper's real-data path: a rectified pair → GCS disparity → depth → pose.

    ``camera`` is the left camera (its fx is the focal length in pixels); ``baseline`` in
    metres; ``doffs`` the principal-point offset between the cameras (Middlebury style).
    """
    from . import stereo

    disparity = stereo.match(left, right, max_disparity=max_disparity)
    depth = stereo.depth_from_disparity(disparity, camera.fx, baseline, doffs)
    est = estimator or PoseEstimator(camera)
    return est.estimate(np.ascontiguousarray(depth, np.float32))
