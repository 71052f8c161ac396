"""The 3-D pose of a person from one rectified stereo pair.

The pair is matched by seed-growing stereo, the disparity turned into depth with the
rig's focal length and baseline, and the body fitted to it from scratch; the joints
are printed and, with ``--picture``, drawn over the left image.

Usage::

    python examples/stereo_pair_to_pose.py LEFT.png RIGHT.png --intrinsics FX FY CX CY
        --baseline 0.12 [--doffs 0] [--picture pose.png]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import depthpose as dp
import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("left", type=Path)
    ap.add_argument("right", type=Path)
    ap.add_argument(
        "--intrinsics", type=float, nargs=4, required=True, metavar=("FX", "FY", "CX", "CY"),
        help="the left camera, in pixels",
    )  # fmt: skip
    ap.add_argument("--baseline", type=float, required=True, help="metres")
    ap.add_argument("--doffs", type=float, default=0.0, help="x offset of the principal points")
    ap.add_argument("--picture", type=Path, help="write the joints over the left image here")
    args = ap.parse_args(argv)

    try:
        left, right = dp.read_image(args.left), dp.read_image(args.right)
        camera = dp.Camera.from_intrinsics(args.intrinsics, left.shape[:2])
        result = dp.estimate_stereo(left, right, camera, args.baseline, doffs=args.doffs)
    except dp.DepthPoseError as e:
        print(f"{type(e).__name__}: {e}", file=sys.stderr)
        return 1
    print(f"body found: {result.mask.sum()} pixels, depth discrepancy {result.discrepancy:.3f}")
    rows = zip(result.joint_names, result.joints, result.confidence, strict=True)
    for name, (x, y, z), c in rows:
        print(f"{name:10s} x {x:+.3f}  y {y:+.3f}  z {z:.3f} m  confidence {c:.2f}")
    if args.picture:
        gray = (255 * left).astype(np.uint8)
        rgb = dp.viz.overlay_labels(np.dstack([gray, gray, gray]), result.labels)
        picture = dp.viz.draw_skeleton(rgb, result.joints, camera, confidence=result.confidence)
        dp.viz.save_png(args.picture, picture)
        print(f"picture: {args.picture}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
