"""Exports: the fitted body as a mesh (trimesh: PLY, glTF/GLB, OBJ, STL), a tracked
sequence as BVH for animation tools, and results as JSON lines."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Union, cast

import numpy as np

from ._core import (
    BVH_NAMES,
    BVH_PARENTS,
    BodyModel,
    InvalidInputError,
    InvalidTypeError,
    write_bvh,
    write_jsonl,
)

if TYPE_CHECKING:
    import trimesh

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["body_mesh", "save_mesh", "write_bvh", "write_jsonl", "BVH_PARENTS", "BVH_NAMES"]

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
