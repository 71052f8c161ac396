"""Exports: the fitted body as a mesh (trimesh: PLY, glTF/GLB, OBJ, STL), a tracked
sequence as BVH for animation tools, and results as JSON lines."""

from __future__ import annotations

import json
import os
from typing import TYPE_CHECKING, Any, Union, cast

import numpy as np

from . import _validate
from ._core import BodyModel, InvalidInputError, InvalidTypeError, _euler_zxy

if TYPE_CHECKING:
    import trimesh

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["body_mesh", "save_mesh", "write_bvh", "write_jsonl", "BVH_PARENTS"]

#: Parent of each body segment (part order of the body model); None = the root.
BVH_PARENTS = {
    "pelvis": None, "torso": "pelvis", "neck": "torso", "head": "neck",
    "r_upper_arm": "torso", "r_forearm": "r_upper_arm", "r_hand": "r_forearm",
    "l_upper_arm": "torso", "l_forearm": "l_upper_arm", "l_hand": "l_forearm",
    "r_thigh": "pelvis", "r_shin": "r_thigh", "r_foot": "r_shin",
    "l_thigh": "pelvis", "l_shin": "l_thigh", "l_foot": "l_shin",
}  # fmt: skip

#: The BVH joint name of each body segment: the names animation tools map by default
#: (Blender, MotionBuilder, Mixamo-style retargeting); Left and Right are the subject's.
BVH_NAMES = {
    "pelvis": "Hips", "torso": "Spine", "neck": "Neck", "head": "Head",
    "r_upper_arm": "RightArm", "r_forearm": "RightForeArm", "r_hand": "RightHand",
    "l_upper_arm": "LeftArm", "l_forearm": "LeftForeArm", "l_hand": "LeftHand",
    "r_thigh": "RightUpLeg", "r_shin": "RightLeg", "r_foot": "RightFoot",
    "l_thigh": "LeftUpLeg", "l_shin": "LeftLeg", "l_foot": "LeftFoot",
}  # fmt: skip

# Pose parameters and joints (ITOP order) of each leg: hip (2) and knee (1); the joints
# whose confidence tells whether the leg was seen.
_LEGS = (((16, 17, 18), (9, 11, 13)), ((19, 20, 21), (10, 12, 14)))

# Exports are y-up, as Blender, three.js, glTF and BVH expect; the camera frame is
# y-down, z-forward (OpenCV). Turning 180° about x maps (x, y, z) to (x, -y, -z).
_FLIP = np.diag([1.0, -1.0, -1.0])


def _model(model: object) -> BodyModel:
    if not isinstance(model, BodyModel):
        raise InvalidTypeError(f"model: expected a depthpose.BodyModel, got {type(model).__name__}")
    return model


def _path(path: object) -> str:
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidTypeError(f"path: expected a path (str or os.PathLike), got {type(path)}")
    return os.fspath(path)


def body_mesh(
    model: BodyModel, pose: np.ndarray, *, rings: int = 20, sectors: int = 24
) -> trimesh.Trimesh:
    """The posed super-quadric body as one ``trimesh.Trimesh`` (camera frame, metres),
    each segment's faces coloured by part."""
    import trimesh

    from .viz import PART_COLORS

    model = _model(model)
    parts = []
    for k, (v, f) in enumerate(model.superquadric_meshes(pose, rings, sectors)):
        rgba = np.append(PART_COLORS[k % len(PART_COLORS)], 255).astype(np.uint8)
        colors = np.tile(rgba, (len(f), 1))
        parts.append(trimesh.Trimesh(vertices=v, faces=f, face_colors=colors, process=False))
    # Joined meshes are a mesh (concatenate is typed for any geometry).
    return cast(trimesh.Trimesh, trimesh.util.concatenate(parts))


def save_mesh(path: PathLike, model: BodyModel, pose: np.ndarray, *, y_up: bool = True) -> None:
    """Writes the posed body; the format follows the suffix (.ply, .glb, .gltf, .obj,
    .stl). The mesh is y-up (the camera frame turned 180° about x: (x, -y, -z)), as
    Blender, three.js and glTF expect; ``y_up=False`` writes the camera frame (x right,
    y down, z forward). A ``.gltf`` holds its buffers inside (base64), so it is one
    self-contained file and exports side by side do not overwrite each other."""
    path = _path(path)
    suffix = path.rsplit(".", 1)[-1].lower()
    if suffix not in ("ply", "glb", "gltf", "obj", "stl"):
        raise InvalidInputError(f"path: unknown mesh format .{suffix} (ply, glb, gltf, obj, stl)")
    if not isinstance(y_up, (bool, np.bool_)):
        raise InvalidTypeError(f"y_up: expected True or False, got {type(y_up).__name__}")
    mesh = body_mesh(model, pose)
    if y_up:
        transform = np.eye(4)
        transform[:3, :3] = _FLIP
        mesh.apply_transform(transform)
    if suffix == "gltf":
        from trimesh.exchange.gltf import export_gltf

        # trimesh's exporter is untyped: it returns {file name: bytes}.
        files = export_gltf(mesh.scene(), embed_buffers=True)  # type: ignore[no-untyped-call]
        with open(path, "wb") as f:
            f.write(files["model.gltf"])
    else:
        mesh.export(path)


def _end_sites(model: BodyModel, names: list[str]) -> dict[str, np.ndarray]:
    """The End Site offset of each segment at the rest pose, y-up: where a ray from the
    segment's joint leaves its ellipsoid (the top of the head, the tips of the hands and
    feet). The ray runs through the ellipsoid's centre when that lies ahead along the
    chain, else straight on along the chain (the head, centred near its joint)."""
    rest = np.zeros(22)
    frames = np.asarray(model.segment_transforms(rest))
    centres, rotations, radii = (np.asarray(a) for a in model.ellipsoids(rest))
    out = {}
    for k, n in enumerate(names):
        origin = frames[k, :3, 3]
        parent = BVH_PARENTS[n]
        chain = origin - frames[names.index(parent), :3, 3] if parent else np.zeros(3)
        d = centres[k] - origin
        if d @ chain <= 0 and np.linalg.norm(chain) > 1e-9:
            d = chain
        if np.linalg.norm(d) < 1e-9:  # a lone segment centred on its joint: its long axis
            d = rotations[k][:, int(np.argmax(radii[k]))]
        d = d / np.linalg.norm(d)
        # |A (origin + t d - centre)| = 1 with A mapping the ellipsoid to the unit sphere.
        to_unit = rotations[k].T / radii[k][:, None]
        a, b = to_unit @ d, to_unit @ (origin - centres[k])
        disc = (a @ b) ** 2 - (a @ a) * (b @ b - 1.0)
        t = (-(a @ b) + np.sqrt(max(disc, 0.0))) / (a @ a)
        out[n] = _FLIP @ (max(t, 0.0) * d)
    return out


def write_bvh(
    path: PathLike,
    model: BodyModel,
    poses: np.ndarray,
    fps: float = 30.0,
    *,
    confidence: np.ndarray | None = None,
) -> None:
    """Writes a tracked sequence (T, 22) as BVH at ``fps`` frames per second, y up
    (x = the subject's left, z = towards the camera at the rest pose), metres.

    One joint per body segment at its proximal joint, named as animation tools expect
    (:data:`BVH_NAMES`: Hips, Spine, Neck, Head, LeftArm, LeftForeArm, LeftHand,
    LeftUpLeg, LeftLeg, LeftFoot, and the Right ones); each chain ends in an End Site at
    the far end of its segment. The rest pose is all joint angles zero (segments
    parallel to the body frame). A failed frame (a pose of 22 NaN, as the estimators
    record it) repeats the previous frame; a pose with some NaN or any infinite value is
    refused. ``confidence`` (T, 15), the estimators' per-joint confidence: a leg whose
    hip, knee and foot all have confidence 0 in a frame (not seen) is written at rest
    in that frame rather than with invented angles."""
    path = _path(path)
    model = _model(model)
    fps = _validate.number(fps, "fps", low=0.0, low_open=True, high=1e6)
    arr = _validate.array(np.asarray(poses) if isinstance(poses, (list, tuple)) else poses, "poses")
    why = _validate._not_numbers(arr.dtype)
    if why is not None:
        raise (InvalidInputError if arr.dtype.kind == "b" else InvalidTypeError)(
            f"poses: dtype {arr.dtype}: {why}"
        )
    poses = arr.astype(np.float64)
    if poses.ndim != 2 or poses.shape[1] != 22 or len(poses) == 0:
        raise InvalidInputError(f"poses: expected (T, 22), got shape {poses.shape}")
    if np.isinf(poses).any():
        raise InvalidInputError("poses: holds an infinite value")
    nan = np.isnan(poses)
    partial = nan.any(axis=1) & ~nan.all(axis=1)
    if partial.any():
        k = int(np.flatnonzero(partial)[0])
        raise InvalidInputError(
            f"poses[{k}]: some parameters are NaN, not all (a failed frame is all NaN)"
        )
    if nan.all():
        raise InvalidInputError("poses: every frame is NaN")
    if confidence is not None:
        conf = _validate.numbers_array(confidence, "confidence").astype(np.float64)
        if conf.shape != (len(poses), 15):
            raise InvalidInputError(
                f"confidence: expected shape ({len(poses)}, 15), got {conf.shape}"
            )
        poses = poses.copy()
        for params, joints in _LEGS:
            unseen = (conf[:, joints] == 0).all(axis=1) & np.isfinite(poses).all(axis=1)
            poses[np.ix_(unseen, params)] = 0.0
    names = list(model.part_names)
    rest = np.zeros(22)
    rest_frames = np.asarray(model.segment_transforms(rest))
    origin = {n: _FLIP @ rest_frames[k, :3, 3] for k, n in enumerate(names)}
    ends = _end_sites(model, names)
    children: dict[str | None, list[str]] = {}
    for n in names:
        children.setdefault(BVH_PARENTS[n], []).append(n)
    order: list[str] = []
    lines = ["HIERARCHY"]

    def emit(name: str, depth: int) -> None:
        pad = "  " * depth
        parent = BVH_PARENTS[name]
        off = origin[name] - (origin[parent] if parent else origin[name])
        kind = "ROOT" if parent is None else "JOINT"
        lines.append(f"{pad}{kind} {BVH_NAMES[name]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}")
        if parent is None:
            lines.append(f"{pad}  CHANNELS 6 Xposition Yposition Zposition "
                         "Zrotation Xrotation Yrotation")  # fmt: skip
        else:
            lines.append(f"{pad}  CHANNELS 3 Zrotation Xrotation Yrotation")
        order.append(name)
        kids = children.get(name, [])
        for c in kids:
            emit(c, depth + 1)
        if not kids:
            lines.append(f"{pad}  End Site")
            lines.append(f"{pad}  {{")
            e = ends[name]
            lines.append(f"{pad}    OFFSET {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}")
            lines.append(f"{pad}  }}")
        lines.append(f"{pad}}}")

    emit(children[None][0], 0)
    lines += ["MOTION", f"Frames: {len(poses)}", f"Frame Time: {1.0 / fps:.6f}"]
    last = poses[np.isfinite(poses).all(1)][0]
    for pose in poses:
        if np.isfinite(pose).all():
            last = pose
        frames = np.asarray(model.segment_transforms(last))
        world = {n: _FLIP @ frames[k, :3, :3] @ _FLIP for k, n in enumerate(names)}
        vals: list[float] = []
        for n in order:
            parent = BVH_PARENTS[n]
            if parent is None:
                t = _FLIP @ frames[names.index(n), :3, 3]
                vals += list(t)
                local = world[n]
            else:
                local = world[parent].T @ world[n]
            vals += list(_euler_zxy(local))
        lines.append(" ".join(f"{v:.6f}" for v in vals))
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def write_jsonl(path: PathLike, results: list[Any]) -> None:
    """One JSON line per frame: a ``PoseResult`` (anything with ``to_dict()``) or None
    for a failed frame."""
    path = _path(path)
    results = list(results)
    for k, r in enumerate(results):
        if r is not None and not callable(getattr(r, "to_dict", None)):
            raise InvalidTypeError(
                f"results[{k}]: expected a PoseResult or None, got {type(r).__name__}"
            )
    with open(path, "w") as f:
        for k, r in enumerate(results):
            rec = {"frame": k, **r.to_dict()} if r is not None else {"frame": k, "joints": None}
            f.write(json.dumps(rec) + "\n")
