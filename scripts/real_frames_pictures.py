#!/usr/bin/env python3
"""Pictures of the pipeline on the twelve real Kinect v1 frames of the shared data.

The frames (``real_depth/skeltrack``: 640×480 millimetres, background removed, no
ground truth) are estimated twice: tracked in file order, and each from scratch. Each
result is drawn as the depth image coloured by body part with the skeleton on top (a
joint drawn thin where its confidence is low), and the twelve pictures are tiled into
one contact sheet per mode, numbered in file order.

Usage::

    python scripts/real_frames_pictures.py [--data DIR] [--out DIR]

Writes ``kinect_tracked.png`` and ``kinect_scratch.png`` to ``--out`` (default
``docs/images``). The frames come from Skeltrack (LGPL-3.0); the pictures carry that
license (``docs/images/COPYING.LGPL3``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import depthpose as dp
import numpy as np
from depthpose import viz
from PIL import Image, ImageDraw

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "real_depth" / "skeltrack"
#: Each picture is scaled to this width in the sheet.
TILE_WIDTH = 320


def _frames(folder: Path) -> tuple[list[str], np.ndarray]:
    files = sorted(folder.glob("depth-data-*.u16"))
    if not files:
        raise SystemExit(f"no depth-data-*.u16 frames in {folder}")
    depth = np.stack([np.fromfile(f, "<u2").reshape(480, 640) for f in files])
    return [f.stem for f in files], depth.astype(np.float32) / 1000.0


def _picture(depth: np.ndarray, res: dp.PoseResult, camera: dp.Camera, k: int) -> np.ndarray:
    pic = viz.overlay_labels(viz.colorize_depth(depth), res.labels)
    pic = viz.draw_skeleton(pic, res.joints, camera, confidence=res.confidence)
    h, w = pic.shape[:2]
    img = Image.fromarray(pic).resize((TILE_WIDTH, TILE_WIDTH * h // w), Image.BILINEAR)
    ImageDraw.Draw(img).text((6, 4), f"frame {k}", fill=(255, 255, 0))
    return np.asarray(img)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--out", type=Path, default=Path("docs/images"))
    args = ap.parse_args(argv)
    _, depth = _frames(args.data)
    camera = dp.Camera.preset("kinect-v1")
    tracker = dp.PoseTracker(camera)
    estimator = dp.PoseEstimator(camera)
    modes = {"tracked": tracker.update, "scratch": estimator.estimate}
    args.out.mkdir(parents=True, exist_ok=True)
    for name, step in modes.items():
        pictures = [_picture(d, step(d), camera, k) for k, d in enumerate(depth)]
        path = args.out / f"kinect_{name}.png"
        # A 128-colour palette keeps the sheet small; the part colours are few.
        sheet = Image.fromarray(viz.montage(pictures, columns=4))
        sheet.quantize(128).save(path, optimize=True)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
