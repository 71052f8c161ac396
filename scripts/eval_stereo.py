#!/usr/bin/env python3
"""Accuracy, density and speed of depthpose's stereo matcher against OpenCV StereoSGBM.

Runs both on the shared Middlebury pairs (../shared/data/stereo: cones, motorcycle) with
the same disparity range and prints a Markdown table:

- bad-1 / bad-2 / bad-4: share of pixels with |d - d_gt| > 1, 2, 4 px among the
  ground-truth pixels each method matched (so a sparse method is judged on what it
  matched; density says how much that is);
- density: share of ground-truth pixels that got a disparity;
- time: best of ``--repeat`` runs, in seconds per megapixel.

OpenCV (``pip install opencv-python-headless``, the ``bench`` extra) is optional: without
it the script reports ours and says so. Usage::

    python scripts/eval_stereo.py [--data ../shared/data/stereo] [--repeat 5]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from depthpose import _core
from depthpose.stereo import match

DEFAULT_DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "stereo"

# SGBM settings: the usual ones for a 5x5 block (OpenCV's sample stereo_match.py):
# P1 = 8·cn·bs², P2 = 32·cn·bs², uniqueness 10 %, speckle filter over 100-px blobs.
SGBM_BLOCK = 5
SGBM_UNIQUENESS = 10
SGBM_SPECKLE_WINDOW = 100
SGBM_SPECKLE_RANGE = 2
SGBM_DISP12_MAX_DIFF = 1


@dataclass
class Pair:
    name: str
    left: np.ndarray  # gray float32 in [0, 1]
    right: np.ndarray
    gt: np.ndarray  # float32 disparity, NaN = unknown
    num_disparities: int  # disparities 0 .. num_disparities - 1 (a multiple of 16)


def read_float_tiff(path: Path) -> np.ndarray:
    """A 32-bit float TIFF (the Middlebury ground truth) via Pillow: the image crate
    behind depthpose reads no float gray TIFF."""
    from PIL import Image

    return np.array(Image.open(path), dtype=np.float32)


def load_pairs(root: Path) -> list[Pair]:
    pairs = []
    cones = root / "cones"
    if cones.is_dir():
        gt = read_float_tiff(cones / "cones_gt_disp_left.tif")
        pairs.append(
            Pair(
                "cones",
                _core.read_gray_image(str(cones / "cones_left.tif")),
                _core.read_gray_image(str(cones / "cones_right.tif")),
                np.where(gt > 0, gt, np.nan).astype(np.float32),
                64,
            )
        )
    moto = root / "motorcycle"
    if moto.is_dir():
        gt = np.load(moto / "motorcycle_disp.npz")["arr_0"]
        pairs.append(
            Pair(
                "motorcycle",
                _core.read_gray_image(str(moto / "motorcycle_left.png")),
                _core.read_gray_image(str(moto / "motorcycle_right.png")),
                np.where(np.isfinite(gt), gt, np.nan).astype(np.float32),
                64,
            )
        )
    return pairs


@dataclass
class Score:
    bad1: float
    bad2: float
    bad4: float
    density: float
    sec_per_mpix: float


def score(disp: np.ndarray, gt: np.ndarray, seconds: float) -> Score:
    known = np.isfinite(gt)
    got = known & np.isfinite(disp)
    err = np.abs(disp[got] - gt[got])
    n = max(int(got.sum()), 1)
    return Score(
        bad1=float((err > 1).sum()) / n,
        bad2=float((err > 2).sum()) / n,
        bad4=float((err > 4).sum()) / n,
        density=float(got.sum()) / max(int(known.sum()), 1),
        sec_per_mpix=seconds / (disp.size / 1e6),
    )


def timed(fn: Callable[[], np.ndarray], repeat: int) -> tuple[np.ndarray, float]:
    best = float("inf")
    out = fn()  # warm-up (thread pools, caches)
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return out, best


def ours(pair: Pair, **options: object) -> Callable[[], np.ndarray]:
    return lambda: match(
        pair.left, pair.right, max_disparity=pair.num_disparities - 1, **options
    )


def sgbm(pair: Pair) -> Optional[Callable[[], np.ndarray]]:
    try:
        import cv2
    except ImportError:
        return None
    left = np.round(pair.left * 255).astype(np.uint8)
    right = np.round(pair.right * 255).astype(np.uint8)
    matcher = cv2.StereoSGBM_create(
        minDisparity=0,
        numDisparities=pair.num_disparities,
        blockSize=SGBM_BLOCK,
        P1=8 * SGBM_BLOCK**2,
        P2=32 * SGBM_BLOCK**2,
        disp12MaxDiff=SGBM_DISP12_MAX_DIFF,
        uniquenessRatio=SGBM_UNIQUENESS,
        speckleWindowSize=SGBM_SPECKLE_WINDOW,
        speckleRange=SGBM_SPECKLE_RANGE,
    )

    def run() -> np.ndarray:
        raw = matcher.compute(left, right)  # int16, 4 fractional bits, < 0 = invalid
        return np.where(raw >= 0, raw / 16.0, np.nan).astype(np.float32)

    return run


def evaluate(root: Path, repeat: int) -> tuple[list[tuple[str, str, Score]], bool]:
    rows = []
    have_cv = True
    for pair in load_pairs(root):
        disp, sec = timed(ours(pair), repeat)
        rows.append((pair.name, "depthpose GCS", score(disp, pair.gt, sec)))
        run = sgbm(pair)
        if run is None:
            have_cv = False
            continue
        disp, sec = timed(run, repeat)
        rows.append((pair.name, "OpenCV StereoSGBM", score(disp, pair.gt, sec)))
    return rows, have_cv


def table(rows: list[tuple[str, str, Score]]) -> str:
    lines = [
        "| pair | method | bad-1 | bad-2 | bad-4 | density | s / Mpix |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, method, s in rows:
        lines.append(
            f"| {name} | {method} | {s.bad1:.1%} | {s.bad2:.1%} | {s.bad4:.1%} "
            f"| {s.density:.1%} | {s.sec_per_mpix:.3f} |"
        )
    return "\n".join(lines)


def main(argv: Optional[list[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder with the pairs")
    p.add_argument("--repeat", type=int, default=5, help="timed runs per method (best kept)")
    args = p.parse_args(argv)
    if not args.data.is_dir():
        print(f"no stereo data at {args.data}", file=sys.stderr)
        return 1
    rows, have_cv = evaluate(args.data, args.repeat)
    print(table(rows))
    if not have_cv:
        print(
            "\nOpenCV is not installed (pip install opencv-python-headless): "
            "StereoSGBM rows are missing."
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
