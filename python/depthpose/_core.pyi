# Type stubs for the native module depthpose._core, checked against the compiled module
# by mypy.stubtest (.ci/run, with .ci/stubtest_allowlist.txt) and tests/test_stub.py. The
# native classes cannot be subclassed (@final); their constructors are __new__, as the
# native types define them.
from collections.abc import Callable, Mapping
from collections.abc import Sequence as _Sequence
from os import PathLike
from pathlib import Path
from typing import Any, Literal, final, overload

import numpy as np
import numpy.typing as npt
from typing_extensions import Self, disjoint_base

__all__ = [
    "BVH_NAMES",
    "BVH_PARENTS",
    "BodyModel",
    "Camera",
    "Candidate",
    "Cluster",
    "DepthPoseError",
    "FileFormatError",
    "FitConfig",
    "FitResult",
    "InvalidInputError",
    "InvalidTypeError",
    "JOINT_NAMES",
    "KINECT_SHAPE",
    "MAX_ARRAY_ELEMENTS",
    "MAX_DEPTH_SCALE",
    "MAX_FIT_POINTS",
    "MAX_IMAGE_PIXELS",
    "MAX_LABELS",
    "MAX_RESULT_BYTES",
    "MIN_DEPTH_SCALE",
    "MOTIONS",
    "MaxflowGraph",
    "MissingFileError",
    "NoBodyError",
    "PipelineConfig",
    "Plane",
    "PoseEstimator",
    "PoseResult",
    "PoseTracker",
    "ResourceLimitError",
    "Segmentation",
    "Sequence",
    "SequenceFrames",
    "ShapeFitResult",
    "StereoPoseEstimator",
    "StereoPoseTracker",
    "TemplateDatabase",
    "__version__",
    "_check_array",
    "_check_integer",
    "_check_mask",
    "_check_number",
    "_check_numbers",
    "_euler_zxy",
    "_not_numbers",
    "_sequence_camera",
    "_stereo_pairs",
    "alpha_beta_swap",
    "alpha_expansion",
    "crf_energy",
    "depth_from_disparity",
    "depth_metres",
    "depth_to_points",
    "fit_pose",
    "fit_poses",
    "foreground_mask",
    "grid_edges",
    "label_all_pixels",
    "make_sequence",
    "match",
    "mirror_view",
    "motion_pose",
    "open_sequence",
    "pixel_graph",
    "pose_from_joints",
    "read_depth",
    "read_float_image",
    "read_image",
    "read_npz",
    "read_pfm",
    "rest_pose_penalty",
    "segment_person",
    "surface_context",
    "surface_normals",
    "swap_limbs",
    "write_depth",
    "write_bvh",
    "write_depth_png",
    "write_jsonl",
    "write_npz",
    "write_pfm",
    "write_rgb_png",
]

__version__: str
"""The package version."""

# ---- errors and limits ----------------------------------------------------------------
class DepthPoseError(ValueError):
    """Base class of every depthpose error about its input (a ValueError). Messages name
    the argument (or file) and print numbers briefly."""

class InvalidInputError(DepthPoseError):
    """An argument has the wrong shape, dtype, range or content."""

class InvalidTypeError(InvalidInputError, TypeError):
    """An argument of the wrong Python type (a str where a number is expected, a list
    where a numpy array is, an object or string array where numbers are)."""

class FileFormatError(DepthPoseError):
    """A file is unreadable, corrupt, truncated or not in the expected format."""

class MissingFileError(FileNotFoundError, FileFormatError):
    """A file or folder that does not exist (errno ENOENT, ``filename`` set)."""

class NoBodyError(DepthPoseError):
    """The input holds no usable body (no valid depth, empty foreground)."""

class ResourceLimitError(DepthPoseError):
    """An input, or the result it asks for, exceeds a size limit; the message names the
    limit. Checked before anything is allocated or copied."""

MAX_IMAGE_PIXELS: int
"""Largest image (height × width) read, written, rendered or passed as a depth image,
mask or picture: 2**23 pixels."""
MAX_FIT_POINTS: int
"""Most depth readings (within the mask) one body fit, shape calibration, template match
or descriptor takes: 2**20."""
MAX_ARRAY_ELEMENTS: int
"""Largest number of elements of any other array argument: 2**26."""
MAX_RESULT_BYTES: int
"""Largest result one call may allocate (an output array, a graph, meshes): 2**30
bytes."""
#: Smallest and largest metres-per-unit scale of integer depth files (1e-6 and 1).
MIN_DEPTH_SCALE: float
MAX_DEPTH_SCALE: float
#: Most labels of a CRF (alpha_expansion, alpha_beta_swap, crf_energy): 1024.
MAX_LABELS: int

# ---- argument checks (depthpose._validate) ----------------------------------------
def _check_integer(
    value: object, name: str, *, low: int | None = None, high: int | None = None
) -> int:
    """A Python or numpy integer (not a bool) within [``low``, ``high``] (either end may
    be open), as an int."""

def _check_number(
    value: object,
    name: str,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
) -> float:
    """A finite Python or numpy real number (not a bool) within [``low``, ``high``]
    (``low_open``: above ``low``)."""

def _check_array(value: object, name: str, *, image: int = 0) -> npt.NDArray[Any]:
    """``value`` itself if it is a numpy array within its size limit (not copied): an
    image (``image`` > 0: H × W at most :data:`MAX_IMAGE_PIXELS`, ``image`` values a
    pixel) or any other array (:data:`MAX_ARRAY_ELEMENTS`)."""

def _check_mask(
    value: object, shape: _Sequence[int], name: str | None = None
) -> npt.NDArray[np.bool_]:
    """A mask of exactly ``shape`` as a C-contiguous bool array: bool, or an integer
    dtype holding only 0 and 1, of any layout. Strings, floats and other integers are
    refused rather than cast. ``name`` defaults to "mask"."""

def _check_numbers(value: object, name: str, *, ndim: int | None = None) -> npt.NDArray[np.float64]:
    """A numeric array (or a list of numbers), any layout, as float64, without NaN or
    inf."""

def _not_numbers(dtype: np.dtype[Any]) -> str | None:
    """Why ``dtype`` cannot hold numbers (None if it can), in the words of the native
    converters' errors."""

# ---- camera -------------------------------------------------------------------------
@final
class Camera:
    def __new__(
        cls, fx: float, fy: float, cx: float, cy: float, width: int, height: int
    ) -> Camera: ...
    @staticmethod
    def preset(name: str) -> Camera:
        """The camera of a common depth sensor, by name.

        Parameters
        ----------
        name : str
            One of :meth:`presets` (case and ``_`` versus ``-`` do not matter):
            ``kinect-v1`` (640×480, f = 580 px), ``kinect-v1-qvga`` (320×240),
            ``kinect-v2`` (512×424, f = 365.4 px), ``azure-kinect`` (NFOV unbinned,
            640×576, f = 504 px), ``realsense-d435`` (depth at 640×480, f = 384.2 px),
            ``itop`` (320×240, f = 285.71 px).

        Returns
        -------
        Camera
            Nominal intrinsics of the sensor's depth stream; a device's own calibration
            differs by a few pixels and is better when you have it.

        Raises
        ------
        InvalidInputError
            ``name`` is not a preset (the message lists the presets).
        InvalidTypeError
            ``name`` is not a string.
        """
    @staticmethod
    def presets() -> list[str]:
        """The names :meth:`preset` knows.

        Returns
        -------
        list of str
            ``["kinect-v1", "kinect-v1-qvga", "kinect-v2", "azure-kinect",
            "realsense-d435", "itop"]``.
        """
    @staticmethod
    def kinect_v1() -> Camera: ...
    @staticmethod
    def kinect_v1_qvga() -> Camera: ...
    @staticmethod
    def itop() -> Camera: ...
    @staticmethod
    def from_intrinsics(intrinsics: list[float], shape: tuple[int, int]) -> Camera: ...
    def scaled(self, factor: float) -> Camera: ...
    @property
    def fx(self) -> float: ...
    @property
    def fy(self) -> float: ...
    @property
    def cx(self) -> float: ...
    @property
    def cy(self) -> float: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def shape(self) -> tuple[int, int]: ...
    @property
    def intrinsics(self) -> list[float]: ...
    def project(self, points: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
    def back_project(
        self, pixels: npt.ArrayLike, depth: npt.ArrayLike
    ) -> npt.NDArray[np.float64]: ...

# ---- cloud --------------------------------------------------------------------------
def depth_to_points(
    depth: npt.NDArray[np.generic], camera: Camera, mask: npt.NDArray[np.bool_] | None = None
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.int32]]:
    """The 3-D points of a depth image.

    Parameters
    ----------
    depth : ndarray
        (H, W) float metres or uint16 millimetres; 0 and NaN are no reading.
    camera : Camera
        Its intrinsics; its size must be the image's.
    mask : ndarray of bool, optional
        (H, W): only these pixels.

    Returns
    -------
    points : ndarray
        (N, 3) float32, camera frame (x right, y down, z forward), metres, of the pixels
        with a reading (and in ``mask``), row by row.
    pixels : ndarray
        (N, 2) int32, their [row, col].
    """

def surface_normals(
    depth: npt.NDArray[np.generic],
    camera: Camera,
    mask: npt.NDArray[np.bool_] | None = None,
    radius: int = 2,
) -> npt.NDArray[np.float32]:
    """Unit surface normals (N, 3) float32, facing the camera, of the points of
    :func:`depth_to_points` (same arguments), from the neighbours within ``radius``
    pixels."""

def pixel_graph(
    depth: npt.NDArray[np.generic],
    camera: Camera,
    mask: npt.NDArray[np.bool_] | None = None,
    connectivity: int = 4,
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """The neighbourhood graph of the points of :func:`depth_to_points` (same arguments),
    4- or 8-connected (``connectivity``) between pixels with a reading.

    Returns
    -------
    edges : ndarray
        (E, 2) int32 point indices.
    distances : ndarray
        (E,) float32 3-D distances, metres.
    depth_steps : ndarray
        (E,) float32 depth differences z_j − z_i, metres.
    """

def foreground_mask(
    depth: npt.NDArray[np.generic],
    background: npt.NDArray[np.generic] | None = None,
    *,
    camera: Camera | None = None,
    min_depth: float = 0.3,
    max_depth: float = 8.0,
    bg_tolerance: float = 0.025,
    bg_tolerance_quadratic: float = 0.003,
    max_step: float = 0.25,
    min_component: int = 40,
    large_share: float = 0.3,
    attach_depth: float = 0.5,
    min_joined_piece: int = 0,
) -> npt.NDArray[np.bool_]:
    """The person's pixels (H, W) bool.

    With ``background`` (the empty scene), foreground is what lies clearly in front of it
    (tolerance ``bg_tolerance + bg_tolerance_quadratic·z²`` metres, following the sensor's
    quantisation), grouped into depth-continuous components (neighbours within
    ``max_step``); the nearest component with at least ``large_share`` of the largest
    one's pixels is the body. Large pieces next to it are kept too, and every piece
    that meets it across a dropout seam of up to 3 pixels with a depth step under
    ``attach_depth`` (a side view's far leg behind the near one, the small pieces
    noise breaks a thin limb into). Dropouts the silhouette surrounds or that bite
    into its edge join the mask.

    Without it, the person is found automatically (:func:`segment_person`): the floor and
    walls are removed and the most person-like object in ``[min_depth, max_depth]`` is
    kept. Speckles are dropped; holes stay holes.

    Parameters
    ----------
    depth
        (H, W) float metres or uint16 millimetres.
    background
        The empty scene's depth (H, W), or None.
    camera
        The intrinsics for the automatic segmentation (default: a camera with a 58°
        horizontal field of view).
    min_depth, max_depth
        The depth range searched, metres.
    bg_tolerance, bg_tolerance_quadratic
        How far in front of the background a pixel must lie, ``a + b·z²`` metres.
    max_step
        Largest depth step between neighbours of one component, metres.
    min_component
        Smallest component kept, pixels.
    large_share
        Share of the largest component's pixels a component needs to be the body.
    attach_depth
        The largest depth step, metres, across which a piece joins the body (for a
        large piece beside it, the largest difference of their median depths).
    min_joined_piece
        With a background: the smallest piece, pixels, that joins the body across a
        dropout seam (0: every one). Depth from a stereo pair leaves small mismatch
        islands beside the body, which ``min_component`` keeps out.

    Raises
    ------
    NoBodyError
        Nothing qualifies.
    InvalidInputError
        A bad argument.
    """

# ---- io -----------------------------------------------------------------------------
KINECT_SHAPE: tuple[int, int]
"""The (height, width) :func:`read_depth` assumes for a raw ``.u16`` file: (480, 640),
Kinect v1."""

def read_depth(
    path: str | PathLike[str], scale: float = 0.001, shape: tuple[int, int] | None = None
) -> npt.NDArray[np.float32]:
    """Reads a depth image as float32 metres (0 or NaN = no reading), the format by the
    file's suffix (see the table of units in :mod:`depthpose.io`).

    Parameters
    ----------
    path : str or os.PathLike
        A ``.png``, ``.tif``/``.tiff``, ``.npy``, ``.pfm`` or raw ``.u16``/``.raw``
        file.
    scale : float
        Metres per integer unit of 16-bit PNG/TIFF, uint16 ``.npy`` and ``.u16``
        files (default millimetres), in [1e-6, 1]; float formats hold metres.
    shape : (int, int), optional
        (height, width) of a raw ``.u16`` file, which holds no header; default
        :data:`KINECT_SHAPE`. Ignored for other formats.

    Returns
    -------
    ndarray
        (H, W) float32 metres.

    Raises
    ------
    MissingFileError
        The file does not exist (a ``FileNotFoundError``).
    FileFormatError
        The file is unreadable, corrupt or truncated, not a depth image (8-bit or
        colour, an array of another dtype or dimension, Python objects), holds negative
        or infinite depth, has an unknown suffix, or (``.u16``) its size is not
        ``shape``.
    ResourceLimitError
        The header or ``shape`` says more than :data:`MAX_IMAGE_PIXELS` pixels (checked
        before the pixels are read).
    InvalidInputError
        ``scale`` or ``shape`` is out of range or of the wrong type.
    """

def write_depth(
    path: str | PathLike[str], depth: npt.NDArray[np.generic], scale: float = 0.001
) -> None:
    """Writes depth as a 16-bit PNG (units of ``scale`` metres), ``.npy`` or ``.pfm``
    (float32 metres), the format by the suffix.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.png``, ``.npy`` or ``.pfm`` file.
    depth : ndarray
        (H, W) float metres or uint16 millimetres, as every depthpose function takes it
        (so uint16 input is millimetres in every format); any memory layout.
    scale : float
        Metres per unit of a PNG, in [1e-6, 1].

    Raises
    ------
    InvalidInputError
        Another suffix; negative or infinite depth; for PNG, depth the file cannot
        store (beyond 65535 units, or below half a unit, which would read back as no
        reading). NaN is written as 0 in a PNG and kept in ``.npy`` and ``.pfm``.
    """

def read_image(path: str | PathLike[str]) -> npt.NDArray[np.float32]:
    """Any PNG/TIFF/JPEG as a gray float32 image: integer types scaled to [0, 1] by
    their type's maximum, float TIFF as stored, colour converted by luminance.

    Raises
    ------
    MissingFileError
        The file does not exist.
    FileFormatError
        The file is not a readable image.
    """

def read_float_image(path: str | PathLike[str]) -> npt.NDArray[np.float32]:
    """A float TIFF (its first channel) or any other image as stored, float32."""

def read_pfm(path: str | PathLike[str]) -> npt.NDArray[np.float32]:
    """A PFM image (``Pf`` gray or ``PF`` colour, its first channel) as float32, top row
    first; the header is checked before the pixels are read.

    Raises
    ------
    MissingFileError
        The file does not exist.
    FileFormatError
        Not a PFM file, a corrupt header, or truncated pixels.
    ResourceLimitError
        The header says more than :data:`MAX_IMAGE_PIXELS` pixels.
    """

def write_pfm(
    path: str | PathLike[str], image: npt.NDArray[np.generic], *, nan_as_inf: bool = False
) -> None:
    """Writes a 2-D image (any real dtype; NaN and inf kept) as little-endian gray PFM.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    image : ndarray
        (H, W) numbers, any memory layout.
    nan_as_inf : bool
        Store NaN as +inf, the Middlebury convention for "unknown".

    Raises
    ------
    InvalidInputError
        Not a non-empty 2-D array of numbers (an object or string array is an
        :class:`InvalidTypeError`).
    """

def read_npz(
    path: str | PathLike[str], what: str = "a .npz archive", keys: list[str] | None = None
) -> dict[str, npt.NDArray[Any]]:
    """The arrays of a ``.npz`` file (numpy's zip of ``.npy`` arrays), read without
    pickles, each of its stored dtype, shape and order.

    Parameters
    ----------
    path : str or os.PathLike
        The archive.
    what : str
        What the file should be, for errors ("a depth sequence").
    keys : list of str, optional
        Read only these arrays (those the file holds); default all.

    Returns
    -------
    dict of str to ndarray
        The arrays by key, in the archive's order.

    Raises
    ------
    MissingFileError
        The file does not exist.
    FileFormatError
        Not a zip archive; an entry with a corrupt header, of Python objects, or
        truncated or corrupt. Every entry is checked, read or not; the message names
        the file and says it is not ``what``.
    """

def write_depth_png(
    path: str | PathLike[str], depth: npt.NDArray[np.generic], scale: float = 0.001
) -> None: ...
def write_rgb_png(path: str | PathLike[str], rgb: npt.NDArray[np.integer]) -> None:
    """Writes an (H, W, 3) picture of integers in 0..255 (any integer dtype and layout)."""

def depth_metres(
    depth: npt.NDArray[np.generic], name: str | None = None
) -> npt.NDArray[np.float32]:
    """``depth`` checked and converted as every depthpose function takes a depth image:
    (H, W) float32/float64 metres or uint16 millimetres, C-contiguous, no negative or
    infinite value (0 and NaN: no reading); returned as float32 metres. Errors name
    ``name`` (default "depth")."""

def write_npz(path: str | PathLike[str], **arrays: npt.ArrayLike) -> None:
    """Writes arrays as an uncompressed ``.npz`` (numpy's zip of ``.npy`` arrays, as
    ``numpy.savez`` writes it): to a temporary file beside ``path``, synced, then
    renamed, so that a reader never sees half a file.

    Parameters
    ----------
    path : str or os.PathLike
        The archive to write.
    **arrays : array_like
        The arrays by key, of plain dtypes (numbers, bools, fixed-width strings).

    Raises
    ------
    InvalidInputError
        An array of an unsupported dtype (an object array is an
        :class:`InvalidTypeError`), named by its key.
    FileFormatError
        The file cannot be written.
    """

# ---- sequences (depthpose.sequence) ----------------------------------------------------
@final
class Sequence:
    """A depth sequence on disk, from :func:`open_sequence`: what its files say about
    it; its frames are read on demand with :meth:`frames` or :meth:`iter_frames`.

    Attributes
    ----------
    path : pathlib.Path
        The ``.npz``, the folder or the image.
    name : str
        The folder's name or the file's stem.
    kind : {"npz", "folder", "image"}
        What the sequence is on disk.
    n_frames : int
        Number of frames.
    camera : Camera
        The camera of the frames (of their size).
    depth_scale : float
        Metres per integer unit of the depth files.
    background : ndarray of float32 or None
        The empty scene in metres: a folder's ``background.png`` or a ``.npz``'s
        ``background``.
    gt_joints : ndarray of float64 or None
        The ground-truth joints a ``.npz`` holds (``joints``, (T, 15, 3)).
    fps : float
        Frames a second: a ``.npz``'s ``fps``, else 30.
    files : list of pathlib.Path
        The frame files of a folder (sorted by name) or the image; empty for a
        ``.npz``.
    """

    @property
    def path(self) -> Path: ...
    @property
    def name(self) -> str: ...
    @property
    def kind(self) -> Literal["npz", "folder", "image"]: ...
    @property
    def n_frames(self) -> int: ...
    @property
    def camera(self) -> Camera: ...
    @property
    def depth_scale(self) -> float: ...
    @property
    def background(self) -> npt.NDArray[np.float32] | None: ...
    @property
    def gt_joints(self) -> npt.NDArray[np.float64] | None: ...
    @property
    def fps(self) -> float: ...
    @property
    def files(self) -> list[Path]: ...
    def frames(self, start: int = 0, stop: int | None = None) -> npt.NDArray[np.float32]:
        """Depth frames [start, stop) as float32 metres, read with the GIL released. A
        frame that cannot be read raises its error (see :meth:`iter_frames` for reading
        around it).

        Parameters
        ----------
        start : int
            The first frame, >= 0.
        stop : int, optional
            One past the last frame (at most :attr:`n_frames`, the default).

        Returns
        -------
        ndarray of float32, shape (k, H, W)
            The frames in metres (k = stop - start, possibly 0).

        Raises
        ------
        InvalidInputError
            ``start`` or ``stop`` not an integer >= 0, or ``start`` after ``stop``.
        MissingFileError
            A frame's file is gone.
        FileFormatError
            A frame cannot be read, or is not of the sequence's size.
        """

    def iter_frames(self, start: int = 0, stop: int | None = None) -> SequenceFrames:
        """Each frame of [start, stop) in order, read one at a time (a ``.npz``'s
        frames at once, on the first step): ``(index, frame)``, the frame being the
        depth (H, W) float32 metres or the :class:`DepthPoseError` (a
        ``MissingFileError`` or ``FileFormatError``) that reading it raised, so that
        one bad frame does not stop the others.

        Parameters
        ----------
        start : int
            The first frame, >= 0.
        stop : int, optional
            One past the last frame (at most :attr:`n_frames`, the default).

        Returns
        -------
        SequenceFrames
            An iterator of ``(index, frame or error)``.

        Raises
        ------
        InvalidInputError
            ``start`` or ``stop`` not an integer >= 0, or ``start`` after ``stop``
            (when called). A ``.npz`` that can no longer be read raises its error on
            the first step.
        """

    def frame_name(self, k: int) -> str:
        """How messages name frame ``k``: its file, or ``path[k]`` (its index in the
        ``.npz``)."""

@final
class SequenceFrames:
    """The iterator of :meth:`Sequence.iter_frames`: ``(index, frame or error)``."""

    def __iter__(self) -> Self: ...
    def __next__(self) -> tuple[int, npt.NDArray[np.float32] | DepthPoseError]: ...

def _sequence_camera(
    shape: tuple[int, int],
    path: str | PathLike[str],
    *,
    camera: Camera | Callable[[tuple[int, int]], Camera] | None = None,
    intrinsics: npt.ArrayLike | None = None,
) -> Camera:
    """The camera of frames of ``shape`` (H, W) at ``path``, resolved from ``camera``
    or ``intrinsics`` as :func:`open_sequence` resolves it (for
    ``depthpose.stereo_sequence``). Raises as :func:`open_sequence` does for these
    arguments."""

def _stereo_pairs(
    folder: str | PathLike[str],
) -> tuple[list[tuple[Path, Path]], tuple[Path, Path] | None]:
    """The rectified stereo pairs of a folder (for ``depthpose.stereo_sequence``),
    sorted by the left image's name, and its empty-scene pair when both files exist.

    The pairs are either in subfolders ``left/`` and ``right/`` (the same file names;
    the empty scene ``background.png`` in each) or side by side, each left image's name
    containing ``left`` (any case) and its partner's the same name with the last
    ``left`` turned into ``right`` (the empty scene ``left_bg.png`` and
    ``right_bg.png``). Images: ``.png``, ``.tif``, ``.tiff``, ``.jpg``, ``.jpeg``,
    ``.bmp``, ``.pgm``, ``.ppm``.

    Raises
    ------
    FileFormatError
        No pairs inside, or the right image of a pair is missing.
    """

def open_sequence(
    path: str | PathLike[str],
    *,
    intrinsics: npt.ArrayLike | None = None,
    depth_scale: float = 0.001,
    camera: Camera | Callable[[tuple[int, int]], Camera] | None = None,
    pattern: str | None = None,
) -> Sequence:
    """Opens a depth sequence: a ``.npz``, a folder of depth frames or one depth
    image. The files are read with the GIL released; a frame is read when asked for.

    A ``.npz`` holds ``depth`` (T, H, W) uint16 (units of ``depth_scale``) or float
    (metres), and optionally ``intrinsics`` [fx, fy, cx, cy], ``background`` (H, W),
    ``joints`` (T, 15, 3) and ``fps``; only the header of ``depth`` is read here. A
    folder's frames are its files with a depth-image suffix (``.png``, ``.tif``,
    ``.tiff``, ``.npy``, ``.pfm``, ``.u16``) or those ``pattern`` matches, sorted by
    name; ``background.png`` among them is the empty scene, not a frame. The frames'
    size is that of most of the first three readable frames, so that one stray image
    of another size is a failed frame, not the size.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.npz``, the folder or the image.
    intrinsics : array_like of 4 numbers, optional
        [fx, fy, cx, cy] of the frames, instead of those a ``.npz`` holds.
    depth_scale : float
        Metres per integer unit, in [MIN_DEPTH_SCALE, MAX_DEPTH_SCALE] (the readers'
        ``scale``; the CLI's ``--depth-scale`` counts units per metre instead).
    camera : Camera or callable, optional
        The camera, instead of ``intrinsics``: a :class:`Camera` of the frames' size,
        or a function of the frames' shape (H, W) returning one (called once, with the
        GIL held).
    pattern : str, optional
        For a folder, a glob of the frame files to read, relative to it (``*``, ``?``,
        ``[...]``, ``**`` as :meth:`pathlib.Path.glob` reads them); default: every
        file with a depth-image suffix. A matched file that is not a depth image is a
        failed frame, not a failed sequence.

    Returns
    -------
    Sequence
        The sequence, its frames unread.

    Raises
    ------
    InvalidTypeError
        ``path`` not a path, ``pattern`` not a string, ``camera`` neither a
        :class:`Camera` nor a function, or the function's result not a Camera.
    InvalidInputError
        ``depth_scale`` out of range; both ``camera`` and ``intrinsics``; a camera of
        another size than the frames; intrinsics not four finite numbers; no
        intrinsics given for a sequence that holds none.
    MissingFileError
        ``path`` does not exist.
    FileFormatError
        A ``.npz`` that is not a readable archive, without ``depth``, with ``depth``
        not (T, H, W) of at least one frame, of uint16 or float, with ``fps`` not one
        positive number; a folder without depth frames (besides ``background.png``),
        none of whose frames can be read, or whose files ``pattern`` does not match;
        an image that cannot be read.
    ResourceLimitError
        Frames of more than ``MAX_IMAGE_PIXELS`` pixels.
    """

# ---- exports ------------------------------------------------------------------------
BVH_PARENTS: dict[str, str | None]
"""Parent of each body segment (part names of the body model); None for the root."""
BVH_NAMES: dict[str, str]
"""The BVH joint name of each body segment: the names animation tools map by default
(Blender, MotionBuilder, Mixamo-style retargeting); Left and Right are the subject's."""

def write_bvh(
    path: str | PathLike[str],
    model: BodyModel,
    poses: npt.ArrayLike,
    fps: float = 30.0,
    *,
    confidence: npt.ArrayLike | None = None,
) -> None:
    """Writes a tracked sequence as BVH, y up (x = the subject's left, z = towards the
    camera at the rest pose), metres.

    One joint per body segment at its proximal joint, named as animation tools expect
    (:data:`BVH_NAMES`: Hips, Spine, Neck, Head, LeftArm, LeftForeArm, LeftHand,
    LeftUpLeg, LeftLeg, LeftFoot, and the Right ones); each chain ends in an End Site
    at the far end of its segment. The rest pose is all joint angles zero (segments
    parallel to the body frame). Each frame holds the root's position and every
    joint's rotation relative to its parent as Z-X-Y Euler angles in degrees.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    model : BodyModel
        The body model the poses are of.
    poses : array_like
        (T, 22) poses. A failed frame (a pose of 22 NaN, as the estimators record it)
        repeats the previous frame.
    fps : float
        Frames per second, in (0, 1e6].
    confidence : array_like, optional
        (T, 15), the estimators' per-joint confidence: a leg whose hip, knee and foot
        all have confidence 0 in a frame (not seen) is written at rest in that frame
        rather than with invented angles.

    Raises
    ------
    InvalidInputError
        ``poses`` not (T, 22), holding an infinite value, a frame with some NaN
        parameters but not all, or every frame NaN; ``fps`` out of range;
        ``confidence`` of another shape or not finite.
    InvalidTypeError
        ``model`` is not a :class:`BodyModel`; an object or string array.
    """

def write_jsonl(path: str | PathLike[str], results: _Sequence[Any]) -> None:
    """Writes one JSON line per frame, ``{"frame": k, ...}`` with the fields of the
    frame's ``PoseResult.to_dict()``, or ``{"frame": k, "joints": null}`` for a failed
    frame (None).

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    results : sequence
        A ``PoseResult`` (anything with ``to_dict()``) or None per frame.

    Raises
    ------
    InvalidTypeError
        An item that is neither None nor has ``to_dict()``, or a value JSON cannot
        hold.
    """

# ---- templates ----------------------------------------------------------------------
def surface_context(
    depth: npt.NDArray[np.generic],
    camera: Camera,
    mask: npt.NDArray[np.bool_] | None = None,
    *,
    samples: int = 100,
    radial_bins: int = 5,
    angular_bins: int = 12,
    seed: int = 0,
    depth_weight: float = 0.0,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """Surface-context descriptors of the (masked) body in ``depth``, as the template
    search matches them: at ``samples`` pixels drawn with ``seed``, histograms of the
    other samples over ``radial_bins`` × ``angular_bins`` log-polar bins.

    Returns
    -------
    descriptors : ndarray
        (N, 3·bins) float32, or (N, 4·bins) with ``depth_weight`` > 0.
    samples : ndarray
        (N, 2) float32 sample pixels as [u, v].
    positions : ndarray
        (N, 2) float32 sample positions normalised to the body's extent.
    """

def _euler_zxy(matrix: npt.ArrayLike) -> tuple[float, float, float]: ...

@final
class Candidate:
    """A template matched to a depth image, placed at the observed body."""

    @property
    def index(self) -> int:
        """The template's index (0..768): ``view·256 + right arm·64 + left arm·16 +
        right leg·4 + left leg``."""
    @property
    def view(self) -> int:
        """The template's view: 0 front, 1 left side, 2 right side."""
    @property
    def pose(self) -> npt.NDArray[np.float64]:
        """(22,) the template's pose placed at the observed body (camera frame)."""
    @property
    def joints(self) -> npt.NDArray[np.float64]:
        """(15, 3) the joints of :attr:`pose`, camera frame."""
    @property
    def cost(self) -> float:
        """Mean assignment cost per descriptor sample (lower is better)."""
    @property
    def prune_cost(self) -> float:
        """The pruning stage's score."""
    @property
    def scale(self) -> float:
        """Observed body size over the template body's size."""
    @property
    def code(self) -> tuple[str, str, str, str, str]:
        """(right arm, left arm, right leg, left leg, view) names of the template."""

@final
class TemplateDatabase:
    """768 rendered template poses (4 poses per arm and per leg, 3 views) with their
    surface-context descriptors; :meth:`match` finds the templates that look like the
    body in a depth image, placed at it.

    Make one with :meth:`build`, :meth:`load` or :meth:`default` (the cached database
    every estimator uses unless given another).
    """

    ARM_POSES: tuple[str, ...]
    """Names of the arm poses, in code order."""
    LEG_POSES: tuple[str, ...]
    """Names of the leg poses, in code order."""
    VIEWS: tuple[str, ...]
    """Names of the views, in code order."""
    @staticmethod
    def build(
        model: BodyModel | npt.NDArray[np.generic] | None = None,
        camera: Camera | None = None,
        *,
        width: int = 96,
        height: int = 96,
        distance: float = 3.0,
        field_height: float = 2.4,
        renderer: str = "superquadric",
        samples: int = 100,
        radial_bins: int = 5,
        angular_bins: int = 12,
        seed: int = 0,
        depth_weight: float = 0.0,
        progress: bool = True,
    ) -> TemplateDatabase:
        """Renders and describes the 768 templates.

        Parameters
        ----------
        model
            The body rendered: a :class:`BodyModel`, its 27 shape values, or None (the
            default model).
        camera
            If given, sets the template image size (``width`` and ``height``); the
            templates are always rendered with the body centred, and the descriptors
            are scale-invariant.
        width, height
            Template image size in pixels.
        distance
            Distance of the body from the template camera (metres).
        field_height
            Height of the scene the template image spans at ``distance`` (metres).
        renderer
            "superquadric" (the native rasteriser of the super-quadric meshes),
            "ellipsoid" (native ray casting of the fitting ellipsoids) or "trimesh"
            (trimesh ray casting of the super-quadric meshes; slow without embree).
        samples, radial_bins, angular_bins, seed
            The descriptor: ``samples`` pixels drawn with ``seed``, histograms over
            ``radial_bins`` × ``angular_bins`` log-polar bins.
        depth_weight
            > 0 adds the body's relief (depth relative to its centre) as a fourth value
            per bin, a depthpose extension of the paper's normals-only descriptor (off
            by default; docs/design.md has its effect).
        progress
            Shows a progress bar on stderr when stderr is a terminal.

        Returns
        -------
        TemplateDatabase

        Raises
        ------
        InvalidInputError
            A setting out of range (the message names it).
        ResourceLimitError
            Descriptors beyond ``MAX_RESULT_BYTES``.
        """
    @staticmethod
    def from_depths(
        depths: npt.NDArray[np.generic],
        model: BodyModel | npt.NDArray[np.generic] | None = None,
        *,
        width: int = 96,
        height: int = 96,
        distance: float = 3.0,
        field_height: float = 2.4,
        samples: int = 100,
        radial_bins: int = 5,
        angular_bins: int = 12,
        seed: int = 0,
        depth_weight: float = 0.0,
    ) -> TemplateDatabase:
        """The database of template depth images rendered elsewhere; the model and
        the settings are those of :meth:`build`.

        Parameters
        ----------
        depths
            (768, height, width) float metres in template order, rendered for the
            template camera of the settings (:attr:`camera`).
        """
    @staticmethod
    def render_template(
        index: int,
        model: BodyModel | npt.NDArray[np.generic] | None = None,
        *,
        width: int = 96,
        height: int = 96,
        distance: float = 3.0,
        field_height: float = 2.4,
        renderer: str = "superquadric",
    ) -> npt.NDArray[np.float32]:
        """The depth image (height, width) float32 metres of template ``index`` as
        :meth:`build` renders it ("superquadric" or "ellipsoid")."""
    @staticmethod
    def template_mesh(
        index: int,
        model: BodyModel | npt.NDArray[np.generic] | None = None,
        *,
        distance: float = 3.0,
        rings: int = 16,
        sectors: int = 20,
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
        """The super-quadric meshes of template ``index`` (every segment in one mesh,
        template camera frame, the body ``distance`` m ahead).

        Returns
        -------
        vertices : ndarray
            (V, 3) float64.
        faces : ndarray
            (F, 3) int64 vertex indices.
        """
    def match(
        self,
        depth: npt.NDArray[np.generic],
        camera: Camera,
        mask: npt.NDArray[np.generic] | None = None,
        top_k: int = 5,
        *,
        shortlist: int = 16,
        representatives: int = 8,
        location_weight: float = 0.1,
        dummy_cost: float = 0.15,
        rerank: int = 0,
    ) -> list[Candidate]:
        """The best ``top_k`` templates for the body in ``depth``, each placed at the
        observed body, best first.

        Parameters
        ----------
        depth
            (H, W) float metres or uint16 millimetres, the camera's size.
        camera
            The depth camera.
        mask
            (H, W) bool: the person's pixels (default: every valid reading).
        top_k
            How many candidates.
        shortlist
            Templates the pruning stage keeps for the exact assignment (grows to
            ``max(shortlist, top_k, rerank)``).
        representatives
            Representative descriptors per template in the pruning stage.
        location_weight, dummy_cost
            The assignment cost's weight of the samples' positions, and the cost of
            leaving a sample unmatched.
        rerank
            > 0 re-orders the exact stage's best ``rerank`` candidates by how well each
            placed pose explains the depth in 3-D (the fit's data and free-space terms):
            a better first candidate for about 0.22 ms per candidate (docs/design.md).

        Returns
        -------
        list of Candidate

        Raises
        ------
        NoBodyError
            No body in the depth (or the mask).
        InvalidInputError
            A bad argument.
        """
    def match_with_shortlist(
        self,
        depth: npt.NDArray[np.generic],
        camera: Camera,
        mask: npt.NDArray[np.generic] | None = None,
        top_k: int = 5,
        *,
        shortlist: int = 16,
        representatives: int = 8,
        location_weight: float = 0.1,
        dummy_cost: float = 0.15,
        rerank: int = 0,
    ) -> tuple[list[Candidate], list[int]]:
        """:meth:`match`, and the pruning stage's short list (template indices, best
        first)."""
    def exact_costs(
        self,
        depth: npt.NDArray[np.generic],
        camera: Camera,
        indices: _Sequence[int] | npt.NDArray[np.integer],
        mask: npt.NDArray[np.generic] | None = None,
        *,
        location_weight: float = 0.1,
        dummy_cost: float = 0.15,
    ) -> npt.NDArray[np.float64]:
        """The exact assignment costs of the body in ``depth`` against the templates
        ``indices``, without pruning: (len(indices),) float64."""
    def save(self, path: str | PathLike[str]) -> None:
        """Writes the database to an ``.npz`` file (with its format version and the
        hash of its model and settings), replacing ``path`` at once when complete."""
    @staticmethod
    def load(
        path: str | PathLike[str],
        model: BodyModel | npt.NDArray[np.generic] | None = None,
        *,
        width: int = 96,
        height: int = 96,
        distance: float = 3.0,
        field_height: float = 2.4,
        renderer: str = "superquadric",
        samples: int = 100,
        radial_bins: int = 5,
        angular_bins: int = 12,
        seed: int = 0,
        depth_weight: float = 0.0,
    ) -> TemplateDatabase:
        """Reads a database written by :meth:`save`. When ``model`` or any setting
        (those of :meth:`build`) is given, the file must be the database of this model
        (None: the default model) and these settings.

        Parameters
        ----------
        path
            The ``.npz`` file.

        Raises
        ------
        MissingFileError
            No such file.
        FileFormatError
            Not a template database, corrupt, of another format version, or (with a
            model or settings given) built for another model or other settings.
        """
    @staticmethod
    def default_path() -> Path:
        """Where the default database is cached: ``$DEPTHPOSE_CACHE`` (or
        ``~/.cache/depthpose``) ``/templates-<hash>.npz``, named by the hash of the
        default model and settings."""
    @staticmethod
    def default(*, progress: bool = True) -> TemplateDatabase:
        """The database of the default model and settings, cached at
        :meth:`default_path`: built and saved on first use (a stale or corrupt file is
        rebuilt), and loaded once per process and cache path, so every estimator made
        without ``templates=`` shares one read-only database (instead of ~0.35 s and
        ~60 MB each).

        Parameters
        ----------
        progress
            Shows a progress bar while building, when stderr is a terminal.
        """
    @staticmethod
    def _settings_hash(
        model: BodyModel | npt.NDArray[np.generic] | None = None,
        *,
        width: int = 96,
        height: int = 96,
        distance: float = 3.0,
        field_height: float = 2.4,
        renderer: str = "superquadric",
        samples: int = 100,
        radial_bins: int = 5,
        angular_bins: int = 12,
        seed: int = 0,
        depth_weight: float = 0.0,
    ) -> str: ...
    def __len__(self) -> int: ...
    @property
    def hash(self) -> str:
        """Hash (hex) of the format version, the model and the settings."""
    @property
    def model_shape(self) -> npt.NDArray[np.float64]:
        """(27,) shape values of the body the templates show."""
    @property
    def poses(self) -> npt.NDArray[np.float64]:
        """(768, 22) template poses as rendered (hip centre straight ahead)."""
    @property
    def joints(self) -> npt.NDArray[np.float64]:
        """(768, 15, 3) template joints, template camera frame."""
    @property
    def views(self) -> list[int]:
        """The view of each template (0 front, 1 left side, 2 right side)."""
    @property
    def camera(self) -> Camera:
        """The camera the templates are rendered with."""

# ---- body ---------------------------------------------------------------------------
@final
class BodyModel:
    """The 16-segment, 22-degree-of-freedom ellipsoid body: its shape, its kinematics
    (pose → joints, segment frames), rendering and meshes.

    Parameters
    ----------
    height : float
        Standing height in metres; the reference proportions are scaled to it.
        Default 1.75.
    """

    def __new__(cls, height: float = 1.75) -> BodyModel: ...
    @property
    def param_names(self) -> list[str]: ...
    @property
    def joint_names(self) -> list[str]: ...
    @property
    def part_names(self) -> list[str]: ...
    @property
    def shape_names(self) -> list[str]: ...
    @property
    def lower_bounds(self) -> npt.NDArray[np.float64]: ...
    @property
    def upper_bounds(self) -> npt.NDArray[np.float64]: ...
    @property
    def shape(self) -> npt.NDArray[np.float64]: ...
    @shape.setter
    def shape(self, value: npt.ArrayLike) -> None: ...
    def shape_dict(self) -> list[tuple[str, float]]: ...
    @staticmethod
    def neutral_pose() -> npt.NDArray[np.float64]: ...
    def clamp_pose(self, pose: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
    @staticmethod
    def pose_with_root_increment(
        pose: npt.NDArray[np.float64], omega: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]: ...
    def segment_transforms(self, pose: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
    def joints(self, pose: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
    def joints_jacobian(self, pose: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
    def distances(
        self,
        points: npt.NDArray[np.floating],
        pose: npt.NDArray[np.float64],
        cap: float | None = None,
    ) -> npt.NDArray[np.float32]: ...
    def residuals_and_jacobian(
        self,
        points: npt.NDArray[np.floating],
        labels: npt.NDArray[np.integer],
        pose: npt.NDArray[np.float64],
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
    def render_depth(
        self, pose: npt.NDArray[np.float64], camera: Camera
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.int16]]: ...
    def depth_discrepancies(
        self,
        poses: npt.NDArray[np.float64],
        depth: npt.NDArray[np.generic],
        mask: npt.NDArray[np.bool_],
        camera: Camera,
        cap: float = 0.1,
    ) -> npt.NDArray[np.float64]: ...
    def superquadric_meshes(
        self, pose: npt.NDArray[np.float64], rings: int = 20, sectors: int = 24
    ) -> list[tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]]: ...
    def ellipsoids(
        self, pose: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
    @property
    def shape_factor_names(self) -> list[str]: ...
    def with_shape_factors(self, factors: npt.ArrayLike) -> BodyModel: ...
    def fit_shape(
        self,
        depths: npt.NDArray[np.generic] | _Sequence[npt.NDArray[np.generic]],
        camera: Camera,
        poses: npt.NDArray[np.float64] | _Sequence[npt.NDArray[np.float64]],
        *,
        masks: npt.NDArray[np.bool_] | _Sequence[npt.NDArray[np.bool_]] | None = None,
        iterations: int = 3,
        config: FitConfig | Mapping[str, Any] | None = None,
        lm_iterations: int = 20,
        prior_weight: float = 1e5,
        bounds: tuple[float, float] | None = None,
    ) -> ShapeFitResult: ...

# ---- fit (src/python/fit.rs) --------------------------------------------------------
@final
class FitConfig:
    """Settings of the hard-EM fit of the body to a depth image (CRF labelling and
    Levenberg–Marquardt): noise scale ``sigma``, robust ``loss``, Potts and
    depth-contrast weights, outlier distance, iterations and pixel stride. Keyword
    arguments, each with a default."""

    sigma: float
    loss: str
    loss_scale: float
    potts: float
    contrast_weight: float
    contrast_sigma: float
    outlier_distance: float
    outlier_distance_start: float
    anneal_iterations: int
    adaptive_anneal: bool
    settled_joint_motion: float
    truncation_factor: float
    max_iterations: int
    label_change_tolerance: float
    energy_tolerance: float
    expansion_cycles: int
    free_space_weight: float
    free_space_margin: float
    free_space_truncation: float
    lm_max_iterations: int
    connectivity: int
    stride: int
    label_all_pixels: bool
    full_resolution_iterations: int
    recentred_start: bool
    swapped_limb_starts: bool
    def __new__(
        cls,
        *,
        sigma: float | None = None,
        loss: str = "squared",
        loss_scale: float = 0.03,
        potts: float | None = None,
        contrast_weight: float | None = None,
        contrast_sigma: float | None = None,
        outlier_distance: float | None = None,
        outlier_distance_start: float | None = None,
        anneal_iterations: int | None = None,
        adaptive_anneal: bool | None = None,
        settled_joint_motion: float | None = None,
        truncation_factor: float | None = None,
        max_iterations: int | None = None,
        label_change_tolerance: float | None = None,
        energy_tolerance: float | None = None,
        expansion_cycles: int | None = None,
        free_space_weight: float | None = None,
        free_space_margin: float | None = None,
        free_space_truncation: float | None = None,
        lm_max_iterations: int | None = None,
        connectivity: int = 4,
        stride: int = 1,
        label_all_pixels: bool = True,
        full_resolution_iterations: int = 0,
        recentred_start: bool = True,
        swapped_limb_starts: bool = False,
    ) -> FitConfig: ...

@final
class FitResult:
    """A fitted pose: its 22 parameters, 15 joints, per-pixel part labels, the energy
    and its trace, the iterations run and why they stopped."""

    @property
    def pose(self) -> npt.NDArray[np.float64]: ...
    @property
    def joints(self) -> npt.NDArray[np.float64]: ...
    @property
    def labels(self) -> npt.NDArray[np.int16]: ...
    @property
    def energy(self) -> float: ...
    @property
    def energy_trace(self) -> npt.NDArray[np.float64]: ...
    @property
    def iterations(self) -> int: ...
    @property
    def converged(self) -> bool: ...
    @property
    def reason(self) -> str: ...
    @property
    def anneal_cut(self) -> int | None: ...
    @property
    def part_counts(self) -> dict[str, int]: ...
    @property
    def outliers(self) -> int: ...

@final
class ShapeFitResult:
    """A body shape calibrated over several frames: the body model, its 12 scale
    factors and the frames' refitted poses."""

    @property
    def model(self) -> BodyModel: ...
    @property
    def factors(self) -> npt.NDArray[np.float64]: ...
    @property
    def factor_names(self) -> list[str]: ...
    def factors_dict(self) -> dict[str, float]: ...
    @property
    def poses(self) -> npt.NDArray[np.float64]: ...
    @property
    def joints(self) -> npt.NDArray[np.float64]: ...
    @property
    def labels(self) -> npt.NDArray[np.int16]: ...
    @property
    def energy(self) -> float: ...
    @property
    def energy_trace(self) -> npt.NDArray[np.float64]: ...
    @property
    def rounds(self) -> int: ...

def fit_pose(
    depth: npt.NDArray[np.generic],
    camera: Camera,
    init_pose: npt.ArrayLike,
    *,
    model: BodyModel | None = None,
    mask: npt.NDArray[np.bool_] | None = None,
    config: FitConfig | Mapping[str, Any] | None = None,
    prior: npt.ArrayLike | None = None,
    prior_weight: float = 100.0,
    resume: FitResult | None = None,
) -> FitResult:
    """Fits the body to ``depth`` from ``init_pose`` (hard EM: CRF labels and
    Levenberg–Marquardt).

    A fresh fit also runs from ``init_pose`` moved so that its visible surface's
    centroid lies on the observed points' (when that moves it by 1 cm or more), in
    parallel, and returns the lower-energy result; this rescues starts that are a few
    centimetres off (``FitConfig(recentred_start=False)`` turns it off);
    ``swapped_limb_starts=True`` also starts from the pose with its left and right legs
    (and arms) exchanged, at up to 3x the work. With a ``stride``,
    ``FitConfig(full_resolution_iterations=N)`` continues the strided EM on every pixel
    for up to N iterations (coarse to fine).

    Parameters
    ----------
    depth
        (H, W) float metres or uint16 millimetres.
    camera
        The depth camera.
    init_pose
        The starting pose (22,).
    model
        The body (default ``BodyModel()``, 1.75 m reference proportions).
    mask
        (H, W) bool: the person's pixels (default: every reading).
    config
        A :class:`FitConfig`, a dict of its keyword arguments, or None (the defaults).
    prior
        A pose (22,): adds ``prior_weight/2 · |pose - prior|²`` to the M-step
        (tracking).
    prior_weight
        The prior's weight.
    resume
        An earlier result on this image (e.g. a brief fit with a small
        ``max_iterations``) whose EM goes on: it continues from ``init_pose`` (normally
        ``resume.pose``) with ``resume``'s labels and iteration count, so the outlier
        distance keeps annealing where it was and ``max_iterations`` counts the earlier
        iterations. Continuing a full-resolution fit that hit its iteration limit gives
        exactly the longer fit.

    Returns
    -------
    FitResult
        ``pose``, ``joints`` (15, 3), ``labels`` (H, W) int16 (-1 = background or
        outlier), ``energy``, ``energy_trace``, ``iterations``, ``converged``,
        ``reason``, ``part_counts`` and ``outliers``.

    Raises
    ------
    InvalidInputError
        A bad argument (the message names it).
    """

def fit_poses(
    depth: npt.NDArray[np.generic],
    camera: Camera,
    init_poses: npt.ArrayLike,
    *,
    model: BodyModel | None = None,
    mask: npt.NDArray[np.bool_] | None = None,
    config: FitConfig | Mapping[str, Any] | None = None,
    prior: npt.ArrayLike | None = None,
    prior_weight: float = 100.0,
    resume: _Sequence[FitResult] | None = None,
) -> list[FitResult]:
    """:func:`fit_pose` from each of ``init_poses`` on the same image.

    The foreground cloud and its graph are built once and the K fits run in parallel
    (one fit's work is mostly sequential), so on several cores this is much faster than
    K :func:`fit_pose` calls; each result is identical to its own :func:`fit_pose` call.

    Parameters
    ----------
    init_poses
        (K, 22) starting poses, K ≥ 1.
    resume
        K earlier results, the k-th continued from ``init_poses[k]`` (see
        :func:`fit_pose`).

    The other parameters are those of :func:`fit_pose`.

    Returns
    -------
    list of FitResult
        One per starting pose.
    """

def label_all_pixels(
    depth: npt.NDArray[np.generic],
    camera: Camera,
    result: FitResult,
    *,
    model: BodyModel | None = None,
    mask: npt.NDArray[np.bool_] | None = None,
    config: FitConfig | Mapping[str, Any] | None = None,
    prior: npt.ArrayLike | None = None,
    prior_weight: float = 100.0,
) -> FitResult:
    """``result`` labelled at every pixel of ``depth``.

    For a fit with a ``stride`` and ``label_all_pixels=False`` in its config (its labels
    are the EM's, at every ``stride``-th pixel only), e.g. the best of several candidate
    fits: one E-step at its pose from those labels, exactly what the same fit with
    ``label_all_pixels=True`` returns. Pass the fit's own ``depth``, ``mask``,
    ``model``, ``config`` and ``prior`` (parameters as for :func:`fit_pose`). A result
    already labelled at every pixel, or a config without a stride, comes back
    unchanged.
    """

def pose_from_joints(
    joints: npt.ArrayLike, model: BodyModel | None = None, init: npt.ArrayLike | None = None
) -> npt.NDArray[np.float64]:
    """The pose (22,) whose joints best match ``joints`` (15, 3) in the camera frame
    (inverse kinematics; NaN rows are skipped).

    Parameters
    ----------
    joints
        (15, 3) joint positions, metres.
    model
        The body (default ``BodyModel()``).
    init
        A starting pose (22,).
    """

# ---- graphcut -----------------------------------------------------------------------
@final
class MaxflowGraph:
    """A directed graph with a source and a sink, for max-flow / min-cut
    (``depthpose.graphcut.Graph``).

    ``MaxflowGraph(n_nodes, dtype=float)`` holds float64 capacities; ``dtype=int`` int64
    ones (exact). Build in batches from numpy arrays, then call :meth:`maxflow`;
    :meth:`segments` gives the side of each node (True = sink side). ``edge_hint``
    reserves room for that many edges.
    """

    def __new__(cls, n_nodes: int, dtype: Any = ..., edge_hint: int = ...) -> MaxflowGraph: ...
    @property
    def n_nodes(self) -> int: ...
    @property
    def n_edges(self) -> int: ...
    @property
    def is_integer(self) -> bool: ...
    def memory_bytes(self) -> int:
        """Heap bytes held by the graph."""

    def add_edges(
        self, src: np.ndarray, dst: np.ndarray, cap: np.ndarray, rev_cap: np.ndarray
    ) -> None:
        """Edges ``src[k] → dst[k]`` of capacity ``cap[k]`` and back of ``rev_cap[k]``."""

    def add_terminal_edges(
        self, nodes: np.ndarray, source_cap: np.ndarray, sink_cap: np.ndarray
    ) -> None:
        """Adds ``source_cap[k]`` to source → ``nodes[k]`` and ``sink_cap[k]`` to → sink."""

    def update_terminal_edges(
        self, nodes: np.ndarray, delta_source: np.ndarray, delta_sink: np.ndarray
    ) -> None:
        """Changes terminal capacities by deltas (may be negative), also after a solve;
        the next :meth:`maxflow` reuses the previous search trees (dynamic cuts). All or
        nothing: a refused batch (bad index, non-finite delta, an int graph's capacities
        summing past int64) changes no capacity."""

    def finalize(self) -> None:
        """Builds the arc arrays now (else the next ``maxflow()`` does), so that
        ``maxflow()`` times the solve alone."""

    def maxflow(self, threads: int | None = None) -> int | float:
        """The maximum flow value (int for an int graph).

        A fresh solve of a large graph whose edges join nearby node ids (a pixel grid)
        is split into row bands solved on up to ``threads`` threads (default: all of
        the pool's, see ``RAYON_NUM_THREADS``), then joined by one more search; the cut
        is the same for any ``threads``, a float flow value may differ in the last bits.
        """

    def segments(self) -> npt.NDArray[np.bool_]:
        """Bool array (n_nodes,): True for nodes on the sink side of the minimum cut."""

def grid_edges(h: int, w: int, connectivity: int = ...) -> npt.NDArray[np.int64]:
    """Edges (E, 2) int64 of an ``h``×``w`` grid, row-major node ids, 4- or 8-connected
    (default 4)."""

def alpha_expansion(
    unary: np.ndarray,
    edges: np.ndarray,
    weights: np.ndarray,
    *,
    pairwise: np.ndarray | None = ...,
    init: np.ndarray | None = ...,
    max_cycles: int = ...,
) -> tuple[npt.NDArray[np.int32], int | float]:
    """Minimises the CRF energy by alpha-expansion; returns ``(labels, energy)``.

    ``unary`` (N, L) costs (``+inf`` forbids a label at a node), ``edges`` (E, 2) node
    indices, ``weights`` (E,) ≥ 0, ``pairwise`` (L, L) a metric (default Potts),
    ``init`` (N,) start labels (default: least unary cost), ``max_cycles`` cycles over
    all labels at most (default 20). Integer ``unary``, ``weights`` and ``pairwise``
    give an exact int energy.
    """

def alpha_beta_swap(
    unary: np.ndarray,
    edges: np.ndarray,
    weights: np.ndarray,
    *,
    pairwise: np.ndarray | None = ...,
    init: np.ndarray | None = ...,
    max_cycles: int = ...,
) -> tuple[npt.NDArray[np.int32], int | float]:
    """Like :func:`alpha_expansion` by alpha-beta swap moves (``pairwise`` may be a
    semi-metric: symmetric, zero exactly on the diagonal; ``max_cycles`` counts cycles
    over label pairs)."""

def crf_energy(
    labels: np.ndarray,
    unary: np.ndarray,
    edges: np.ndarray,
    weights: np.ndarray,
    pairwise: np.ndarray | None = ...,
) -> int | float:
    """The CRF energy of ``labels`` (``inf`` if a node has a forbidden label)."""

# ---- stereo -------------------------------------------------------------------------
# depthpose.stereo re-exports these. They take any object and name what they refuse;
# lists are read as numpy.asarray reads them.
@overload
def match(
    left: npt.ArrayLike,
    right: npt.ArrayLike,
    *,
    max_disparity: int | None = None,
    window: int = 5,
    threshold: float | None = None,
    num_seeds: int | None = None,
    seeds: npt.ArrayLike | None = None,
    seed: int = 0,
    return_confidence: Literal[False] = False,
    lr_check: bool = False,
    subpixel: bool = True,
    fill_gaps: bool = True,
    min_segment: int | None = None,
    similarity: str = "mncc",
    half_occlusion: bool = True,
    seed_distinctness: float | None = None,
    min_texture: float | None = None,
) -> npt.NDArray[np.float32]: ...
@overload
def match(
    left: npt.ArrayLike,
    right: npt.ArrayLike,
    *,
    max_disparity: int | None = None,
    window: int = 5,
    threshold: float | None = None,
    num_seeds: int | None = None,
    seeds: npt.ArrayLike | None = None,
    seed: int = 0,
    return_confidence: Literal[True],
    lr_check: bool = False,
    subpixel: bool = True,
    fill_gaps: bool = True,
    min_segment: int | None = None,
    similarity: str = "mncc",
    half_occlusion: bool = True,
    seed_distinctness: float | None = None,
    min_texture: float | None = None,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]: ...
@overload
def match(
    left: npt.ArrayLike,
    right: npt.ArrayLike,
    *,
    max_disparity: int | None = None,
    window: int = 5,
    threshold: float | None = None,
    num_seeds: int | None = None,
    seeds: npt.ArrayLike | None = None,
    seed: int = 0,
    return_confidence: bool = False,
    lr_check: bool = False,
    subpixel: bool = True,
    fill_gaps: bool = True,
    min_segment: int | None = None,
    similarity: str = "mncc",
    half_occlusion: bool = True,
    seed_distinctness: float | None = None,
    min_texture: float | None = None,
) -> npt.NDArray[np.float32] | tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """Disparity of a rectified pair by Growing Correspondence Seeds: left pixel ``x``
    matches right pixel ``x - d`` (``d >= 0``).

    Parameters
    ----------
    left, right : array_like
        Gray (H, W) or colour (H, W, 3) images, uint8 or float, of one shape.
    max_disparity : int, optional
        Largest disparity searched (default: the whole line).
    window : int
        Odd side of the correlation window.
    threshold : float, optional
        Smallest accepted correlation (default 0.47).
    num_seeds : int, optional
        Random seeds matched by exhaustive search.
    seeds : array_like, optional
        Extra seeds, (N, 3) rows (x, y, d).
    seed : int
        Seed of the random seeds.
    return_confidence : bool
        Also return the correlation of each match (NaN unmatched).
    lr_check : bool
        Keep only matches confirmed right-to-left (twice the time).
    subpixel : bool
        Refine each match to a fraction of a pixel.
    fill_gaps : bool
        Fill one-pixel gaps that integer uniqueness leaves on slanted surfaces.
    min_segment : int, optional
        Drop matched segments smaller than this many pixels (default 200).
    similarity : str
        "mncc" (Moravec's normalised cross-correlation) or "ncc".
    half_occlusion : bool
        Drop the matches a nearer surface spreads into the band on its left that the
        right camera cannot see (within half a window of a match more than 2 px
        farther on the left).
    seed_distinctness, min_texture : float, optional
        Tuning of the seed search (defaults of ``StereoConfig``).

    Returns
    -------
    disparity : ndarray
        (H, W) float32, NaN where unmatched. A uniform (textureless) pair gives an
        all-NaN result, not an error.
    confidence : ndarray
        With ``return_confidence``: (H, W) float32 correlation, NaN where unmatched.

    Raises
    ------
    InvalidInputError
        Images of other shapes, a bad setting (named).
    ResourceLimitError
        Images beyond :data:`MAX_IMAGE_PIXELS`.
    """

def depth_from_disparity(
    disparity: npt.ArrayLike, focal: float, baseline: float, doffs: float = 0.0
) -> npt.NDArray[np.float32]:
    """Depth in metres, Z = baseline·focal / (d + doffs); 0 where there is no
    disparity.

    Raises
    ------
    InvalidInputError
        A depth beyond the float32 range (a disparity within ~1e-38 of -doffs), or a
        bad argument.
    """

# ---- person segmentation ------------------------------------------------------------
@final
class Plane:
    """A support plane ``normal · X = offset`` (camera frame, metres, ``offset > 0``)."""

    @property
    def normal(self) -> list[float]: ...
    @property
    def offset(self) -> float: ...
    @property
    def inliers(self) -> int: ...
    @property
    def area(self) -> float: ...

@final
class Cluster:
    """A depth-continuous cluster of pixels, measured in metres."""

    @property
    def pixels(self) -> int: ...
    @property
    def area(self) -> float: ...
    @property
    def height(self) -> float: ...
    @property
    def width(self) -> float: ...
    @property
    def centroid(self) -> list[float]: ...
    @property
    def median_depth(self) -> float: ...
    @property
    def bbox(self) -> list[int]: ...
    @property
    def person_like(self) -> bool: ...
    @property
    def score(self) -> float: ...

@final
class Segmentation:
    """The person's pixels and how they were found (see ``depthpose.segment_person``)."""

    @property
    def mask(self) -> npt.NDArray[np.bool_]: ...
    @property
    def method(self) -> str: ...
    @property
    def planes(self) -> list[Plane]: ...
    @property
    def person(self) -> Cluster: ...
    @property
    def others(self) -> list[Cluster]: ...

def segment_person(
    depth: npt.NDArray[np.generic],
    camera: Camera,
    background: npt.NDArray[np.generic] | None = None,
    *,
    previous: Segmentation | None = None,
) -> Segmentation:
    """The person's pixels of a depth image, and how they were found.

    With ``background`` (a frame of the empty scene), by background subtraction
    (``method == "background"``). Without it (``method == "planes"``): the support
    planes (floor, walls) are found by RANSAC and removed, the rest is split into
    depth-continuous clusters, and the person is the cluster that looks most like one in
    metres (footprint area, height, width); of comparable ones, the nearest. The result
    lists the removed ``planes`` and the ``others``: person-like clusters not chosen.

    Parameters
    ----------
    depth
        (H, W) float metres or uint16 millimetres.
    camera
        The depth camera.
    background
        The empty scene's depth (H, W), or None.
    previous
        In a video, the previous frame's result: its planes are reused and the person
        it found stays chosen when someone else comes nearer.

    Raises
    ------
    NoBodyError
        Nothing looks like a person (the message says what was found).
    InvalidInputError
        A bad argument.
    """

# ---- pipeline -----------------------------------------------------------------------
JOINT_NAMES: list[str]
"""The 15 joints of every result, in the order of ``PoseResult.joints`` (rows) and of
the ground truth the evaluation tools read: Head, Neck, RShoulder, LShoulder, RElbow,
LElbow, RHand, LHand, Torso, RHip, LHip, RKnee, LKnee, RFoot, LFoot."""

@final
class PipelineConfig:
    """Settings of the estimator and the tracker; keyword arguments, each optional.

    Parameters
    ----------
    candidates
        Template candidates taken from the search from scratch (each also gives its
        left/right-swapped and mirrored-view hypotheses). Default 4.
    hypotheses
        Hypotheses, ranked by depth discrepancy, refined by brief EM fits; the best of
        each view the search looks at first (as it is and, for a tilted silhouette,
        turned upright head up and head down) is always among them. Default 20.
    back_views
        Each template hypothesis is also tried turned around (seen from behind).
        Default True.
    any_roll
        The search also looks at the frame rotated about the optical axis: the views
        that turn a leaning or lying body upright, head up and head down, and, for a
        body explained badly, every eighth of a turn. From scratch, a body that these
        first views read badly is also searched on each of them alone
        (``timings["views"]``). Default True.
    limb_poses
        From scratch (``estimate`` and a track's first frame), the search's best fit
        also tries each limb in a wider set of poses (arms overhead or in a V, kicks, a
        leg out sideways, a crouch, …), one limb at a time, and keeps a limb pose whose
        refitted body explains the depth better. Default True.
    candidate_iterations
        EM iterations of each brief fit, one per hypothesis, started from the hypothesis
        or from its copy moved onto the observed body, whichever explains the depth
        better. Default 2.
    finals
        The best brief fits refined fully. Default 5.
    final_iterations
        EM iterations of each final (None: ``fit.max_iterations``). Default 10.
    candidate_stride, final_stride
        Pixel strides of the brief and the final fits. Default 2 and 2.
    prior_weight
        Tracking: weight of the prior toward the predicted pose. Default 100.
    track_iterations, track_stride
        Tracking: EM iterations and pixel stride per frame. Default 4 and 2.
    velocity_damping
        Tracking: share of the last velocity carried into the prediction. Default 0.5.
    min_inlier_share
        Tracking: the track is lost when the body explains less of the person's pixels.
        Default 0.75.
    lost_ratio, lost_discrepancy
        Tracking: ... or its depth discrepancy exceeds this times the recent median, or
        this value (raised by what a stereo rig's depth noise adds). Default 1.6 and
        0.5. A search whose best body explains the depth worse than
        ``lost_discrepancy`` (from scratch, or on a lost frame) also runs on the frame
        seen at every eighth of a turn about the optical axis (with ``any_roll``); from
        scratch its fit is kept when it ranks better by ``switch_margin``.
    recheck_every
        Tracking: the template search also runs every this many frames, not only when
        the track is lost (0 = only when lost). Default 0.
    recheck_hypotheses, lost_hypotheses
        Template hypotheses of a re-check and of a lost frame. Default 4 and 8. A lost
        frame whose best fit still explains the depth worse than ``lost_discrepancy``
        (a cut, say) is searched again with ``hypotheses``.
    switch_margin
        A re-check switches when it explains the depth better by this share; from
        scratch the wide search's and the size end's fits replace the first by the
        same, and on a lost frame a re-initialised limb replaces the tracked one by it
        too. Default 0.05.
    pose_prior_weight
        Weight of the rest-pose penalty where poses compete. Default 0.005.
    penetration_weight
        Weight (per metre) of the arms' depth inside the trunk where poses compete:
        an arm hidden inside the torso contradicts no pixel, and this charges the pose
        no body takes (0 = never). Default 0.3.
    size_range, size_step
        From scratch, unless the estimator or tracker was given a ``model``, the best
        fit is refitted with the body scaled by 1 ± k·``size_step`` up to
        ± ``size_range`` and the size whose body explains the depth best is kept
        (``result.shape``); a tracker does so on its first frame and calibrates the
        shape from there. A result that still explains the depth worse than
        ``lost_discrepancy`` is searched again with the body at the end of the range
        the size search leaned toward (``timings["sizes"]``), and that fit is kept when
        it ranks better by ``switch_margin``. 0 turns it off. Default 0.15 and 0.05.
    calibration_frames, calibration_every, calibration_prior_weight, calibration_rounds
        Tracking: shape calibration over this many usable frames (0 = never), every
        this many, with this prior weight and rounds. Default 8, 1, 1e5 and 3.
    learn_background
        Tracking without a ``background`` frame: learn the scene's static background
        over the frames — per pixel, the farthest depth that stays stable for 8 frames
        outside the person's mask (pixels without readings, and those the person has
        never left, stay unknown) — and, once half of the pixels are known, segment the
        person as what lies clearly in front of it, the automatic support-plane test
        deciding the pixels not yet learned (``result.segmentation_method`` is then
        ``"learned"``). A person standing still is not learned: their pixels are
        excluded, and a learned depth only gives way to a farther stable one. Ignored by
        ``PoseEstimator`` and when a background frame is given. Default False.
    working_focal
        Focal length (pixels) of the working resolution large images are reduced to.
        Default 300.
    fit
        The fits' settings: a FitConfig, a dict of its keyword arguments, or None.

    Raises
    ------
    InvalidInputError
        An unknown name or a nonsensical value (the message names it).
    """

    def __new__(cls, **kwargs: Any) -> PipelineConfig: ...
    def replace(self, **kwargs: Any) -> PipelineConfig: ...
    def as_dict(self) -> dict[str, Any]: ...
    def __getattr__(self, name: str) -> Any: ...

@final
class PoseResult:
    """The pose of one frame."""

    @property
    def pose(self) -> npt.NDArray[np.float64]: ...
    @property
    def joints(self) -> npt.NDArray[np.float64]: ...
    @property
    def joint_names(self) -> list[str]: ...
    @property
    def model(self) -> BodyModel: ...
    @property
    def shape(self) -> npt.NDArray[np.float64]: ...
    @property
    def labels(self) -> npt.NDArray[np.int16]: ...
    @property
    def mask(self) -> npt.NDArray[np.bool_]: ...
    @property
    def energy(self) -> float: ...
    @property
    def iterations(self) -> int: ...
    @property
    def converged(self) -> bool: ...
    @property
    def confidence(self) -> npt.NDArray[np.float64]: ...
    @property
    def timings(self) -> dict[str, float]: ...
    @property
    def source(self) -> str: ...
    @property
    def discrepancy(self) -> float: ...
    @property
    def segmentation_method(self) -> str | None: ...
    @property
    def planes(self) -> list[Plane]: ...
    @property
    def others(self) -> list[Cluster]: ...
    def to_dict(self) -> dict[str, Any]: ...
    def to_json(self) -> str: ...

@final
class PoseEstimator:
    """Pose from scratch, one depth frame at a time.

    Parameters
    ----------
    camera
        The depth camera (the frames' size and intrinsics). Frames from sensors of high
        resolution are processed at a reduced working resolution; results come back in
        the input's pixel grid.
    model
        The subject's body, when its shape is known. Without it the body is
        ``BodyModel()`` (1.75 m reference proportions) scaled, frame by frame, to the
        size that explains the depth best (``config.size_range``).
    templates
        A :class:`TemplateDatabase` (default: the cached default
        database, built on first use).
    config
        A :class:`PipelineConfig` (default: ``PipelineConfig()``).
    background
        A frame of the empty scene (H, W) for background subtraction; without it the
        person is found automatically (:func:`~depthpose.segment_person`).

    Raises
    ------
    InvalidTypeError
        An argument of the wrong type (the message names it).
    InvalidInputError
        A background of the wrong size or content.
    """

    def __new__(
        cls,
        camera: Camera,
        *,
        model: BodyModel | None = None,
        templates: TemplateDatabase | None = None,
        config: PipelineConfig | None = None,
        background: npt.NDArray[np.generic] | None = None,
    ) -> PoseEstimator: ...
    @property
    def camera(self) -> Camera:
        """The camera the frames come from."""
    @property
    def working_camera(self) -> Camera:
        """The camera the pipeline works with (the input's, reduced for large images)."""
    @property
    def model(self) -> BodyModel:
        """The body model fitted with (``BodyModel()`` when none was given)."""
    @property
    def config(self) -> PipelineConfig:
        """The settings."""
    def estimate(
        self, depth: npt.NDArray[np.generic], mask: npt.NDArray[np.generic] | None = None
    ) -> PoseResult:
        """The pose of one frame: the person's pixels (``mask``, else found), the
        template search with its swapped and mirrored hypotheses, EM from the most
        promising, and the pose whose body explains the depth best.

        Parameters
        ----------
        depth
            (H, W) float metres or uint16 millimetres; 0 or NaN = no reading.
        mask
            (H, W) bool: the person's pixels (default: found automatically).

        Returns
        -------
        PoseResult
            The pose, its joints, labels and timings.

        Raises
        ------
        NoBodyError
            No person in the frame.
        InvalidInputError
            A bad argument.
        """
    def person_mask(self, depth: npt.NDArray[np.generic]) -> npt.NDArray[np.bool_]:
        """The person's pixels (H, W) as :meth:`estimate` finds them.

        Parameters
        ----------
        depth
            (H, W) float metres or uint16 millimetres.

        Raises
        ------
        NoBodyError
            No person in the frame.
        """
    def discrepancies(
        self,
        poses: npt.ArrayLike,
        depth: npt.NDArray[np.generic],
        mask: npt.NDArray[np.generic] | None = None,
    ) -> npt.NDArray[np.float64]:
        """How badly each pose explains a frame: the rendered body against the
        person's pixels, the depth difference capped at 0.1 m (0 = perfectly, about
        1 = unrelated).

        Parameters
        ----------
        poses
            (N, 22) poses, or one pose (22,).
        depth
            (H, W) float metres or uint16 millimetres.
        mask
            (H, W) bool: the person's pixels (default: found automatically).

        Returns
        -------
        numpy.ndarray
            (N,) discrepancies.

        Raises
        ------
        NoBodyError
            No person in the frame.
        InvalidInputError
            A bad argument.
        """
    def discrepancy(
        self,
        pose: npt.ArrayLike,
        depth: npt.NDArray[np.generic],
        mask: npt.NDArray[np.generic] | None = None,
    ) -> float:
        """:meth:`discrepancies` of one pose (22,)."""
    def penalty(self, poses: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """What each of ``poses`` (N, 22) is charged on top of its discrepancy when
        poses compete: the rest-pose penalty (:func:`rest_pose_penalty` with
        ``config.pose_prior_weight``) plus ``config.penetration_weight`` times how far
        its arms' axes pass into the trunk beyond a limb radius (metres). (N,)."""

@final
class PoseTracker:
    """Pose through a depth video: each :meth:`update` starts from the previous pose.

    A tracked frame starts from the previous pose moved on by a damped velocity, with a
    prior toward that prediction. When the fit explains too little of the person or the
    depth much worse than lately, the track is lost and the template search runs (the
    tracked pose among its starts). With ``config.recheck_every`` > 0 the search also
    runs every that many frames and the track switches when it finds a clearly better
    pose.

    With ``config.learn_background`` and no ``background``, the tracker learns the
    scene's static background over the frames, outside the person's mask, and segments
    the person in front of it once enough is known (``result.segmentation_method ==
    "learned"``; the learning's time is ``timings["background"]``). What it learned is
    kept across :meth:`reset` (the same camera and scene).

    Parameters
    ----------
    camera, model, templates, config, background
        As for :class:`PoseEstimator`. Without a ``model`` the body's size is found on
        the first frame (again on a few later frames, ``timings["resize"]``, while no
        frame read from scratch is explained well) and the shape is calibrated from
        there.
    calibrate
        Fit the subject's body shape over the first usable frames (default None: when
        no ``model`` is given; a given model is taken as the subject's known shape).

    Raises
    ------
    InvalidTypeError
        An argument of the wrong type (the message names it).
    InvalidInputError
        A background of the wrong size or content.
    """

    def __new__(
        cls,
        camera: Camera,
        *,
        model: BodyModel | None = None,
        templates: TemplateDatabase | None = None,
        config: PipelineConfig | None = None,
        background: npt.NDArray[np.generic] | None = None,
        calibrate: bool | None = None,
    ) -> PoseTracker: ...
    def update(
        self, depth: npt.NDArray[np.generic], mask: npt.NDArray[np.generic] | None = None
    ) -> PoseResult:
        """The pose of the next frame. While calibrating, a usable frame may be kept for
        the shape calibration, and the frame that completes it runs it
        (``timings["calibration"]``).

        Parameters
        ----------
        depth
            (H, W) float metres or uint16 millimetres; 0 or NaN = no reading.
        mask
            (H, W) bool: the person's pixels (default: found automatically).

        Returns
        -------
        PoseResult
            The pose; its ``source`` says whether it was tracked or searched.

        Raises
        ------
        NoBodyError
            No person in the frame.
        InvalidInputError
            A bad argument.
        """
    def reset(self, shape: bool = False) -> None:
        """Forgets the track. The calibrated shape is kept (the same subject) unless
        ``shape`` is true: then the starting model is restored and calibrated again."""
    def start_from(self, pose: npt.NDArray[np.generic]) -> None:
        """Starts the track from a known pose (22,): the next :meth:`update` refines it
        instead of searching the templates."""
    @property
    def camera(self) -> Camera:
        """The camera the frames come from."""
    @property
    def model(self) -> BodyModel:
        """The model tracked with (the calibrated one once calibrated)."""
    @property
    def base_model(self) -> BodyModel:
        """The model the tracker started with."""
    @property
    def config(self) -> PipelineConfig:
        """The settings."""
    @property
    def lost_frames(self) -> int:
        """Frames on which the track was lost and the template search ran."""
    @property
    def switches(self) -> int:
        """Frames on which the track switched to a search's result or re-initialised a limb."""
    @property
    def calibrating(self) -> bool:
        """Whether the tracker is still collecting frames to calibrate the shape."""
    @property
    def calibrated(self) -> bool:
        """Whether the shape calibration ran and succeeded."""
    @property
    def shape_factors(self) -> npt.NDArray[np.float64] | None:
        """The calibrated shape factors (12,) relative to :attr:`base_model`."""
    @property
    def calibration(self) -> ShapeFitResult | None:
        """The shape fit of the calibration (None before or when it failed)."""
    @property
    def calibration_error(self) -> str | None:
        """Why the calibration failed, else None."""
    @property
    def calibration_frame(self) -> int | None:
        """Frames :meth:`update` had been given when the calibration ran."""

@disjoint_base
class StereoPoseTracker:
    """Pose through a video of rectified stereo pairs.

    Parameters
    ----------
    camera
        The left camera (its size and intrinsics; ``fx`` is the focal length of the
        disparity). Left pixel ``x`` matches right pixel ``x - d``.
    baseline
        Distance between the camera centres, metres.
    doffs
        The x-offset of the right principal point from the left one, pixels
        (Middlebury's ``doffs``; 0 for a pair rectified to a common principal point).
    model, templates, config, calibrate
        As for :class:`PoseTracker`.
    background
        The pair ``(left, right)`` of the empty scene, for background subtraction
        (optional: without it the person is found automatically).
    background_depth
        Or the empty scene's depth (H, W) in metres.
    max_disparity
        The largest disparity searched (default: the whole line).
    fattening
        Remove the band of background pixels along the person's outline that take the
        person's disparity (default True).
    disparity_tolerance
        Disparity error (pixels) the segmentation tolerates on a floor, a wall or
        against the background (default 1).
    disparity_sigma
        The matched disparity's standard deviation in pixels (default 0.25, this
        matcher's on textured surfaces): depth noise σ_Z = Z²·disparity_sigma/(f·B)
        grows with depth, and the tracker's lost test allows for the discrepancy it
        adds to a good fit's. 0: no noise model.
    weigh_points
        Weigh each point in the fit by how precisely its depth is known,
        1/(σ² + σ_Z²) (default False: every point alike).

    Raises
    ------
    InvalidInputError
        A bad argument.
    """

    def __new__(
        cls,
        camera: Camera,
        baseline: float,
        *,
        doffs: float = 0.0,
        model: BodyModel | None = None,
        templates: TemplateDatabase | None = None,
        config: PipelineConfig | None = None,
        background: tuple[npt.NDArray[np.generic], npt.NDArray[np.generic]] | None = None,
        background_depth: npt.NDArray[np.generic] | None = None,
        calibrate: bool | None = None,
        max_disparity: int | None = None,
        fattening: bool = True,
        disparity_tolerance: float = 1.0,
        disparity_sigma: float = 0.25,
        weigh_points: bool = False,
    ) -> Self: ...
    def update(
        self,
        left: npt.NDArray[np.generic],
        right: npt.NDArray[np.generic],
        mask: npt.NDArray[np.generic] | None = None,
    ) -> PoseResult:
        """The pose of the next pair.

        Parameters
        ----------
        left, right
            The rectified images, gray (H, W) or colour (H, W, 3), any numeric dtype.
        mask
            (H, W) bool: the person's pixels in the left image (default: found).

        Returns
        -------
        PoseResult
            Its ``timings`` begin with the stereo stage (``stereo``); the pair's
            disparity is :attr:`disparity`.

        Raises
        ------
        NoBodyError
            No person in the pair's depth.
        InvalidInputError
            A bad argument.
        """
    def reset(self, shape: bool = False) -> None:
        """Forgets the video (the track and the last disparity); the calibrated shape
        too when ``shape`` is true."""
    @property
    def disparity(self) -> npt.NDArray[np.float32] | None:
        """The last pair's disparity (H, W) in pixels, NaN unmatched; None before the
        first pair."""
    @property
    def camera(self) -> Camera:
        """The left camera."""
    @property
    def baseline(self) -> float:
        """Distance between the camera centres, metres."""
    @property
    def doffs(self) -> float:
        """The x-offset of the right principal point from the left one, pixels."""
    @property
    def model(self) -> BodyModel:
        """The model fitted with (the calibrated one once calibrated)."""
    @property
    def config(self) -> PipelineConfig:
        """The settings, adapted to the stereo depth's noise."""
    @property
    def shape_factors(self) -> npt.NDArray[np.float64] | None:
        """The calibrated shape factors (12,), when tracking and calibrated."""
    @property
    def calibration_error(self) -> str | None:
        """Why the shape calibration failed, else None."""

@final
class StereoPoseEstimator(StereoPoseTracker):
    """Pose of each rectified pair from scratch: the parameters of
    :class:`StereoPoseTracker` (``calibrate`` has no effect); :meth:`update` takes a
    pair and forgets it."""

    def estimate(
        self,
        left: npt.NDArray[np.generic],
        right: npt.NDArray[np.generic],
        mask: npt.NDArray[np.generic] | None = None,
    ) -> PoseResult:
        """The pose of one pair (as :meth:`StereoPoseTracker.update`)."""

def swap_limbs(pose: npt.NDArray[np.generic]) -> npt.NDArray[np.float64]:
    """The left/right-swapped pose: right and left limb angles exchanged, the lateral
    neck bend negated, the root unchanged (the body mirrored in its own sagittal
    plane). An involution."""

def mirror_view(pose: npt.NDArray[np.generic]) -> npt.NDArray[np.float64]:
    """The mirror image of the posed body in the camera's vertical plane through the
    hip centre: the same silhouette flipped left-right, limbs swapped so that the body
    stays a right-handed one. An involution."""

def rest_pose_penalty(poses: npt.NDArray[np.generic], weight: float) -> npt.NDArray[np.float64]:
    """``weight`` × Σ θ² over the 14 limb angles of each pose (N, 22) → (N,)."""

# ---- synthetic sequences --------------------------------------------------------------
MOTIONS: tuple[str, ...]
"""The motions :func:`make_sequence` renders: "walk", "wave", "squat", "turn",
"arm_raise"."""

def motion_pose(motion: str, t: float) -> npt.NDArray[np.float64]:
    """The joint angles (22,) of ``motion`` at phase ``t`` (modulo 1); the root parts
    are zero."""

def make_sequence(
    motion: str = "wave",
    frames: int = 30,
    camera: Camera | None = None,
    *,
    distance: float = 3.0,
    view_deg: float = 0.0,
    noise: float = 1.0,
    seed: int = 0,
    height: float = 1.75,
    fps: float = 30.0,
    cycles: float = 1.0,
    camera_height: float = 1.2,
    tilt_deg: float = 5.0,
    wall_distance: float | None = None,
) -> dict[str, npt.NDArray[Any]]:
    """A synthetic depth sequence of the body model in a room, through a Kinect-v1-like
    sensor. The same seed gives the same sequence.

    Parameters
    ----------
    motion
        One of :data:`MOTIONS`.
    frames
        Number of frames, 1..10000.
    camera
        The depth camera (default: ``Camera.itop()``, 320×240).
    distance
        The hip centre's distance ahead at the start (m), 0.8..8.
    view_deg
        The subject's yaw (degrees): 0 faces the camera, +90 turns the left side
        toward it.
    noise
        Sensor noise scale, 0..10 (0: the exact render, millimetre-rounded).
    seed
        Seed of the sensor noise.
    height
        The subject's height (m).
    fps
        Frame rate recorded with the sequence.
    cycles
        Motion cycles over the sequence.
    camera_height
        The camera's height above the floor (m).
    tilt_deg
        The camera's downward pitch (degrees).
    wall_distance
        The back wall's distance (m), at least 0.5 m behind the subject (default:
        1.5 m behind).

    Returns
    -------
    dict
        ``depth`` (T, H, W) uint16 millimetres, ``background`` (H, W) uint16 (the empty
        room), ``mask`` (T, H, W) bool (the person), ``joints`` (T, 15, 3) float32
        (camera frame), ``intrinsics`` (4,) [fx, fy, cx, cy], ``joint_names``, ``fps``,
        ``meta`` (the settings as JSON), ``poses`` (T, 22) and ``labels`` (T, H, W)
        int16 (the body part of each person pixel, −1 elsewhere).

    Raises
    ------
    InvalidInputError
        A setting out of range (the message names it).
    """
