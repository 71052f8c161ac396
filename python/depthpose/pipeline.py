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
    "swap_limbs",
    "mirror_view",
    "depth_discrepancy",
]

JOINT_NAMES = [
    "Head", "Neck", "RShoulder", "LShoulder", "RElbow", "LElbow", "RHand", "LHand",
    "Torso", "RHip", "LHip", "RKnee", "LKnee", "RFoot", "LFoot",
]  # fmt: skip


@dataclass
class PipelineConfig:
    """Settings of the estimator and the tracker."""

    #: Template candidates taken from the search when estimating from scratch; each
    #: also gives its left/right-swapped and mirrored-view hypotheses (see
    #: :func:`swap_limbs`, :func:`mirror_view`).
    candidates: int = 5
    #: Hypotheses (after ranking all by :func:`depth_discrepancy`) refined by EM.
    hypotheses: int = 4
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
    #: Tracking: a frame is also lost when its depth discrepancy (see
    #: :func:`depth_discrepancy`) exceeds this many times the running median of the
    #: track's recent discrepancies ...
    lost_ratio: float = 1.6
    #: ... or this absolute value.
    lost_discrepancy: float = 0.5
    #: Tracking: every this many frames the template search is run again (with the
    #: swapped and mirrored hypotheses of the tracked pose) and the track switches when
    #: a hypothesis explains the depth clearly better (0 = never).
    recheck_every: int = 8
    #: ... "clearly better": lower discrepancy by at least this share.
    switch_margin: float = 0.1
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
    #: How badly the fitted body explains the depth (see :func:`depth_discrepancy`).
    discrepancy: float = float("nan")

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
            "discrepancy": float(self.discrepancy) if np.isfinite(self.discrepancy) else None,
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


# -- left/right ambiguity ------------------------------------------------------------
# Pose layout (src/body, ``BodyModel.param_names``): 0..3 root translation, 3..6 root
# rotation vector, 6 neck flexion, 7 neck lateral bend, 8..12 right shoulder (3) + elbow,
# 12..16 the same on the left, 16..19 right hip (2) + knee, 19..22 the same on the left.
# The joint angles are anatomical (the same motion on both sides), so exchanging the
# right and left blocks and negating the lateral neck bend mirrors the body in its own
# sagittal plane.
_SWAP = np.r_[0:8, 12:16, 8:12, 19:22, 16:19]
_NECK_LATERAL = 7
_FLIP_X = np.diag([-1.0, 1.0, 1.0])


def swap_limbs(pose: np.ndarray) -> np.ndarray:
    """The left/right-swapped pose: the body mirrored in its own sagittal plane (right
    and left limb angles exchanged, lateral neck bend negated), root unchanged. In a
    side view this puts the far leg where the near one was. An involution."""
    pose = np.asarray(pose, np.float64)
    if pose.shape != (22,):
        raise InvalidInputError(f"pose: expected 22 values, got shape {pose.shape}")
    out = pose[_SWAP].copy()
    out[_NECK_LATERAL] = -out[_NECK_LATERAL]
    return out


def mirror_view(pose: np.ndarray) -> np.ndarray:
    """The mirror image of the posed body in the camera's vertical plane through the hip
    centre (x → −x about the hip centre): the same silhouette flipped left-right, limbs
    swapped so that the body stays a right-handed one. Joints of the result are the
    mirrored joints with right and left exchanged. An involution."""
    out = swap_limbs(pose)
    rot = _FLIP_X @ _rotation_matrix(out[3:6]) @ _FLIP_X
    out[3:6] = _rotation_vector(rot)
    return out


def _rotation_matrix(v: np.ndarray) -> np.ndarray:
    theta = float(np.linalg.norm(v))
    if theta < 1e-12:
        return np.eye(3)
    k = np.asarray(v, np.float64) / theta
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(theta) * kx + (1 - np.cos(theta)) * (kx @ kx)


def _rotation_vector(r: np.ndarray) -> np.ndarray:
    cos = np.clip(0.5 * (np.trace(r) - 1.0), -1.0, 1.0)
    theta = float(np.arccos(cos))
    if theta < 1e-12:
        return np.zeros(3)
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if np.pi - theta > 1e-4:
        return theta * w / (2 * np.sin(theta))
    # Near a half turn: the axis from the symmetric part, its sign from w.
    b = 0.5 * (r + np.eye(3))
    i = int(np.argmax(np.diag(b)))
    axis = b[:, i] / np.sqrt(max(b[i, i], 1e-300))
    if axis @ w < 0:
        axis = -axis
    return theta * axis / np.linalg.norm(axis)


def depth_discrepancy(
    model, pose: np.ndarray, depth: np.ndarray, mask: np.ndarray, camera: Camera,
    cap: float = 0.1,
) -> float:  # fmt: skip
    """How badly ``pose`` explains the observed body, from the depth data alone: the
    rendered body is compared with the foreground pixel by pixel; where both have depth
    the cost is the depth difference capped at ``cap`` metres, a foreground pixel with
    no body rendered or a rendered pixel outside the foreground costs ``cap``. The sum
    is divided by ``cap`` × the foreground pixel count: 0 = perfect, about 1 or more =
    unrelated. Unlike the silhouette, the depth tells the near limb from the far one."""
    rendered, _ = model.render_depth(np.asarray(pose, np.float64), camera)
    rendered = np.asarray(rendered)
    obs = mask & np.isfinite(depth) & (depth > 0)
    n = int(obs.sum())
    if n == 0:
        return float("inf")
    ren = np.isfinite(rendered) & (rendered > 0)
    both = obs & ren
    diff = np.minimum(np.abs(rendered[both] - depth[both]), cap).sum()
    # Rendered where the image shows something else (not a hole inside the mask).
    outside = (ren & ~mask).sum()
    missing = (obs & ~ren).sum()
    return float((diff + cap * (outside + missing)) / (cap * n))


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

    def _result(self, fit, timings, source, discrepancy=float("nan")) -> PoseResult:
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
            discrepancy=float(discrepancy),
        )

    def discrepancy(self, pose: np.ndarray, depth: np.ndarray, mask: np.ndarray) -> float:
        """:func:`depth_discrepancy` of ``pose`` with this estimator's model and camera."""
        return depth_discrepancy(self.model, pose, depth, mask, self.camera)

    def hypotheses(self, depth: np.ndarray, mask: np.ndarray) -> list[np.ndarray]:
        """Start poses from the template search: each of the best ``candidates``
        templates, its left/right-swapped pose and the mirror images of both (the
        search cannot tell a side view's near limbs from its far ones, nor a view from
        its mirror image); near-duplicates dropped."""
        cands = self.templates.match(depth, self.camera, mask=mask, top_k=self.config.candidates)
        if not cands:
            raise NoBodyError("depth: no template matched the foreground")
        out: list[np.ndarray] = []
        seen: list[np.ndarray] = []
        for c in cands:
            p = np.asarray(c.pose, np.float64)
            for q in (p, swap_limbs(p), mirror_view(p), mirror_view(swap_limbs(p))):
                j = np.asarray(self.model.joints(q))
                if any(np.linalg.norm(j - s, axis=1).mean() < 0.03 for s in seen):
                    continue
                seen.append(j)
                out.append(q)
        return out

    def search(self, depth, mask, *, extra=(), timings=None):
        """Best fit from the template hypotheses (and ``extra`` start poses, always
        refined): all ranked by their depth discrepancy, the best ``hypotheses`` refined
        briefly by EM, the one explaining the depth best refined fully. Returns the fit
        and its discrepancy."""
        starts = self.hypotheses(depth, mask)
        if timings is not None:
            timings["templates"] = time.perf_counter()
        ranked = sorted(starts, key=lambda q: self.discrepancy(q, depth, mask))
        chosen = [*list(extra), *ranked[: max(1, self.config.hypotheses)]]
        fits = [
            self._fit(depth, mask, q, iterations=self.config.candidate_iterations) for q in chosen
        ]
        scores = [self.discrepancy(f.pose, depth, mask) for f in fits]
        k = int(np.argmin(scores))
        best, best_score = fits[k], scores[k]
        final = self._fit(depth, mask, best.pose)
        final_score = self.discrepancy(final.pose, depth, mask)
        if final_score <= best_score:
            best, best_score = final, final_score
        return best, best_score

    def estimate(self, depth: np.ndarray, mask: np.ndarray | None = None) -> PoseResult:
        """Foreground → template search (with swapped and mirrored hypotheses) → EM
        from the most promising, keeping the pose that explains the depth best."""
        t = {"start": time.perf_counter()}
        mask = self._mask(depth, mask)
        t["foreground"] = time.perf_counter()
        best, score = self.search(depth, mask, timings=t)
        t["fit"] = time.perf_counter()
        return self._result(best, _stage_times(t), "templates", score)


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
        self._recent: list[float] = []
        self._since_check = 0
        self.lost_frames = 0
        self.switches = 0

    def start_from(self, pose: np.ndarray) -> None:
        """Starts the track from a known pose (the next :meth:`update` refines it
        instead of searching the templates)."""
        pose = np.asarray(pose, np.float64)
        if pose.shape != (22,) or not np.isfinite(pose).all():
            raise InvalidInputError(f"pose: expected 22 finite values, got shape {pose.shape}")
        self.reset()
        self._prev = pose.copy()

    def _lost(self, fit, mask: np.ndarray, score: float) -> bool:
        n = int(mask.sum())
        inliers = int((np.asarray(fit.labels) >= 0).sum())
        if n == 0 or inliers / n < self.config.min_inlier_share:
            return True
        if score > self.config.lost_discrepancy:
            return True
        if len(self._recent) >= 3:
            return score > self.config.lost_ratio * float(np.median(self._recent))
        return False

    def _predict(self) -> np.ndarray:
        assert self._prev is not None
        if self._prev2 is None:
            return self._prev.copy()
        pred = self._prev + self.config.velocity_damping * (self._prev - self._prev2)
        lo, hi = np.asarray(self.model.lower_bounds), np.asarray(self.model.upper_bounds)
        return np.clip(pred, lo, hi)

    def update(self, depth: np.ndarray, mask: np.ndarray | None = None) -> PoseResult:
        """The pose of the next frame. A lost track is re-initialised from the
        templates; every ``recheck_every`` frames the template hypotheses and the
        swapped-limbs pose of the track compete with the tracked pose, and the track
        switches when one explains the depth clearly better."""
        est = self.estimator
        cfg = self.config
        switched = False
        if self._prev is None:
            res = est.estimate(depth, mask)
            switched = True
        else:
            t = {"start": time.perf_counter()}
            m = est._mask(depth, mask)
            t["foreground"] = time.perf_counter()
            pred = self._predict()
            fit = est._fit(depth, m, pred, iterations=cfg.track_iterations, prior=pred)
            score = est.discrepancy(fit.pose, depth, m)
            t["fit"] = time.perf_counter()
            lost = self._lost(fit, m, score)
            self._since_check += 1
            recheck = cfg.recheck_every > 0 and self._since_check >= cfg.recheck_every
            res = est._result(fit, _stage_times(t), "tracking", score)
            if lost or recheck:
                self._since_check = 0
                t2 = {"start": time.perf_counter()}
                pose = np.asarray(fit.pose)
                best, best_score = est.search(depth, m, extra=[pose, swap_limbs(pose)])
                t2["search"] = time.perf_counter()
                margin = 0.0 if lost else cfg.switch_margin
                if best_score < score * (1.0 - margin):
                    timings = res.timings
                    timings["search"] = _stage_times(t2)["total"]
                    timings["total"] += timings["search"]
                    res = est._result(best, timings, "templates", best_score)
                    switched = True
                else:
                    res.timings["search"] = _stage_times(t2)["total"]
                if lost:
                    self.lost_frames += 1
            mask = m
        if switched:
            self.switches += self._prev is not None
            self._prev2 = None
            self._recent = []
        else:
            self._prev2 = self._prev
        self._prev = res.pose.copy()
        if np.isfinite(res.discrepancy):
            self._recent = [*self._recent[-14:], res.discrepancy]
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
