"""The articulated body model (16 ellipsoid segments, 22 pose parameters).

`BodyModel` is the native class; this module adds trimesh conveniences. Frames and
parameters: the body frame sits at the hip centre with x = the subject's left, y = down,
z = the subject's back; the neutral pose (zero root rotation) faces the camera. Pose
order: root translation (3), root rotation vector (3), neck (2), right shoulder (3),
right elbow, left shoulder (3), left elbow, right hip (2), right knee, left hip (2),
left knee. Jacobian columns 3..6 are body-frame rotation increments (R <- R exp([w]x));
apply a step with `BodyModel.pose_with_root_increment`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, cast

import numpy as np

from depthpose import _validate
from depthpose._core import BodyModel, InvalidTypeError

if TYPE_CHECKING:
    import trimesh

__all__ = ["BodyModel", "body_trimesh", "ellipsoid_trimeshes"]


#: Most icosphere subdivisions of :func:`ellipsoid_trimeshes` (20 · 4**6 faces each).
MAX_SUBDIVISIONS = 6


def _check_model(model: object) -> None:
    if not isinstance(model, BodyModel):
        raise InvalidTypeError(f"model: expected a depthpose.BodyModel, got {type(model).__name__}")


def body_trimesh(
    model: BodyModel, pose: np.ndarray, rings: int = 20, sectors: int = 24
) -> trimesh.Trimesh:
    """All super-quadric segment meshes of `pose` joined into one `trimesh.Trimesh`
    (camera frame); `face_attributes['part']` holds each face's segment label."""
    import trimesh

    _check_model(model)
    parts = model.superquadric_meshes(pose, rings, sectors)
    meshes = [trimesh.Trimesh(v, f, process=False) for v, f in parts]
    labels = np.concatenate([np.full(len(f), k, np.int16) for k, (_, f) in enumerate(parts)])
    # Joined meshes are a mesh (concatenate is typed for any geometry).
    joined = cast(trimesh.Trimesh, trimesh.util.concatenate(meshes))
    joined.face_attributes["part"] = labels
    return joined


def ellipsoid_trimeshes(
    model: BodyModel, pose: np.ndarray, subdivisions: int = 4
) -> list[trimesh.Trimesh]:
    """The fitting ellipsoids of `pose` as `trimesh` icospheres scaled and placed in the
    camera frame (one per segment, label order)."""
    import trimesh

    _check_model(model)
    subdivisions = _validate.integer(subdivisions, "subdivisions", low=0, high=MAX_SUBDIVISIONS)
    centres, rotations, radii = model.ellipsoids(pose)
    out = []
    for c, r, e in zip(centres, rotations, radii, strict=False):
        sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
        v = (sphere.vertices * e) @ r.T + c
        out.append(trimesh.Trimesh(v, sphere.faces, process=False))
    return out
