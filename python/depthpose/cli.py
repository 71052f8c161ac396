"""The ``depthpose`` command line."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from . import DepthPoseError, __version__

__all__ = ["main"]


def _cmd_foreground(args: argparse.Namespace) -> int:
    """Foreground masks of depth frames, written as pictures."""
    from . import foreground_mask, read_depth, viz

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    background = read_depth(args.background) if args.background else None
    failures = 0
    for path in args.inputs:
        try:
            depth = read_depth(path, scale=args.depth_scale)
            mask = foreground_mask(depth, background)
        except DepthPoseError as e:
            print(f"{path}: {e}", file=sys.stderr)
            failures += 1
            continue
        pic = viz.overlay_mask(viz.colorize_depth(depth), mask)
        viz.save_png(out / (Path(path).stem + "_foreground.png"), pic)
        print(f"{path}: {int(mask.sum())} body pixels")
    return 1 if failures else 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="depthpose", description="3-D human pose from depth images and stereo pairs."
    )
    p.add_argument("--version", action="version", version=f"depthpose {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    demo = sub.add_parser("demo", help="run the pipeline on built-in synthetic data")
    demo.add_argument("--out", default="depthpose-demo", help="folder for results and pictures")
    demo.add_argument("--frames", type=int, default=30, help="number of frames")
    demo.set_defaults(func=_cmd_demo)

    fg = sub.add_parser("foreground", help="foreground masks of depth images, as pictures")
    fg.add_argument("inputs", nargs="+", help="depth images (.png, .npy, .pfm, .u16)")
    fg.add_argument("--out", required=True, help="output folder")
    fg.add_argument("--background", help="depth image of the empty scene")
    fg.add_argument("--depth-scale", type=float, default=0.001, help="metres per unit")
    fg.set_defaults(func=_cmd_foreground)
    return p


def _cmd_demo(args: argparse.Namespace) -> int:
    from . import demo

    return demo.run(Path(args.out), frames=args.frames)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    t0 = time.perf_counter()
    try:
        rc = int(args.func(args))
    except DepthPoseError as e:
        print(f"depthpose: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("depthpose: interrupted", file=sys.stderr)
        return 130
    if args.command != "demo":
        print(f"done in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return rc


if __name__ == "__main__":  # pragma: no cover
    np.seterr(all="ignore")
    sys.exit(main())
