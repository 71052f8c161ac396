"""The depth image as a cloud of 3-D points: points, normals, neighbours, foreground."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _core, _validate
from ._core import Camera, Cluster, Plane, Segmentation, foreground_mask, segment_person

__all__ = [
    "Cluster",
    "Plane",
    "PointCloud",
    "Segmentation",
    "foreground_mask",
    "point_cloud",
    "segment_person",
]


@dataclass(frozen=True)
class PointCloud:
    """Foreground depth pixels as 3-D points with normals and their pixel graph.

    ``points`` (N, 3) camera frame, metres; ``pixels`` (N, 2) [row, col]; ``normals``
    (N, 3) unit, facing the camera; ``edges`` (E, 2) point indices of neighbouring pixels,
    with the 3-D ``distance`` (E,) and depth difference ``depth_diff`` (E,) of each edge.
    """

    points: np.ndarray
    pixels: np.ndarray
    normals: np.ndarray
    edges: np.ndarray
    distance: np.ndarray
    depth_diff: np.ndarray

    def __len__(self) -> int:
        return int(self.points.shape[0])


def point_cloud(
    depth: np.ndarray,
    camera: Camera,
    mask: np.ndarray | None = None,
    *,
    connectivity: int = 4,
    normal_radius: int = 2,
) -> PointCloud:
    """Points, normals and the 4- or 8-neighbour graph of the (masked) depth pixels;
    ``normal_radius`` in 1..32 pixels."""
    normal_radius = _validate.integer(normal_radius, "normal_radius", low=1, high=32)
    points, pixels = _core.depth_to_points(depth, camera, mask)
    normals = _core.surface_normals(depth, camera, mask, normal_radius)
    edges, distance, depth_diff = _core.pixel_graph(depth, camera, mask, connectivity)
    return PointCloud(points, pixels, normals, edges, distance, depth_diff)
