#!/usr/bin/env python3
"""Accuracy, density and speed of depthpose's stereo matcher against OpenCV StereoSGBM.

Runs both on the shared Middlebury pairs (../shared/data/stereo: cones, motorcycle) with
the same disparity range and prints a Markdown table:

- bad-1 / bad-2 / bad-4: share of pixels with |d - d_gt| > 1, 2, 4 px among the
  ground-truth pixels each method matched (so a sparse method is judged on what it
  matched; density says how much that is);
- density: share of ground-truth pixels that got a disparity;
- time: best of ``--repeat`` runs (the methods take turns), in seconds per megapixel,
  as wall-clock time and as CPU time of the process (all threads). On a shared machine
  the wall time depends on the load; the CPU time much less;
- the CPU-time ratio to each SGBM mode, run by run (median and quartiles): the methods
  run back to back in each repeat, so the ratio cancels the machine's speed swings that
  best-of-N times of separate methods do not.

SGBM runs in two modes: OpenCV's default (``MODE_SGBM``, single-threaded, 5 paths) and
``MODE_SGBM_3WAY`` (3 paths, parallel over rows: OpenCV's fastest SGBM on several
cores, and on these pairs no less accurate). The issue's target compares with SGBM; a
user with several cores would pick the 3-way mode, so both rows are shown.

OpenCV (``pip install opencv-python-headless``, the ``bench`` extra) is optional: without
it the script reports ours and says so. Usage::

    python scripts/eval_stereo.py [--data ../shared/data/stereo] [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

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
                _core.read_image(str(cones / "cones_left.tif")),
                _core.read_image(str(cones / "cones_right.tif")),
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
                _core.read_image(str(moto / "motorcycle_left.png")),
                _core.read_image(str(moto / "motorcycle_right.png")),
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
    cpu_sec_per_mpix: float


def score(disp: np.ndarray, gt: np.ndarray, seconds: float, cpu_seconds: float = 0.0) -> Score:
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
        cpu_sec_per_mpix=cpu_seconds / (disp.size / 1e6),
    )


def timed(
    fns: list[Callable[[], np.ndarray]], repeat: int
) -> list[tuple[np.ndarray, list[float], list[float]]]:
    """Output, wall times and CPU times (s) of `repeat` runs of each function.

    The functions take turns within each repeat, so a slow phase of a shared machine
    hits all of them alike instead of whichever happened to run during it.
    """
    outs = [fn() for fn in fns]  # warm-up (thread pools, caches)
    wall: list[list[float]] = [[] for _ in fns]
    cpu: list[list[float]] = [[] for _ in fns]
    for _ in range(repeat):
        for i, fn in enumerate(fns):
            t0, c0 = time.perf_counter(), time.process_time()
            outs[i] = fn()
            wall[i].append(time.perf_counter() - t0)
            cpu[i].append(time.process_time() - c0)
    return list(zip(outs, wall, cpu, strict=True))


def paired_ratio(ours_cpu: list[float], theirs_cpu: list[float]) -> tuple[float, float, float]:
    """Median and quartiles of our CPU time over theirs, repeat by repeat.

    Each repeat runs the methods back to back, so their ratio cancels the machine's
    slow and fast phases that make best-of-N times of separate methods drift apart
    (on a shared virtual machine the speed swings by tens of percent within minutes).
    """
    r = np.asarray(ours_cpu) / np.asarray(theirs_cpu)
    q1, med, q3 = np.percentile(r, [25, 50, 75])
    return float(med), float(q1), float(q3)


def ours(pair: Pair, **options: object) -> Callable[[], np.ndarray]:
    return lambda: match(pair.left, pair.right, max_disparity=pair.num_disparities - 1, **options)


def sgbm(pair: Pair, three_way: bool = False) -> Callable[[], np.ndarray] | None:
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
        mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY if three_way else cv2.STEREO_SGBM_MODE_SGBM,
    )

    def run() -> np.ndarray:
        raw = matcher.compute(left, right)  # int16, 4 fractional bits, < 0 = invalid
        return np.where(raw >= 0, raw / 16.0, np.nan).astype(np.float32)

    return run


def evaluate(
    root: Path, repeat: int
) -> tuple[list[tuple[str, str, Score]], list[tuple[str, str, tuple[float, float, float]]], bool]:
    rows = []
    ratios = []
    have_cv = True
    for pair in load_pairs(root):
        methods: list[tuple[str, Callable[[], np.ndarray]]] = [("depthpose GCS", ours(pair))]
        for three_way, name in [(False, "OpenCV StereoSGBM"), (True, "OpenCV StereoSGBM 3-way")]:
            run = sgbm(pair, three_way)
            if run is None:
                have_cv = False
                break
            methods.append((name, run))
        results = timed([fn for _, fn in methods], repeat)
        for (name, _), (disp, wall, cpu) in zip(methods, results, strict=True):
            rows.append((pair.name, name, score(disp, pair.gt, min(wall), min(cpu))))
        ours_cpu = results[0][2]
        for (name, _), (_, _, cpu) in zip(methods[1:], results[1:], strict=True):
            ratios.append((pair.name, name, paired_ratio(ours_cpu, cpu)))
    return rows, ratios, have_cv


def table(rows: list[tuple[str, str, Score]]) -> str:
    lines = [
        "| pair | method | bad-1 | bad-2 | bad-4 | density | wall s / Mpix | CPU s / Mpix |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, method, s in rows:
        lines.append(
            f"| {name} | {method} | {s.bad1:.1%} | {s.bad2:.1%} | {s.bad4:.1%} "
            f"| {s.density:.1%} | {s.sec_per_mpix:.3f} | {s.cpu_sec_per_mpix:.3f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder with the pairs")
    p.add_argument("--repeat", type=int, default=5, help="timed runs per method (best kept)")
    p.add_argument("--threads", type=int, help="threads for both methods (default: all)")
    args = p.parse_args(argv)
    if not args.data.is_dir():
        print(f"no stereo data at {args.data}", file=sys.stderr)
        return 1
    if args.threads is not None:
        # Ours uses rayon's global pool: the variable must be set before its first use.
        os.environ["RAYON_NUM_THREADS"] = str(args.threads)
        try:
            import cv2

            cv2.setNumThreads(args.threads)
        except ImportError:
            pass
    rows, ratios, have_cv = evaluate(args.data, args.repeat)
    print(table(rows))
    if ratios:
        print(f"\nCPU time of depthpose GCS over the peer's, run by run ({args.repeat} runs):")
        for name, method, (med, q1, q3) in ratios:
            print(f"- {name}, {method}: median {med:.2f}x (quartiles {q1:.2f}-{q3:.2f})")
    if not have_cv:
        print(
            "\nOpenCV is not installed (pip install opencv-python-headless): "
            "StereoSGBM rows are missing."
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
