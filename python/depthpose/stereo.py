"""Stereo matching by Growing Correspondence Seeds, and disparity → depth.

Images are a rectified pair; left pixel ``x`` matches right pixel ``x - d`` (``d >= 0``).
Unmatched pixels get NaN. See ``docs/design.md`` for the method and its accuracy.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from depthpose import _core

from ._core import depth_from_disparity, match

__all__ = ["match", "depth_from_disparity", "cli_stereo", "write_pfm"]


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
