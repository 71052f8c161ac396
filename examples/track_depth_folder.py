"""Track a person through a folder of depth frames, frame by frame, as from a live camera.

Each frame is read, handed to a :class:`depthpose.PoseTracker` and its joints printed as
soon as they are known; a frame that cannot be read or fitted is reported and skipped.
Replace the folder loop with your camera's frame callback for a live loop.

Usage::

    python examples/track_depth_folder.py FRAMES_DIR --camera kinect-v1 [--glob '*.png']
        [--depth-scale 1000]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import depthpose as dp


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--camera", default="kinect-v1", help=f"one of {dp.Camera.presets()}")
    ap.add_argument("--glob", default="*.png", help="the frame files, sorted by name")
    ap.add_argument("--depth-scale", type=float, default=1000.0, help="units per metre")
    args = ap.parse_args(argv)

    files = sorted(args.folder.glob(args.glob))
    if not files:
        print(f"no files match {args.glob!r} in {args.folder}", file=sys.stderr)
        return 2
    tracker: dp.PoseTracker | None = None
    tracked = 0
    for k, path in enumerate(files):
        try:
            depth = dp.read_depth(path, scale=1.0 / args.depth_scale)
            if tracker is None:
                # The preset's intrinsics, resampled to the frames' size (a Kinect v1
                # preset serves its 320x240 frames too).
                camera = dp.Camera.preset(args.camera)
                if camera.shape != depth.shape:
                    camera = camera.scaled(depth.shape[1] / camera.width)
                tracker = dp.PoseTracker(camera)
            t0 = time.perf_counter()
            result = tracker.update(depth)
            ms = 1000 * (time.perf_counter() - t0)
        except dp.DepthPoseError as e:
            print(f"{path.name}: skipped ({type(e).__name__}: {e})", file=sys.stderr)
            continue
        tracked += 1
        joint = dict(zip(result.joint_names, result.joints.round(2).tolist(), strict=True))
        print(
            f"frame {k:4d} {ms:6.1f} ms {result.source:9s} head {joint['Head']} "
            f"hands {joint['RHand']} {joint['LHand']} (m)"
        )
    print(f"{tracked}/{len(files)} frames tracked", file=sys.stderr)
    return 0 if tracked else 1


if __name__ == "__main__":
    sys.exit(main())
