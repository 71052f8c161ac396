"""The template database that finds the initial pose (paper Section II-C).

768 templates (4 poses per arm and per leg, 3 views) rendered from the super-quadric
body and described by surface contexts. :class:`TemplateDatabase` and
:class:`Candidate` are the native classes; ``TemplateDatabase.match`` returns candidate
poses placed at the observed body, and the fitting stage refines the best few. This
module holds the ``renderer="trimesh"`` ray casting the native builder calls.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._core import Camera, Candidate, TemplateDatabase, surface_context

__all__ = [
    "ARM_POSES",
    "LEG_POSES",
    "VIEWS",
    "Candidate",
    "TemplateDatabase",
    "surface_context",
]

ARM_POSES = TemplateDatabase.ARM_POSES
LEG_POSES = TemplateDatabase.LEG_POSES
VIEWS = TemplateDatabase.VIEWS


def _raycast_depths(
    count: int, shape: np.ndarray, camera: Camera, distance: float, bar: Any
) -> np.ndarray:
    """Depth images (count, H, W) of the templates' super-quadric meshes for
    ``camera``, by trimesh ray casting (embree when ``embreex`` is installed, trimesh's
    own triangle intersector otherwise); ``bar`` (a progress bar or None) advances by
    one per template."""
    import trimesh

    h, w = camera.height, camera.width
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    dirs = np.stack(
        [(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones_like(u)], axis=-1
    ).reshape(-1, 3)
    unit = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    origins = np.zeros_like(unit)
    out = np.zeros((count, h, w), dtype=np.float32)
    for i in range(count):
        verts, faces = TemplateDatabase.template_mesh(i, shape, distance=distance)
        mesh = trimesh.Trimesh(vertices=verts, faces=faces, process=False)
        locs, rays, _ = mesh.ray.intersects_location(origins, unit, multiple_hits=True)
        depth = np.full(h * w, np.inf)
        np.minimum.at(depth, rays, locs[:, 2])
        depth[~np.isfinite(depth)] = 0.0
        out[i] = depth.reshape(h, w)
        if bar is not None:
            bar.update(1)
    return out
