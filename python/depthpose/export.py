"""Exports: the fitted body as a mesh (trimesh: PLY, glTF/GLB, OBJ, STL), a tracked
sequence as BVH for animation tools, and results as JSON lines."""

from __future__ import annotations

import json
import os
from typing import TYPE_CHECKING, Any, Union, cast

import numpy as np

from . import _validate
from ._core import BodyModel, InvalidInputError, InvalidTypeError

if TYPE_CHECKING:
    import trimesh

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["body_mesh", "save_mesh", "write_bvh", "write_jsonl", "BVH_PARENTS"]

#: Parent of each body segment (part order of the body model); -1 = the root.
BVH_PARENTS = {
    "pelvis": None, "torso": "pelvis", "neck": "torso", "head": "neck",
    "r_upper_arm": "torso", "r_forearm": "r_upper_arm", "r_hand": "r_forearm",
    "l_upper_arm": "torso", "l_forearm": "l_upper_arm", "l_hand": "l_forearm",
    "r_thigh": "pelvis", "r_shin": "r_thigh", "r_foot": "r_shin",
    "l_thigh": "pelvis", "l_shin": "l_thigh", "l_foot": "l_shin",
}  # fmt: skip

# BVH files are y-up; our frames are y-down, z-forward: turn 180° about x.
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


def save_mesh(path: PathLike, model: BodyModel, pose: np.ndarray) -> None:
    """Writes the posed body; the format follows the suffix (.ply, .glb, .gltf, .obj, .stl)."""
    suffix = _path(path).rsplit(".", 1)[-1].lower()
    if suffix not in ("ply", "glb", "gltf", "obj", "stl"):
        raise InvalidInputError(f"path: unknown mesh format .{suffix} (ply, glb, gltf, obj, stl)")
    body_mesh(model, pose).export(os.fspath(path))


def _euler_zxy(r: np.ndarray) -> tuple[float, float, float]:
    """Angles (z, x, y) in degrees with r = Rz(z) @ Rx(x) @ Ry(y)."""
    x = np.arcsin(np.clip(r[2, 1], -1.0, 1.0))
    if abs(r[2, 1]) < 1 - 1e-9:
        z = np.arctan2(-r[0, 1], r[1, 1])
        y = np.arctan2(-r[2, 0], r[2, 2])
    else:  # gimbal lock: put everything in z
        z = np.arctan2(r[1, 0], r[0, 0])
        y = 0.0
    return float(np.degrees(z)), float(np.degrees(x)), float(np.degrees(y))


def _rot(axis: str, deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def write_bvh(path: PathLike, model: BodyModel, poses: np.ndarray, fps: float = 30.0) -> None:
    """Writes a tracked sequence (T, 22) as BVH at ``fps`` frames per second: one
    joint per body segment at its proximal joint, the rest pose being all joint angles
    zero (segments parallel to the body frame), y up, metres. A failed frame (a pose of
    22 NaN, as the estimators record it) repeats the previous frame; a pose with some
    NaN or any infinite value is refused."""
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
    names = list(model.part_names)
    rest = np.zeros(22)
    rest_frames = np.asarray(model.segment_transforms(rest))
    origin = {n: _FLIP @ rest_frames[k, :3, 3] for k, n in enumerate(names)}
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
        lines.append(f"{pad}{kind} {name}")
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
            lines.append(f"{pad}    OFFSET 0.000000 0.000000 0.000000")
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
