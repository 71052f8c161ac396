"""Track a depth sequence and export it for Blender, three.js or any BVH tool.

Writes the motion as BVH (standard joint names, y up, with the fitted body's bone
lengths), the body of a chosen frame as a binary glTF mesh, and the joints of every
frame as an ``.npz``. In Blender: File > Import > Motion Capture (.bvh) and glTF 2.0.

Usage::

    python examples/export_to_blender.py SEQUENCE.npz --out export/ [--frame 0]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import depthpose as dp
import numpy as np
from depthpose.sequence import open_sequence


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence", type=Path, help=".npz with depth and intrinsics, or a folder")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--frame", type=int, default=0, help="the frame whose body is meshed")
    args = ap.parse_args(argv)

    seq = open_sequence(args.sequence)
    tracker = dp.PoseTracker(seq.camera, background=seq.background)
    results = [tracker.update(depth) for depth in seq.frames()]
    poses = np.stack([r.pose for r in results])
    confidence = np.stack([r.confidence for r in results])
    # The body as calibrated over the first frames: the last result carries it.
    model = results[-1].model

    args.out.mkdir(parents=True, exist_ok=True)
    dp.export.write_bvh(args.out / "motion.bvh", model, poses, seq.fps, confidence=confidence)
    frame = min(max(args.frame, 0), len(results) - 1)
    dp.export.save_mesh(args.out / "body.glb", model, poses[frame])
    np.savez(args.out / "joints.npz", joints=np.stack([r.joints for r in results]),
             joint_names=results[0].joint_names, pose=poses, shape=results[-1].shape)  # fmt: skip
    print(f"{len(results)} frames: {args.out / 'motion.bvh'}, {args.out / 'body.glb'}, "
          f"{args.out / 'joints.npz'}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
