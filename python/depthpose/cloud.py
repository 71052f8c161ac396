"""The depth image as a cloud of 3-D points: points, normals, neighbours, foreground."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _core, _validate
from ._core import Camera, Cluster, Plane, Segmentation

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


def foreground_mask(
    depth: np.ndarray,
    background: np.ndarray | None = None,
    *,
    camera: Camera | None = None,
    min_depth: float = 0.3,
    max_depth: float = 8.0,
    bg_tolerance: float = 0.025,
    bg_tolerance_quadratic: float = 0.003,
    max_step: float = 0.25,
    min_component: int = 40,
    large_share: float = 0.3,
) -> np.ndarray:
    """The person's pixels (H, W) bool.

    With ``background`` (the empty scene), foreground is what lies clearly in front of it
    (tolerance ``bg_tolerance + bg_tolerance_quadratic·z²`` metres, following the sensor's
    quantisation), grouped into depth-continuous components (neighbours within
    ``max_step``); the nearest component with at least ``large_share`` of the largest
    one's pixels is the body, and large pieces next to it are kept too.

    Without it, the person is found automatically (:func:`segment_person`): the floor and
    walls are removed and the most person-like object in ``[min_depth, max_depth]`` is
    kept. ``camera`` gives the intrinsics for that (without it, a camera with a 58°
    horizontal field of view is assumed). Speckles are dropped; holes stay holes.
    Raises ``NoBodyError`` when nothing qualifies.
    """
    return _core.foreground_mask(
        depth,
        background,
        camera=camera,
        min_depth=min_depth,
        max_depth=max_depth,
        bg_tolerance=bg_tolerance,
        bg_tolerance_quadratic=bg_tolerance_quadratic,
        max_step=max_step,
        min_component=min_component,
        large_share=large_share,
    )


def segment_person(
    depth: np.ndarray,
    camera: Camera,
    background: np.ndarray | None = None,
    *,
    previous: Segmentation | None = None,
) -> Segmentation:
    """The person's pixels of a depth image, and how they were found.

    With ``background`` (a frame of the empty scene), by background subtraction
    (``method == "background"``). Without it (``method == "planes"``): the support
    planes (floor, walls) are found by RANSAC and removed, the rest is split into
    depth-continuous clusters, and the person is the cluster that looks most like one in
    metres (footprint area, height, width); of comparable ones, the nearest. In a video,
    pass the previous frame's result as ``previous``: its planes are reused and the
    person it found stays chosen when someone else comes nearer. The result lists the
    removed ``planes`` and the ``others``: person-like clusters not chosen.
    Raises ``NoBodyError`` (saying what was found) when nothing looks like a person.
    """
    return _core.segment_person(depth, camera, background, previous=previous)
