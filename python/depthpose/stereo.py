"""Stereo matching by Growing Correspondence Seeds, and disparity → depth.

Images are a rectified pair; left pixel ``x`` matches right pixel ``x - d`` (``d >= 0``).
Unmatched pixels get NaN. See ``docs/design.md`` for the method and its accuracy.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Literal, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from depthpose import _core

__all__ = ["match", "depth_from_disparity", "cli_stereo", "write_pfm"]

_Pair = tuple[NDArray[np.float32], NDArray[np.float32]]


@overload
def match(
    left: ArrayLike,
    right: ArrayLike,
    *,
    max_disparity: int | None = ...,
    window: int = ...,
    threshold: float | None = ...,
    num_seeds: int | None = ...,
    seeds: ArrayLike | None = ...,
    seed: int = ...,
    return_confidence: Literal[False] = ...,
    lr_check: bool = ...,
    subpixel: bool = ...,
    fill_gaps: bool = ...,
    min_segment: int | None = ...,
    similarity: str = ...,
    half_occlusion: bool = ...,
) -> NDArray[np.float32]: ...


@overload
def match(
    left: ArrayLike,
    right: ArrayLike,
    *,
    max_disparity: int | None = ...,
    window: int = ...,
    threshold: float | None = ...,
    num_seeds: int | None = ...,
    seeds: ArrayLike | None = ...,
    seed: int = ...,
    return_confidence: Literal[True],
    lr_check: bool = ...,
    subpixel: bool = ...,
    fill_gaps: bool = ...,
    min_segment: int | None = ...,
    similarity: str = ...,
    half_occlusion: bool = ...,
) -> _Pair: ...


def match(
    left: ArrayLike,
    right: ArrayLike,
    *,
    max_disparity: int | None = None,
    window: int = 5,
    threshold: float | None = None,
    num_seeds: int | None = None,
    seeds: ArrayLike | None = None,
    seed: int = 0,
    return_confidence: bool = False,
    lr_check: bool = False,
    subpixel: bool = True,
    fill_gaps: bool = True,
    min_segment: int | None = None,
    similarity: str = "mncc",
    half_occlusion: bool = True,
) -> NDArray[np.float32] | _Pair:
    """Disparity (H, W) float32 of a rectified pair, NaN where unmatched.

    ``left``/``right``: gray (H, W) or colour (H, W, 3) arrays, uint8 or float, same shape.
    ``max_disparity``: largest disparity searched (default: the whole line).
    ``window``: odd side of the correlation window. ``threshold``: smallest accepted
    correlation (default 0.47). ``num_seeds``: random seeds matched by exhaustive search.
    ``seeds``: extra seeds, an (N, 3) array of rows (x, y, d). ``seed``: RNG seed.
    ``return_confidence``: also return the correlation of each match (NaN unmatched).
    ``lr_check``: keep only matches confirmed right-to-left (twice the time).
    ``fill_gaps``: fill one-pixel gaps that integer uniqueness leaves on slanted surfaces.
    ``min_segment``: drop matched segments smaller than this many pixels (default 200).
    ``half_occlusion``: drop the matches a nearer surface spreads into the band on its
    left that the right camera cannot see (within half a window of a match more than
    2 px farther on the left).
    A uniform (textureless) pair gives an all-NaN result, not an error.
    """
    disparity, confidence = _core.stereo_match(
        _array(left),
        _array(right),
        max_disparity=max_disparity,
        window=window,
        threshold=threshold,
        num_seeds=num_seeds,
        seeds=None if seeds is None else _array(seeds),
        seed=seed,
        lr_check=lr_check,
        subpixel=subpixel,
        fill_gaps=fill_gaps,
        min_segment=min_segment,
        similarity=similarity,
        half_occlusion=half_occlusion,
    )
    return (disparity, confidence) if return_confidence else disparity


def depth_from_disparity(
    disparity: ArrayLike, focal: float, baseline: float, doffs: float = 0.0
) -> NDArray[np.float32]:
    """Depth in metres, Z = baseline·focal / (d + doffs); 0 where there is no disparity."""
    return _core.depth_from_disparity(_array(disparity), focal, baseline, doffs)


def _array(a: ArrayLike) -> object:
    """Numpy arrays pass through (so the native checks see their dtype and size before
    any copy); lists and tuples of numbers are converted; anything else passes for the
    native checks to refuse by name."""
    if isinstance(a, (list, tuple)):
        try:
            return np.asarray(a)
        except (ValueError, TypeError):
            return a  # ragged: the native check names it
    return a


def write_pfm(path: str | Path, image: NDArray[np.float32]) -> None:
    """Writes a single-channel float image as PFM (little-endian, bottom row first);
    NaN is stored as +inf, the Middlebury convention for "unknown"."""
    _core.write_pfm(path, image, nan_as_inf=True)


def _write_disparity(path: Path, disparity: NDArray[np.float32], max_disparity: float) -> None:
    suffix = path.suffix.lower()
    if suffix == ".npy":
        np.save(path, disparity)
    elif suffix == ".pfm":
        write_pfm(path, disparity)
    elif suffix == ".png":
        # 8-bit visualisation: disparity scaled to 0..255 over the range, 0 unmatched.
        scale = 255.0 / max(max_disparity, 1.0)
        vis = np.where(np.isnan(disparity), 0.0, np.clip(disparity * scale, 0, 255))
        gray = vis.astype(np.uint8)
        _core.write_rgb_png(str(path), np.repeat(gray[:, :, None], 3, axis=2))
    else:
        raise _core.InvalidInputError(f"--out: unsupported extension {suffix!r} (.npy, .pfm, .png)")


def cli_stereo(argv: list[str]) -> int:
    """`depthpose stereo LEFT RIGHT --out DISP [...]`: match a rectified pair."""
    p = argparse.ArgumentParser(
        prog="depthpose stereo",
        description="Disparity (and depth) of a rectified stereo pair by Growing "
        "Correspondence Seeds.",
    )
    p.add_argument("left", type=Path, help="left image (PNG/TIFF/JPEG)")
    p.add_argument("right", type=Path, help="right image, same size")
    p.add_argument("--out", type=Path, required=True, help="disparity: .npy, .pfm or .png")
    p.add_argument("--depth-out", type=Path, help="depth as 16-bit PNG in millimetres")
    p.add_argument("--focal", type=float, help="focal length in pixels (for --depth-out)")
    p.add_argument("--baseline", type=float, help="baseline in metres (for --depth-out)")
    p.add_argument("--doffs", type=float, default=0.0, help="disparity offset in pixels")
    p.add_argument("--max-disparity", type=int, help="largest disparity searched")
    p.add_argument("--window", type=int, default=5, help="odd correlation window side")
    p.add_argument("--threshold", type=float, help="smallest accepted correlation")
    p.add_argument("--seed", type=int, default=0, help="random seed")
    p.add_argument("--lr-check", action="store_true", help="left-right consistency check")
    args = p.parse_args(argv)
    if args.depth_out is not None and (args.focal is None or args.baseline is None):
        p.error("--depth-out needs --focal and --baseline")
    left = _core.read_image(args.left)
    right = _core.read_image(args.right)
    disparity = match(
        left,
        right,
        max_disparity=args.max_disparity,
        window=args.window,
        threshold=args.threshold,
        seed=args.seed,
        lr_check=args.lr_check,
    )
    matched = np.isfinite(disparity)
    top = float(np.nanmax(disparity)) if matched.any() else 1.0
    _write_disparity(args.out, disparity, args.max_disparity or top)
    if args.depth_out is not None:
        depth = depth_from_disparity(disparity, args.focal, args.baseline, args.doffs)
        # A 16-bit PNG in millimetres holds up to 65.535 m: farther matches (tiny
        # disparities) are written as 0, no reading, and counted.
        far = depth > 65.535
        depth = np.where(far, np.float32(0), depth)
        _core.write_depth_png(str(args.depth_out), depth)
        if far.any():
            print(f"{int(far.sum())} matches beyond 65.535 m written as 0 (no reading)")
    print(f"matched {matched.mean():.1%} of {disparity.shape[1]}x{disparity.shape[0]} pixels")
    return 0
