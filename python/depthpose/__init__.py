"""depthpose: 3-D human pose from depth images and stereo pairs, live on a laptop CPU.

The native core lives in the private module ``depthpose._core``; this package re-exports
its public names with a typed API.

Errors: every error depthpose raises about its input is a :class:`DepthPoseError` (a
``ValueError``) naming the argument or file:

- :class:`InvalidInputError`: an argument of the wrong shape, dtype, range or content;
  its subclass :class:`InvalidTypeError` (also a ``TypeError``) an argument of the
  wrong Python type.
- :class:`FileFormatError`: an unreadable, corrupt or truncated file; its subclass
  :class:`MissingFileError` (also a ``FileNotFoundError``) a file that does not exist.
- :class:`NoBodyError`: no usable body in the input (no valid depth, no foreground).
- :class:`ResourceLimitError`: an input, or the result it asks for, beyond a size limit
  (:data:`MAX_IMAGE_PIXELS`, :data:`MAX_ARRAY_ELEMENTS`, :data:`MAX_RESULT_BYTES`,
  :data:`MAX_FIT_POINTS`), checked before anything is allocated.

Nothing panics, aborts or hangs on bad input; see ``docs/robustness.md``.
"""

from __future__ import annotations

from . import export, graphcut, io, stereo, synth, viz
from ._core import (
    JOINT_NAMES,
    MAX_ARRAY_ELEMENTS,
    MAX_FIT_POINTS,
    MAX_IMAGE_PIXELS,
    MAX_RESULT_BYTES,
    Camera,
    Candidate,
    DepthPoseError,
    FileFormatError,
    InvalidInputError,
    InvalidTypeError,
    MissingFileError,
    NoBodyError,
    ResourceLimitError,
    TemplateDatabase,
    __version__,
    depth_to_points,
    pixel_graph,
    surface_context,
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
from .pipeline import PipelineConfig, PoseEstimator, PoseResult, PoseTracker
from .stereo_pose import StereoPoseEstimator, StereoPoseTracker, estimate_stereo

__all__ = [
    "BodyModel",
    "JOINT_NAMES",
    "PipelineConfig",
    "PoseEstimator",
    "PoseResult",
    "PoseTracker",
    "estimate_stereo",
    "StereoPoseEstimator",
    "StereoPoseTracker",
    "export",
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
    "InvalidTypeError",
    "MAX_ARRAY_ELEMENTS",
    "MAX_FIT_POINTS",
    "MAX_IMAGE_PIXELS",
    "MAX_RESULT_BYTES",
    "MissingFileError",
    "NoBodyError",
    "ResourceLimitError",
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
