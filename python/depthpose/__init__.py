"""depthpose: 3-D human pose from depth images and stereo pairs, live on a laptop CPU.

The native core lives in the private module ``depthpose._core``; this package re-exports
its public names with a typed API. Every error is a :class:`DepthPoseError` (a
``ValueError``).
"""

from __future__ import annotations

from . import graphcut, io, stereo, synth, viz
from ._core import (
    Camera,
    DepthPoseError,
    FileFormatError,
    InvalidInputError,
    NoBodyError,
    __version__,
    depth_to_points,
    pixel_graph,
    surface_normals,
)
from .body import BodyModel
from .cloud import (
    Cluster,
    Plane,
    PointCloud,
    Segmentation,
    foreground_mask,
    point_cloud,
    segment_person,
)
from .fit import (
    FitConfig,
    FitResult,
    ShapeFitResult,
    fit_pose,
    fit_poses,
    fit_shape,
    pose_from_joints,
)
from .io import read_depth, read_image, write_depth
from .pipeline import PipelineConfig, PoseEstimator, PoseResult, PoseTracker, estimate_stereo
from .templates import Candidate, TemplateDatabase, surface_context

__all__ = [
    "BodyModel",
    "PipelineConfig",
    "PoseEstimator",
    "PoseResult",
    "PoseTracker",
    "estimate_stereo",
    "graphcut",
    "stereo",
    "synth",
    "Camera",
    "Candidate",
    "DepthPoseError",
    "FileFormatError",
    "FitConfig",
    "FitResult",
    "ShapeFitResult",
    "fit_shape",
    "InvalidInputError",
    "NoBodyError",
    "PointCloud",
    "Cluster",
    "Plane",
    "Segmentation",
    "segment_person",
    "TemplateDatabase",
    "__version__",
    "depth_to_points",
    "fit_pose",
    "fit_poses",
    "foreground_mask",
    "io",
    "pixel_graph",
    "point_cloud",
    "pose_from_joints",
    "read_depth",
    "read_image",
    "surface_context",
    "surface_normals",
    "viz",
    "write_depth",
]
