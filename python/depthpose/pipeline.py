"""The whole pipeline in one call (:class:`PoseEstimator`), a video in one loop
(:class:`PoseTracker`), and sequences of frames (:func:`estimate_frames`).

From scratch: foreground → surface-context template search → hard EM (CRF labels +
Levenberg–Marquardt) from the best few candidates, keeping the lowest energy. Tracking:
each frame starts from the previous pose extrapolated by a damped constant-velocity
model, with a prior toward it; a lost track (too few points explained) is
re-initialised from the templates. Subject shape calibration: unless told the shape
(a ``model``), the tracker fits the body shape (``fit_shape``, 12 factors) once to its
first frames and keeps it (see :class:`PoseTracker` and
``docs/pipeline.md``). Stereo: :func:`estimate_stereo` (GCS disparity → depth → pose).

Two people in view: the foreground stage keeps the nearest large body (see
``foreground_mask``), so the nearest person is estimated.
"""

from __future__ import annotations

import functools
import json
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import _validate
from ._core import Camera, DepthPoseError, InvalidInputError, InvalidTypeError, NoBodyError
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
    "rest_pose_penalty",
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
    candidates: int = 4
    #: Hypotheses (after ranking all by :func:`depth_discrepancy`) refined by EM; 20
    #: takes all of them (at most 4 per candidate).
    hypotheses: int = 20
    #: EM iterations for each candidate before choosing.
    candidate_iterations: int = 2
    #: The best this many candidate fits (by :func:`depth_discrepancy`) are then refined
    #: fully, in parallel, and the best of those kept. More finals is more accurate
    #: (docs/pipeline.md) and, beyond the number of cores, slower.
    finals: int = 3
    #: EM iterations of each final, the candidate iterations included (None: the
    #: ``fit`` settings' ``max_iterations``, 20). The finals' accuracy on the shared
    #: sequences was the same from 8 to 20 (scratch 70.3–71.7 mm, PCK 0.873–0.878) and
    #: 10 cuts the long tail of finals that would run on (docs/pipeline.md, session 13).
    final_iterations: int | None = 10
    #: Pixel stride (``FitConfig``'s ``stride``) of those brief candidate fits. At 2 a
    #: brief fit costs about a seventh of one at 1, so all the hypotheses can be tried
    #: (docs/pipeline.md, session 9).
    candidate_stride: int = 2
    #: Pixel stride of the finals' continued EM; the final labels cover every pixel
    #: either way. When it equals ``candidate_stride`` the brief fits skip labelling
    #: every pixel and the result is always a final.
    final_stride: int = 2
    #: Tracking: weight of the prior toward the predicted pose (see ``fit_pose``).
    prior_weight: float = 100.0
    #: Tracking: EM iterations per tracked frame (on the ``track_stride`` grid); 4
    #: since session 9, when 4, 5 and 6 tracked equally well (docs/pipeline.md).
    track_iterations: int = 4
    #: Tracking: EM of a tracked frame runs on every ``track_stride``-th pixel of every
    #: ``track_stride``-th row, then labels the full resolution once (``FitConfig``'s
    #: ``stride``; 1 = every pixel). See docs/pipeline.md for speed and accuracy.
    track_stride: int = 2
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
    #: ... with this many template hypotheses besides the tracked pose and its
    #: swapped-limbs pose (a lost track searches with ``hypotheses``). On the shared
    #: sequences 2, 6 and all gave the same accuracy (docs/pipeline.md, session 9).
    recheck_hypotheses: int = 4
    #: Tracking: template hypotheses refined (besides the tracked pose and its
    #: swapped-limbs pose) when the track is lost; 20 takes all of them. On the shared
    #: sequences 8, 12 and all tracked equally well within the run-to-run spread of
    #: a track's path, and 8 cut the mean cost per frame by 13–18 % (docs/pipeline.md,
    #: session 10).
    lost_hypotheses: int = 8
    #: ... "clearly better": lower discrepancy by at least this share.
    switch_margin: float = 0.1
    #: Weight of the rest-pose term added to the depth discrepancy wherever poses
    #: compete (ranking the template hypotheses, choosing the final, a search's best
    #: against the tracked pose): ``pose_prior_weight`` × Σ θ² over the 14 limb angles
    #: (rad; 0 is the model's rest pose, arms down and legs straight); see
    #: :func:`rest_pose_penalty`. The depth cannot tell where a limb hidden behind
    #: the torso is, and a hypothesis that hides an ambiguous arm there (raised
    #: sideways, pointing away) scores as well as one that shows it: the term
    #: prefers the ordinary pose when the depth is silent. 0 turns it off. On the
    #: shared sequences (docs/pipeline.md, session 21) 0.005 tracked better from each
    #: of 7 start frames (mean MPJPE 41.2 → 38.6 mm) and left from-scratch estimates
    #: unchanged (59.6 mm).
    pose_prior_weight: float = 0.005
    #: Fitting settings passed to ``fit_pose`` as ``FitConfig`` keywords (None = defaults).
    fit: dict[str, Any] | None = None
    #: Tracking: subject shape calibration (see :class:`PoseTracker`): the body shape is
    #: fitted once (``fit_shape``) to this many usable frames and kept (0 = never).
    #: Only when the tracker is not told the shape (no ``model``) or is asked to
    #: (``calibrate=True``).
    calibration_frames: int = 8
    #: ... taking every this many usable frames (1 = consecutive; larger spreads the
    #: frames over more of the motion but calibrates later: on the shared sequences
    #: 2 was worse than 1, see docs/pipeline.md).
    calibration_every: int = 1
    #: ... with this weight of the prior toward the starting shape (``fit_shape``'s
    #: ``prior_weight``).
    calibration_prior_weight: float = 1e5
    #: ... and at most this many rounds (``fit_shape``'s ``iterations``).
    calibration_rounds: int = 3

    def validate(self) -> None:
        """Raises ``InvalidInputError`` naming the first nonsensical field."""

        def count(name: str, low: int) -> None:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < low:
                raise InvalidInputError(
                    f"{name}: expected an integer >= {low}, got {_validate.brief(v)}"
                )

        def real(name: str, low: float, high: float = np.inf, *, inf: bool = False) -> None:
            v = getattr(self, name)
            ok = isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
            ok = ok and (bool(np.isfinite(v)) or (inf and v == np.inf)) and low <= v <= high
            if not ok:
                what = "number (or inf)" if inf else "finite number"
                raise InvalidInputError(
                    f"{name}: expected a {what} in [{low}, {high}], got {_validate.brief(v)}"
                )

        count("candidates", 1)
        if self.candidates > 768:  # the template search's top_k
            raise InvalidInputError(
                f"candidates: expected 1..768, got {_validate.brief(self.candidates)}"
            )
        count("hypotheses", 0)
        count("finals", 1)
        count("candidate_iterations", 1)
        if self.final_iterations is not None:
            count("final_iterations", 1)
        count("track_iterations", 1)
        for name in ("track_stride", "candidate_stride", "final_stride"):
            count(name, 1)
            if getattr(self, name) > 8:
                raise InvalidInputError(f"{name}: expected 1..8, got {getattr(self, name)!r}")
        count("recheck_every", 0)
        count("recheck_hypotheses", 1)
        count("lost_hypotheses", 1)
        count("calibration_frames", 0)
        count("calibration_every", 1)
        count("calibration_rounds", 1)
        real("prior_weight", 0.0)
        real("velocity_damping", 0.0, 1.0)
        real("min_inlier_share", 0.0, 1.0)
        real("lost_ratio", 0.0, inf=True)
        real("lost_discrepancy", 0.0, inf=True)
        real("switch_margin", 0.0, 1.0)
        real("pose_prior_weight", 0.0)
        real("calibration_prior_weight", 0.0)


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
# The limb angles: shoulders (3 each), elbows, hips (2 each), knees.
_LIMB_ANGLES = np.r_[8:22]
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


def rest_pose_penalty(poses: np.ndarray, weight: float) -> np.ndarray:
    """``weight`` × Σ θ² over the 14 limb angles of each pose (rad; 0 is the rest
    pose: arms hanging, legs straight): a pose's distance from the ordinary, added to
    its :func:`depth_discrepancy` where poses compete. (N, 22) → (N,); (22,) → (1,)."""
    p = np.asarray(poses, np.float64).reshape(-1, 22)
    return weight * (p[:, _LIMB_ANGLES] ** 2).sum(axis=1)


def depth_discrepancy(
    model, pose: np.ndarray, depth: np.ndarray, mask: np.ndarray, camera: Camera,
    cap: float = 0.1,
) -> float:  # fmt: skip
    """How badly ``pose`` explains the observed body, from the depth data alone: the
    rendered body is compared with the foreground pixel by pixel; where both have depth
    the cost is the depth difference capped at ``cap`` metres, a foreground pixel with
    no body rendered or a rendered pixel outside the foreground costs ``cap``. The sum
    is divided by ``cap`` × the foreground pixel count: 0 = perfect, about 1 or more =
    unrelated. Unlike the silhouette, the depth tells the near limb from the far one.
    (``BodyModel.depth_discrepancies`` scores many poses at once, in parallel.)"""
    poses = np.asarray(pose, np.float64).reshape(1, -1)
    return float(model.depth_discrepancies(poses, depth, mask, camera, cap)[0])


def _model(model):
    from .body import BodyModel

    return BodyModel() if model is None else model


@functools.lru_cache(maxsize=8)
def _joint_part_matrix(part_names: tuple[str, ...]) -> np.ndarray:
    """(15, parts) 0/1: which of the model's parts belong to each joint's neighbourhood."""
    m = np.zeros((len(_JOINT_PARTS), len(part_names)), np.int64)
    for j, parts in enumerate(_JOINT_PARTS):
        for p in parts:
            if p in part_names:
                m[j, part_names.index(p)] = 1
    m.flags.writeable = False
    return m


def joint_confidence(model, pose, labels: np.ndarray, camera: Camera) -> np.ndarray:
    """Per-joint confidence: the share of the model's visible surface around the joint
    that the data labelled as that part (from a render of the fitted pose), zero for a
    joint outside the image."""
    _, rendered = model.render_depth(pose, camera)
    names = tuple(model.part_names)
    n_parts = len(names)
    seen = np.bincount(labels[labels >= 0].ravel(), minlength=n_parts)[:n_parts]
    expect = np.bincount(rendered[rendered >= 0].ravel(), minlength=n_parts)[:n_parts]
    parts = _joint_part_matrix(names)
    e, s = parts @ expect, parts @ seen  # integer sums: exact
    joints = model.joints(pose)
    uv = camera.project(joints)
    inside = (
        np.isfinite(uv).all(1)
        & (uv[:, 0] >= 0) & (uv[:, 0] < camera.width)
        & (uv[:, 1] >= 0) & (uv[:, 1] < camera.height)
    )  # fmt: skip
    # A hidden joint (nothing of its parts rendered) gets 0.3: only the kinematic chain.
    conf = np.where(e > 0, np.minimum(1.0, s / np.maximum(e, 1)), 0.3)
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
            raise InvalidTypeError(
                f"camera: expected a depthpose.Camera, got {type(camera).__name__}"
            )
        self.camera = camera
        from .body import BodyModel
        from .templates import TemplateDatabase

        if model is not None and not isinstance(model, BodyModel):
            raise InvalidTypeError(
                f"model: expected a depthpose.BodyModel or None, got {type(model).__name__}"
            )
        if templates is not None and not isinstance(templates, TemplateDatabase):
            raise InvalidTypeError(
                f"templates: expected a TemplateDatabase or None, got {type(templates).__name__}"
            )
        if background is not None:
            _validate.depth_image(background, "background")
            if background.shape != camera.shape:
                raise InvalidInputError(
                    f"background: shape {background.shape} does not match the camera's "
                    f"{camera.shape}"
                )
        self.model = _model(model)
        if config is not None and not isinstance(config, PipelineConfig):
            raise InvalidTypeError(
                f"config: expected a PipelineConfig, got {type(config).__name__}"
            )
        self.config = config or PipelineConfig()
        self.config.validate()
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
            # bool, or integers 0 and 1; anything else (a string array, floats) is
            # refused rather than cast to bool.
            shape = depth.shape if isinstance(depth, np.ndarray) else self.camera.shape
            return _validate.mask(mask, shape)
        return foreground_mask(depth, self.background)

    def _fit_config(self, iterations=None, stride=None, label_all_pixels=None):
        from .fit import FitConfig

        kwargs = dict(self.config.fit or {})
        if iterations is not None:
            kwargs["max_iterations"] = iterations
        if stride is not None:
            kwargs["stride"] = stride
        if label_all_pixels is not None:
            kwargs["label_all_pixels"] = label_all_pixels
        return FitConfig(**kwargs)

    def _fit(self, depth, mask, init, *, iterations=None, prior=None, stride=None, resume=None):
        from .fit import fit_pose

        return fit_pose(
            depth,
            self.camera,
            init,
            model=self.model,
            mask=mask,
            config=self._fit_config(iterations, stride),
            prior=prior,
            prior_weight=self.config.prior_weight,
            resume=resume,
        )

    def _fits(self, depth, mask, inits, *, iterations=None, stride=None, resume=None, brief=False):
        """:meth:`_fit` from each of ``inits``, in parallel (no prior). ``brief``: the
        fits are only ranked by pose or continued at the same stride, so a strided fit
        skips labelling every pixel (``FitConfig.label_all_pixels``)."""
        from .fit import fit_poses

        return fit_poses(
            depth,
            self.camera,
            np.asarray(inits, np.float64).reshape(-1, 22),
            model=self.model,
            mask=mask,
            config=self._fit_config(iterations, stride, False if brief else None),
            resume=resume,
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

    def discrepancies(self, poses, depth: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """:meth:`discrepancy` of each of ``poses``, rendered in parallel."""
        poses = np.asarray(poses, np.float64).reshape(-1, 22)
        return np.asarray(self.model.depth_discrepancies(poses, depth, mask, self.camera))

    def penalty(self, poses) -> np.ndarray:
        """:func:`rest_pose_penalty` of each of ``poses`` with ``config.pose_prior_weight``:
        what a pose's discrepancy is charged when poses compete."""
        return rest_pose_penalty(poses, self.config.pose_prior_weight)

    def hypotheses(self, depth: np.ndarray, mask: np.ndarray) -> list[np.ndarray]:
        """Start poses from the template search: each of the best ``candidates``
        templates, its left/right-swapped pose and the mirror images of both (the
        search cannot tell a side view's near limbs from its far ones, nor a view from
        its mirror image); near-duplicates dropped."""
        cands = self.templates.match(depth, self.camera, mask=mask, top_k=self.config.candidates)
        if not cands:
            raise NoBodyError("depth: no template matched the foreground")
        out: list[np.ndarray] = []
        seen = np.empty((4 * len(cands), 15, 3))  # joints of the poses kept so far
        for c in cands:
            p = np.asarray(c.pose, np.float64)
            for q in (p, swap_limbs(p), mirror_view(p), mirror_view(swap_limbs(p))):
                j = np.asarray(self.model.joints(q))
                kept = seen[: len(out)]
                if len(out) and (np.linalg.norm(kept - j, axis=2).mean(axis=1) < 0.03).any():
                    continue
                seen[len(out)] = j
                out.append(q)
        return out

    def search(self, depth, mask, *, extra=(), timings=None, hypotheses=None, label=True):
        """Best fit from the template hypotheses (and ``extra`` start poses, always
        refined): the best ``hypotheses`` (default ``config.hypotheses``) by their depth
        discrepancy (no ranking when that is all of them) refined briefly by EM (in
        parallel), the ``finals`` explaining the depth best refined
        fully (their EM continued, in parallel), the best of all kept. Returns the fit and
        its discrepancy. Poses are compared by discrepancy plus :meth:`penalty`.
        ``label=False``: a final comes back with the labels of its EM only (at every
        ``final_stride``-th pixel); :meth:`label_all` completes it."""
        starts = self.hypotheses(depth, mask)
        if timings is not None:
            timings["templates"] = time.perf_counter()
        n = max(1, self.config.hypotheses if hypotheses is None else hypotheses)
        if n < len(starts):
            ranking = self.discrepancies(starts, depth, mask) + self.penalty(starts)
            order = np.argsort(ranking, kind="stable")
            starts = [starts[i] for i in order[:n]]
        # (When all are refined, ranking them first would only reorder the fits.)
        chosen = [*list(extra), *starts]
        # Candidates continued at their own stride need no labels beyond their EM's.
        brief = self.config.candidate_stride == self.config.final_stride
        fits = self._fits(
            depth,
            mask,
            chosen,
            iterations=self.config.candidate_iterations,
            stride=self.config.candidate_stride,
            brief=brief,
        )
        poses = [f.pose for f in fits]
        scores = self.discrepancies(poses, depth, mask)
        ranking = scores + self.penalty(poses)
        order = np.argsort(ranking, kind="stable")[: self.config.finals]
        best, best_score = fits[order[0]], float(scores[order[0]])
        best_rank = float(ranking[order[0]])
        # The best candidates' EM goes on where their brief fits stopped (same labels,
        # the outlier distance still annealing) rather than starting over.
        winners = [fits[i] for i in order]
        # The finals are ranked by pose too: only the one kept is labelled at every pixel.
        finals = self._fits(
            depth,
            mask,
            [f.pose for f in winners],
            resume=winners,
            iterations=self.config.final_iterations,
            stride=self.config.final_stride,
            brief=True,
        )
        poses = [f.pose for f in finals]
        final_scores = self.discrepancies(poses, depth, mask)
        final_ranking = final_scores + self.penalty(poses)
        k = int(np.argmin(final_ranking))
        # (A brief candidate's labels cover only its own pixels: a final is kept then.)
        if brief or final_ranking[k] <= best_rank:
            best, best_score = finals[k], float(final_scores[k])
            if label:
                best = self.label_all(depth, mask, best)
        return best, best_score

    def label_all(self, depth, mask, fit):
        """``fit``, a final of :meth:`search` (at ``final_stride``), labelled at every
        pixel: what the fit itself would have returned with ``label_all_pixels``."""
        from .fit import label_all_pixels

        config = self._fit_config(None, self.config.final_stride)
        if not config.label_all_pixels:
            return fit
        return label_all_pixels(depth, self.camera, fit, model=self.model, mask=mask, config=config)

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
    """Pose through a depth video: each :meth:`update` starts from the previous pose.

    **Subject shape calibration.** Unless told the shape, the tracker refines the body
    shape over its first frames and keeps it: it collects every
    ``config.calibration_every``-th *usable* frame until it has
    ``config.calibration_frames`` of them, then runs :func:`~depthpose.fit_shape` once on
    their depth, masks and poses (prior weight ``config.calibration_prior_weight``),
    which refits every frame's pose and labels with the shape, and tracks with the
    calibrated model from the next frame on (continuing from the calibrated pose of the
    frame). Usable: any frame but a track's first (the template search alone) whose
    result explains at least ``min_inlier_share`` of the foreground points, whether
    tracked, kept after a search or switched. Not only the frames that passed the
    lost-track test: with a wrong shape the depth discrepancy exceeds the absolute
    threshold on most frames, so waiting for those left half the shared sequences
    uncalibrated (docs/pipeline.md). The frame that completes the collection takes the
    calibration's time (``timings["calibration"]``; about 1.5–3 s for 8 frames on an
    idle 2-core machine).

    ``calibrate``: None (default) calibrates when no ``model`` is given (the shape is
    unknown) and ``config.calibration_frames > 0``; a given ``model`` is taken as the
    subject's known shape and kept. ``True`` calibrates a given model too (e.g. one
    scaled from a known height); ``False`` never calibrates.

    A calibration that fails (``DepthPoseError`` from ``fit_shape``) leaves the model
    as it was; the error is in :attr:`calibration_error` and it is not retried.
    :meth:`reset` forgets the track but keeps the calibrated shape (the same subject);
    ``reset(shape=True)`` also restores the starting model and calibrates again.
    """

    def __init__(
        self,
        camera: Camera,
        *,
        model=None,
        templates=None,
        config: PipelineConfig | None = None,
        background: np.ndarray | None = None,
        calibrate: bool | None = None,
    ) -> None:
        if calibrate is not None and not isinstance(calibrate, (bool, np.bool_)):
            raise InvalidInputError(
                f"calibrate: expected True, False or None, got {type(calibrate).__name__}"
            )
        self.estimator = PoseEstimator(
            camera, model=model, templates=templates, config=config, background=background
        )
        #: The model the tracker started with (calibration starts from it).
        self.base_model = self.estimator.model
        self._calibrate = (model is None) if calibrate is None else bool(calibrate)
        self.reset(shape=True)

    @property
    def model(self):
        return self.estimator.model

    @property
    def config(self) -> PipelineConfig:
        return self.estimator.config

    @property
    def calibrating(self) -> bool:
        """Whether the tracker is still collecting frames to calibrate the shape."""
        return (
            self._calibrate
            and self.config.calibration_frames > 0
            and not self.calibrated
            and self.calibration_error is None
        )

    def reset(self, shape: bool = False) -> None:
        """Forget the track. The calibrated shape is kept (the same subject) unless
        ``shape`` is true: then the starting model is restored and, if calibration is
        on, the shape is calibrated again over the next frames."""
        self._prev: np.ndarray | None = None
        self._prev2: np.ndarray | None = None
        self._recent: list[float] = []
        self._since_check = 0
        self.lost_frames = 0
        self.switches = 0
        if shape:
            # Frames kept for the calibration survive a plain reset (the subject is the
            # same).
            self._calib_buffer: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
            self._calib_seen = 0
            self.estimator.model = self.base_model
            #: Whether the model was calibrated (``model`` is then the calibrated one).
            self.calibrated = False
            #: Shape factors (12,) of the calibrated model relative to
            #: :attr:`base_model` (``BodyModel.shape_factor_names`` order); None before.
            self.shape_factors: np.ndarray | None = None
            #: The ``fit_shape`` result of the calibration (None before).
            self.calibration = None
            #: Why the calibration failed (the ``DepthPoseError`` message), else None.
            self.calibration_error: str | None = None
            #: Frames :meth:`update` had been given when the calibration ran.
            self.calibration_frame: int | None = None
            self._frames = 0

    def start_from(self, pose: np.ndarray) -> None:
        """Starts the track from a known pose (the next :meth:`update` refines it
        instead of searching the templates)."""
        pose = np.asarray(pose, np.float64)
        if pose.shape != (22,) or not np.isfinite(pose).all():
            raise InvalidInputError(f"pose: expected 22 finite values, got shape {pose.shape}")
        self.reset()
        self._prev = pose.copy()

    def _explains_enough(self, labels, mask) -> bool:
        """At least ``min_inlier_share`` of the foreground is labelled as body."""
        n = int(np.asarray(mask).sum())
        inliers = int((np.asarray(labels) >= 0).sum())
        return n > 0 and inliers >= self.config.min_inlier_share * n

    def _lost(self, fit, mask: np.ndarray, score: float) -> bool:
        if not self._explains_enough(fit.labels, mask):
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

    def _collect(self, depth: np.ndarray, mask: np.ndarray, res: PoseResult) -> None:
        """Keeps a usable frame for the calibration; runs it when there are enough."""
        cfg = self.config
        self._calib_seen += 1
        if (self._calib_seen - 1) % cfg.calibration_every:
            return
        # uint16 frames are millimetres; keep metres so that frames of either kind stack.
        metres = depth / 1000.0 if depth.dtype == np.uint16 else depth
        self._calib_buffer.append((np.array(metres, np.float32), mask.copy(), res.pose.copy()))
        if len(self._calib_buffer) < cfg.calibration_frames:
            return
        from . import fit as _fit

        t0 = time.perf_counter()
        depths, masks, poses = (np.stack(v) for v in zip(*self._calib_buffer, strict=True))
        self._calib_buffer = []
        self.calibration_frame = self._frames
        try:
            r = _fit.fit_shape(
                depths,
                self.estimator.camera,
                poses,
                model=self.base_model,
                masks=masks,
                iterations=cfg.calibration_rounds,
                config=cfg.fit,
                prior_weight=cfg.calibration_prior_weight,
            )
        except DepthPoseError as e:
            self.calibration_error = f"{type(e).__name__}: {e}"
        else:
            self.estimator.model = r.model
            self.calibrated = True
            self.calibration = r
            self.shape_factors = np.asarray(r.factors, np.float64).copy()
            # Continue from this frame's pose under the calibrated shape; the velocity
            # and the discrepancy history belong to the old shape.
            self._prev = np.asarray(r.poses[-1], np.float64).copy()
            self._prev2 = None
            self._recent = []
        res.timings["calibration"] = 1000 * (time.perf_counter() - t0)
        res.timings["total"] += res.timings["calibration"]

    def update(self, depth: np.ndarray, mask: np.ndarray | None = None) -> PoseResult:
        """The pose of the next frame. A lost track is re-initialised from the
        templates; every ``recheck_every`` frames the template hypotheses and the
        swapped-limbs pose of the track compete with the tracked pose, and the track
        switches when one explains the depth clearly better. While calibrating, a
        usable frame may be kept for (and complete) the shape calibration."""
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
            fit = est._fit(
                depth,
                m,
                pred,
                iterations=cfg.track_iterations,
                prior=pred,
                stride=cfg.track_stride,
            )
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
                best, best_score = est.search(
                    depth,
                    m,
                    extra=[pose, swap_limbs(pose)],
                    hypotheses=cfg.lost_hypotheses if lost else cfg.recheck_hypotheses,
                    label=False,
                )
                margin = 0.0 if lost else cfg.switch_margin
                rank_best = best_score + float(est.penalty(best.pose)[0])
                rank_track = score + float(est.penalty(fit.pose)[0])
                switch = rank_best < rank_track * (1.0 - margin)
                if switch:
                    best = est.label_all(depth, m, best)
                t2["search"] = time.perf_counter()
                if switch:
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
        self._frames += 1
        first = self._prev is None
        if switched:
            self.switches += self._prev is not None
            self._prev2 = None
            self._recent = []
        else:
            self._prev2 = self._prev
        self._prev = res.pose.copy()
        if np.isfinite(res.discrepancy):
            self._recent = [*self._recent[-14:], res.discrepancy]
        if self.calibrating and not first and self._explains_enough(res.labels, mask):
            self._collect(np.asarray(depth), np.asarray(mask, bool), res)
        return res


@dataclass
class FramesResult:
    """Per-frame results of a sequence; failed frames are NaN with their error."""

    joints: np.ndarray  # (T, 15, 3)
    pose: np.ndarray  # (T, 22)
    confidence: np.ndarray  # (T, 15)
    errors: list[dict[str, Any]]  # {"frame": index, "error": message}
    seconds: list[float] = field(default_factory=list)
    #: Tracked: the calibrated shape factors (see :class:`PoseTracker`), else None.
    shape_factors: np.ndarray | None = None
    #: Tracked: why the shape calibration failed, else None.
    calibration_error: str | None = None
    #: Tracked: the frame (index in ``frames`` + ``first_frame``) whose update ran the
    #: calibration (attempted), else None.
    calibration_frame: int | None = None


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
    calibrate: bool | None = None,
) -> FramesResult:
    """Poses of frames (T, H, W); the first ``warmup`` frames only prime the tracker and
    are not returned. A frame that raises is recorded as NaN and the loop goes on.
    ``calibrate``: the tracker's shape calibration (see :class:`PoseTracker`); the
    tracker's calibration outcome is in ``FramesResult.shape_factors`` /
    ``calibration_error``."""
    if isinstance(frames, (list, tuple)):
        try:
            frames = np.asarray(frames)
        except (ValueError, TypeError):
            raise InvalidInputError("frames: not a stack of equally sized depth images") from None
    if not isinstance(frames, np.ndarray):
        raise InvalidTypeError(f"frames: expected a numpy array, got {type(frames).__name__}")
    if frames.ndim != 3:
        raise InvalidInputError(f"frames: expected (T, H, W), got shape {frames.shape}")
    if frames.dtype.kind not in "fu":
        raise (InvalidTypeError if frames.dtype.kind in "OUSV" else InvalidInputError)(
            f"frames: depth must be float metres or uint16 millimetres, got dtype {frames.dtype}"
        )
    warmup = _validate.integer(warmup, "warmup", low=0, high=frames.shape[0])
    first_frame = _validate.integer(first_frame, "first_frame", low=0)
    if not isinstance(track, (bool, np.bool_)):
        raise InvalidTypeError(f"track: expected True or False, got {type(track).__name__}")
    if on_frame is not None and not callable(on_frame):
        raise InvalidTypeError(f"on_frame: expected a callable, got {type(on_frame).__name__}")
    n = frames.shape[0] - warmup
    if n < 0:
        raise InvalidInputError(f"warmup: {warmup} exceeds the {frames.shape[0]} frames")
    out = FramesResult(np.full((n, 15, 3), np.nan), np.full((n, 22), np.nan), np.zeros((n, 15)), [])
    if track:
        tracker = PoseTracker(camera, model=model, templates=templates, config=config,
                              background=background, calibrate=calibrate)  # fmt: skip
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
        if track and out.calibration_frame is None and tracker.calibration_frame is not None:
            out.calibration_frame = first_frame + k
        if k >= warmup:
            out.joints[k - warmup] = res.joints
            out.pose[k - warmup] = res.pose
            out.confidence[k - warmup] = res.confidence
            out.seconds.append(time.perf_counter() - t0)
            if on_frame is not None:
                on_frame(first_frame + k, res)
    if track:
        out.shape_factors = tracker.shape_factors
        out.calibration_error = tracker.calibration_error
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
    background: np.ndarray | None = None,
    mask: np.ndarray | None = None,
) -> PoseResult:
    """The paper's real-data path: a rectified pair → GCS disparity → depth → pose.

    ``camera`` is the left camera (its fx is the focal length in pixels); ``baseline`` in
    metres; ``doffs`` the principal-point offset between the cameras (Middlebury style).
    The person is found like in a depth image (:func:`~depthpose.foreground_mask`):
    ``background`` is the empty scene's depth (H, W) in metres, e.g. the depth of a pair
    taken without the person (``stereo.depth_from_disparity(stereo.match(...))``), and
    what lies clearly in front of it is the person; ``mask`` gives the person's pixels
    directly. Without either, the estimator's own background (``estimator``'s) or the
    nearest large body in range is used. The result's ``timings`` include ``stereo``
    (matching and depth, ms).
    """
    from . import stereo

    if not isinstance(camera, Camera):
        raise InvalidInputError(f"camera: expected a depthpose.Camera, got {type(camera).__name__}")
    number = isinstance(baseline, (int, float, np.integer, np.floating))
    if isinstance(baseline, bool) or not number:
        raise InvalidTypeError(
            f"baseline: expected a number of metres, got {_validate.type_name(baseline)}"
        )
    if not (np.isfinite(baseline) and baseline > 0):
        raise InvalidInputError(f"baseline: must be finite and > 0 metres, got {baseline}")
    if mask is not None and background is not None:
        raise InvalidInputError("mask: give either mask or background, not both")
    t0 = time.perf_counter()
    disparity = stereo.match(left, right, max_disparity=max_disparity)
    depth = stereo.depth_from_disparity(disparity, camera.fx, float(baseline), doffs)
    depth = np.ascontiguousarray(depth, np.float32)
    if depth.shape != camera.shape:
        raise InvalidInputError(
            f"left: image is {depth.shape[1]}x{depth.shape[0]}, camera is "
            f"{camera.width}x{camera.height}"
        )
    t_stereo = 1000 * (time.perf_counter() - t0)
    est = estimator or PoseEstimator(camera)
    if background is not None:
        mask = foreground_mask(depth, np.ascontiguousarray(background, np.float32))
    elif mask is not None:
        mask = np.asarray(mask)
        if mask.shape != depth.shape:
            raise InvalidInputError(f"mask: expected shape {depth.shape}, got {mask.shape}")
    res = est.estimate(depth, mask)
    res.timings = {"stereo": t_stereo, **res.timings}
    res.timings["total"] = res.timings.get("total", 0.0) + t_stereo
    return res
