"""Pictures: depth colour maps, masks and labels over depth, skeletons (numpy only;
the 3-D views use matplotlib from the ``viz`` extra)."""

from __future__ import annotations

import os
from typing import Any, Union

import numpy as np

from . import _core, _validate
from ._core import InvalidInputError, InvalidTypeError

PathLike = Union[str, "os.PathLike[str]"]

__all__ = [
    "BONES",
    "PART_COLORS",
    "colorize_depth",
    "draw_skeleton",
    "montage",
    "overlay_labels",
    "overlay_mask",
    "plot_body_3d",
    "save_gif",
    "save_png",
]

#: Distinct colours for up to 16 labels (body parts), RGB uint8.
PART_COLORS = np.array(
    [
        [230, 25, 75],
        [60, 180, 75],
        [255, 225, 25],
        [0, 130, 200],
        [245, 130, 48],
        [145, 30, 180],
        [70, 240, 240],
        [240, 50, 230],
        [210, 245, 60],
        [250, 190, 212],
        [0, 128, 128],
        [220, 190, 255],
        [170, 110, 40],
        [255, 250, 200],
        [128, 0, 0],
        [170, 255, 195],
    ],
    dtype=np.uint8,
)


def colorize_depth(
    depth: np.ndarray, near: float | None = None, far: float | None = None
) -> np.ndarray:
    """(H, W, 3) uint8: near is bright, far is dark, no reading (0, NaN) is black.
    ``depth``: a 2-D array of numbers (metres, or any unit with ``near``/``far`` in it)."""
    d = _picture_values(depth, "depth")
    if d.ndim != 2:
        raise InvalidInputError(f"depth: expected a 2-D array, got shape {d.shape}")
    valid = np.isfinite(d) & (d > 0)
    if not valid.any():
        return np.zeros((*d.shape, 3), np.uint8)
    lo = float(np.percentile(d[valid], 1)) if near is None else _validate.number(near, "near")
    hi = float(np.percentile(d[valid], 99)) if far is None else _validate.number(far, "far")
    t = np.clip((hi - np.where(valid, d, hi)) / max(hi - lo, 1e-6), 0, 1)
    g = (40 + 215 * t).astype(np.uint8)
    rgb = np.stack([g, g, g], axis=-1)
    rgb[~valid] = 0
    return rgb


def _picture_values(value: object, name: str) -> np.ndarray:
    """A numeric array (NaN allowed) as float32, within the image size limit."""
    a = _validate.array(value, name, image=4)
    why = _core._not_numbers(a.dtype)
    if why is not None:
        cls = InvalidInputError if a.dtype.kind == "b" else InvalidTypeError
        raise cls(f"{name}: dtype {a.dtype}: {why}")
    return a.astype(np.float32)


def _rgb(rgb: object, name: str = "rgb") -> np.ndarray:
    """An (H, W, 3) picture of integers in 0..255 (uint8 or another integer type) as
    float32."""
    a = _validate.array(rgb, name, image=3)
    if a.ndim != 3 or a.shape[2] != 3:
        raise InvalidInputError(f"{name}: expected an (H, W, 3) picture, got shape {a.shape}")
    if a.dtype.kind not in "iu":
        raise (InvalidInputError if a.dtype.kind in "fb" else InvalidTypeError)(
            f"{name}: expected integers 0..255 (uint8), got dtype {a.dtype}"
        )
    if a.size and (a.min() < 0 or a.max() > 255):
        raise InvalidInputError(f"{name}: values must be in 0..255")
    return a.astype(np.float32)


def _alpha(alpha: object) -> float:
    return _validate.number(alpha, "alpha", low=0.0, high=1.0)


def _color(color: object) -> np.ndarray:
    c = np.asarray(color) if isinstance(color, (tuple, list)) else color
    c = _validate.numbers_array(c, "color", ndim=1)
    if c.shape != (3,) or (c < 0).any() or (c > 255).any():
        raise InvalidInputError(f"color: expected (r, g, b) in 0..255, got {color!r}")
    return c.astype(np.float32)


def overlay_mask(
    rgb: np.ndarray,
    mask: np.ndarray,
    color: tuple[int, int, int] = (60, 200, 90),
    alpha: float = 0.5,
) -> np.ndarray:
    """Tints the pixels of ``mask`` (H, W) in ``color``. ``mask`` is a bool array (or
    integers 0 and 1), as everywhere in depthpose: an integer mask is not an index."""
    out = _rgb(rgb)
    m = _validate.mask(mask, out.shape[:2])
    a = _alpha(alpha)
    out[m] = (1 - a) * out[m] + a * _color(color)
    return out.astype(np.uint8)


def overlay_labels(rgb: np.ndarray, labels: np.ndarray, alpha: float = 0.6) -> np.ndarray:
    """Colours each labelled pixel (label >= 0; labels (H, W) integers) by its part."""
    out = _rgb(rgb)
    lab = _validate.array(labels, "labels", image=1)
    if lab.shape != out.shape[:2]:
        raise InvalidInputError(f"labels: shape {lab.shape} does not match {out.shape[:2]}")
    if lab.dtype.kind not in "iu":
        raise InvalidInputError(f"labels: expected integer labels, got dtype {lab.dtype}")
    alpha = _alpha(alpha)
    on = lab >= 0
    colors = PART_COLORS[lab[on] % len(PART_COLORS)].astype(np.float32)
    out[on] = (1 - alpha) * out[on] + alpha * colors
    return out.astype(np.uint8)


def montage(images: list[np.ndarray], columns: int = 4, pad: int = 2) -> np.ndarray:
    """Tiles equally sized (H, W, 3) images into one picture."""
    if not isinstance(images, (list, tuple)) or not images:
        raise InvalidInputError("images: need a list of at least one image")
    columns = _validate.integer(columns, "columns", low=1, high=4096)
    pad = _validate.integer(pad, "pad", low=0, high=4096)
    images = [_rgb(im, f"images[{k}]").astype(np.uint8) for k, im in enumerate(images)]
    h, w = images[0].shape[:2]
    for k, im in enumerate(images):
        if im.shape[:2] != (h, w):
            raise InvalidInputError(f"images[{k}]: shape {im.shape} differs from {(h, w, 3)}")
    rows = (len(images) + columns - 1) // columns
    out = np.zeros((rows * (h + pad) - pad, columns * (w + pad) - pad, 3), np.uint8)
    for k, im in enumerate(images):
        r, c = divmod(k, columns)
        out[r * (h + pad) : r * (h + pad) + h, c * (w + pad) : c * (w + pad) + w] = im
    return out


def save_png(path: PathLike, rgb: np.ndarray) -> None:
    """Writes an (H, W, 3) picture (integers 0..255, e.g. uint8) as PNG."""
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidTypeError(f"path: expected a path (str or os.PathLike), got {type(path)}")
    _core.write_rgb_png(os.fspath(path), rgb)


#: Bones of the 15-joint skeleton (ITOP order), as joint index pairs.
BONES = [
    (0, 1), (1, 2), (1, 3), (2, 4), (4, 6), (3, 5), (5, 7), (1, 8), (8, 9), (8, 10),
    (9, 11), (11, 13), (10, 12), (12, 14),
]  # fmt: skip

#: Colours: the subject's right side red, left side blue, centre yellow.
SIDE_COLORS = {"R": (230, 40, 40), "L": (40, 90, 240), "C": (240, 210, 40)}
_JOINT_SIDE = "CCRLRLRLCRLRLRL"


def _drawable(a: np.ndarray, b: np.ndarray, h: int, w: int) -> bool:
    """Whether the segment a–b is worth drawing: finite, and not absurdly long (a joint
    near the camera plane projects far outside the picture)."""
    if not np.isfinite([*a, *b]).all():
        return False
    return bool(max(abs(b[0] - a[0]), abs(b[1] - a[1])) <= 4 * (h + w))


def draw_skeleton(
    rgb: np.ndarray,
    joints: np.ndarray,
    camera: _core.Camera,
    width: int = 2,
    *,
    confidence: np.ndarray | None = None,
) -> np.ndarray:
    """Draws the 15-joint skeleton (joints (15, 3), camera frame, metres; NaN joints
    are left out) projected into the picture, with Pillow's ``ImageDraw``.
    ``confidence`` (15,), a result's per-joint confidence: joints of confidence 0 (not
    seen, such as the legs of an upper-body view) are left out too, with their bones."""
    out = _rgb(rgb).astype(np.uint8)
    if not isinstance(camera, _core.Camera):
        raise InvalidTypeError(f"camera: expected a depthpose.Camera, got {type(camera)}")
    width = _validate.integer(width, "width", low=1, high=64)
    j = _validate.array(
        np.asarray(joints) if isinstance(joints, (list, tuple)) else joints, "joints"
    )
    if j.shape != (15, 3) or _core._not_numbers(j.dtype) is not None:
        raise InvalidInputError(f"joints: expected (15, 3) numbers, got {j.shape} {j.dtype}")
    joints = j.astype(np.float64)
    if np.isinf(joints).any():
        raise InvalidInputError("joints: holds an infinite value")
    if confidence is not None:
        c = _validate.array(
            np.asarray(confidence) if isinstance(confidence, (list, tuple)) else confidence,
            "confidence",
        )
        if c.shape != (15,) or _core._not_numbers(c.dtype) is not None:
            raise InvalidInputError(f"confidence: expected (15,) numbers, got {c.shape} {c.dtype}")
        joints[~(c.astype(np.float64) > 0)] = np.nan
    if not np.isfinite(joints).any():
        return out
    from PIL import Image, ImageDraw

    uv = camera.project(np.nan_to_num(joints, nan=0.0))
    uv[~np.isfinite(joints).all(1)] = np.nan
    h, w = out.shape[:2]
    picture = Image.fromarray(out)
    draw = ImageDraw.Draw(picture)
    for a, b in BONES:
        if _drawable(uv[a], uv[b], h, w):
            side = _JOINT_SIDE[b] if _JOINT_SIDE[b] != "C" else _JOINT_SIDE[a]
            draw.line([tuple(uv[a]), tuple(uv[b])], fill=SIDE_COLORS[side], width=width)
    r = 1.0 + 0.5 * width
    for p in uv:
        if _drawable(p, p, h, w) and -r <= p[0] < w + r and -r <= p[1] < h + r:
            u, v = p
            draw.ellipse([u - r, v - r, u + r, v + r], fill=(255, 255, 255))
    return np.asarray(picture, dtype=np.uint8).copy()


def plot_body_3d(
    model: _core.BodyModel, pose: np.ndarray, ax: Any = None, *, joints: np.ndarray | None = None
) -> Any:
    """A 3-D view of the fitted ellipsoid body and skeleton (matplotlib, ``viz`` extra).
    Returns the axes. Camera frame shown with y (down) flipped so the body stands up."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    if ax is None:
        ax = plt.figure(figsize=(5, 6)).add_subplot(projection="3d")
    flip = np.array([1.0, -1.0, 1.0])
    for k, (v, f) in enumerate(model.superquadric_meshes(pose, 10, 12)):
        v = v * flip
        ax.plot_trisurf(v[:, 0], v[:, 2], v[:, 1], triangles=f, color=PART_COLORS[k] / 255,
                        alpha=0.35, linewidth=0)  # fmt: skip
    j = (model.joints(pose) if joints is None else np.asarray(joints)) * flip
    for a, b in BONES:
        ax.plot(*zip(j[a][[0, 2, 1]], j[b][[0, 2, 1]], strict=False), color="k", linewidth=2)
    ax.scatter(j[:, 0], j[:, 2], j[:, 1], color="k", s=10)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_zlabel("height (m)")
    centre = j.mean(0)
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre[[0, 2, 1]], strict=False):
        setter(c - 1.0, c + 1.0)
    return ax


def save_gif(path: PathLike, pictures: list[np.ndarray], fps: float = 10.0) -> None:
    """An animated GIF of (H, W, 3) uint8 pictures (Pillow)."""
    from PIL import Image

    if not isinstance(pictures, (list, tuple)) or not pictures:
        raise InvalidInputError("pictures: need a list of at least one picture")
    fps = _validate.number(fps, "fps", low=0.0, low_open=True, high=1000.0)
    frames = [
        Image.fromarray(_rgb(p, f"pictures[{k}]").astype(np.uint8)) for k, p in enumerate(pictures)
    ]
    frames[0].save(os.fspath(path), save_all=True, append_images=frames[1:],
                   duration=int(1000 / fps), loop=0)  # fmt: skip
