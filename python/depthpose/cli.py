"""The ``depthpose`` command line."""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from . import DepthPoseError, InvalidInputError, __version__

__all__ = ["main"]


def _check_writable(out: Path) -> None:
    """Creates `out`'s folder and writes (and removes) a probe file there, so that a long
    job whose output cannot be written fails before the work, not after it."""
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out.parent, prefix=".depthpose-probe-"):
            pass
    except OSError as e:
        raise InvalidInputError(f"--out {out}: cannot write there ({e.strerror or e})") from None


def _failure(e: Exception) -> str:
    """How a frame's error is reported: its class and message (an exception that is not
    a DepthPoseError is a bug, and says so)."""
    if isinstance(e, DepthPoseError):
        return f"{type(e).__name__}: {e}"
    return f"internal error (please report it) {type(e).__name__}: {e}"


def _exit_code(done: int, failed: int) -> int:
    """0 when every item succeeded, 1 when some failed, 2 when none could be done."""
    if failed == 0:
        return 0
    return 1 if done > 0 else 2


def _cmd_foreground(args: argparse.Namespace) -> int:
    """Foreground masks of depth frames, written as pictures, image by image: an image
    that fails is reported and the others are written."""
    from . import foreground_mask, read_depth, viz

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    background = read_depth(args.background, scale=args.depth_scale) if args.background else None
    done = failed = 0
    for path in args.inputs:
        try:
            depth = read_depth(path, scale=args.depth_scale)
            mask = foreground_mask(depth, background)
            pic = viz.overlay_mask(viz.colorize_depth(depth), mask)
            viz.save_png(out / (Path(path).stem + "_foreground.png"), pic)
        except Exception as e:  # one image's failure must not stop the others
            print(f"{path}: {_failure(e)}", file=sys.stderr)
            failed += 1
            continue
        done += 1
        print(f"{path}: {int(mask.sum())} body pixels")
    if failed:
        print(f"{done}/{done + failed} images done, {failed} failed", file=sys.stderr)
    return _exit_code(done, failed)


def _cmd_estimate(args: argparse.Namespace) -> int:
    """Poses of every frame of a sequence, a folder of frames or one image, frame by
    frame: a frame that cannot be read or estimated is reported (which, why) and
    recorded as NaN; the others are estimated and written."""
    import json

    from .pipeline import JOINT_NAMES, PoseEstimator, PoseTracker
    from .sequence import open_sequence

    seq = open_sequence(args.input, intrinsics=args.intrinsics, depth_scale=args.depth_scale)
    out = Path(args.out)
    _check_writable(out)
    viz_dir = Path(args.viz) if args.viz else None
    if viz_dir:
        viz_dir.mkdir(parents=True, exist_ok=True)
    jsonl = open(args.jsonl, "w") if args.jsonl else None  # noqa: SIM115
    n = seq.n_frames
    joints = np.full((n, 15, 3), np.nan)
    pose = np.full((n, 22), np.nan)
    confidence = np.zeros((n, 15))
    errors: list[tuple[int, str]] = []
    if args.track:
        tracker = PoseTracker(seq.camera, background=seq.background)
        step = tracker.update
    else:
        step = PoseEstimator(seq.camera, background=seq.background).estimate
    t0 = time.perf_counter()
    try:
        for k, frame in seq.iter_frames():
            sys.stderr.write(f"\rframe {k + 1}/{n}")
            try:
                if isinstance(frame, Exception):
                    raise frame
                res = step(frame)
                if viz_dir:
                    from . import viz

                    pic = viz.overlay_labels(viz.colorize_depth(frame), res.labels)
                    pic = viz.draw_skeleton(pic, res.joints, seq.camera)
                    viz.save_png(viz_dir / f"frame_{k:05d}.png", pic)
            except Exception as e:  # one frame's failure must not stop the others
                if args.track:
                    tracker.reset()
                joints[k], pose[k], confidence[k] = np.nan, np.nan, 0.0
                errors.append((k, _failure(e)))
                if jsonl:
                    jsonl.write(json.dumps({"frame": k, "joints": None, "error": errors[-1][1]}))
                    jsonl.write("\n")
                continue
            joints[k], pose[k], confidence[k] = res.joints, res.pose, res.confidence
            if jsonl:
                jsonl.write(json.dumps({"frame": k, **res.to_dict()}) + "\n")
    finally:
        sys.stderr.write("\n")
        if jsonl:
            jsonl.close()
    for k, message in errors:
        print(f"frame {k} ({seq.frame_name(k)}): {message}", file=sys.stderr)
    np.savez(
        out, joints=joints, pose=pose, confidence=confidence,
        joint_names=np.array(JOINT_NAMES),
        failed_frames=np.array([k for k, _ in errors], np.int64),
        errors=np.array([m for _, m in errors], dtype=str),
    )  # fmt: skip
    dt = time.perf_counter() - t0
    done = n - len(errors)
    print(f"{done}/{n} frames estimated in {dt:.1f} s ({n / max(dt, 1e-9):.1f} frames/s)")
    if seq.gt_joints is not None and seq.gt_joints.shape == joints.shape:
        from .metrics import evaluate

        acc = evaluate(joints, seq.gt_joints)
        print(f"against the sequence's joints: MPJPE {acc['mpjpe_mm']:.1f} mm, "
              f"PCK@10cm {100 * acc['pck']:.1f} %")  # fmt: skip
    return _exit_code(done, len(errors))


def _cmd_batch(args: argparse.Namespace) -> int:
    from .batch import run

    summary = run(
        args.inputs, args.out, scheduler=args.scheduler, n_workers=args.workers,
        chunk_frames=args.chunk_frames, overlap=args.overlap, track=args.track,
        intrinsics=args.intrinsics, depth_scale=args.depth_scale, templates=args.templates,
    )  # fmt: skip
    print(summary.report())
    return 0 if summary.failed_frames == 0 and not summary.failed_sequences else 1


def _cmd_stereo(args: argparse.Namespace) -> int:
    from .stereo import cli_stereo

    return cli_stereo(args.stereo_args)


def _cmd_templates(args: argparse.Namespace) -> int:
    from .templates import TemplateDatabase

    if args.action == "build":
        db = TemplateDatabase.build(progress=True)
        path = Path(args.out) if args.out else TemplateDatabase.default_path()
        db.save(path)
        print(f"{len(db)} templates written to {path}")
    else:
        path = Path(args.out) if args.out else TemplateDatabase.default_path()
        db = TemplateDatabase.load(path)
        print(f"{path}: {len(db)} templates")
    return 0


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

    est = sub.add_parser("estimate", help="poses of a depth sequence or image")
    est.add_argument(
        "input", help=".npz sequence (shared layout), folder of depth frames, or image"
    )
    est.add_argument("--out", required=True, help="output .npz (joints, pose, confidence)")
    est.add_argument("--viz", help="folder for a picture of each frame")
    est.add_argument("--jsonl", help="also write one JSON line per frame here")
    est.add_argument(
        "--track",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="track through the sequence (default) or estimate each frame",
    )
    est.add_argument("--intrinsics", type=float, nargs=4, metavar=("FX", "FY", "CX", "CY"))
    est.add_argument("--depth-scale", type=float, default=0.001, help="metres per unit")
    est.set_defaults(func=_cmd_estimate)
    est.epilog = (
        "Frames are estimated one by one: a frame that cannot be read or estimated is "
        "reported on stderr and recorded as NaN (its index and error are in the output's "
        "failed_frames and errors). Exit code 0: every frame estimated; 1: some failed; "
        "2: none could be (or the input could not be opened)."
    )

    bat = sub.add_parser("batch", help="many sequences on a Dask cluster, resumable")
    bat.add_argument("inputs", nargs="+", help="sequences (.npz), frame folders or globs")
    bat.add_argument("--out", required=True, help="output folder")
    bat.add_argument("--scheduler", help="address of a Dask scheduler (tcp://host:port)")
    bat.add_argument("--workers", type=int, help="local workers (default: one per core)")
    bat.add_argument("--chunk-frames", type=int, default=32)
    bat.add_argument("--overlap", type=int, default=4, help="warm-up frames per chunk")
    bat.add_argument("--track", action=argparse.BooleanOptionalAction, default=True)
    bat.add_argument("--intrinsics", type=float, nargs=4, metavar=("FX", "FY", "CX", "CY"))
    bat.add_argument("--depth-scale", type=float, default=0.001)
    bat.add_argument("--templates", help="a saved template database to share")
    bat.set_defaults(func=_cmd_batch)

    st = sub.add_parser("stereo", help="disparity (and depth) of a rectified stereo pair",
                        add_help=False)  # fmt: skip
    st.add_argument("stereo_args", nargs=argparse.REMAINDER)
    st.set_defaults(func=_cmd_stereo)

    tp = sub.add_parser("templates", help="build or inspect the template database")
    tp.add_argument("action", choices=["build", "info"])
    tp.add_argument("--out", help="file (default: the cache used by default)")
    tp.set_defaults(func=_cmd_templates)

    fg = sub.add_parser("foreground", help="foreground masks of depth images, as pictures")
    fg.add_argument("inputs", nargs="+", help="depth images (.png, .npy, .pfm, .u16)")
    fg.add_argument("--out", required=True, help="output folder")
    fg.add_argument("--background", help="depth image of the empty scene")
    fg.add_argument("--depth-scale", type=float, default=0.001, help="metres per unit")
    fg.set_defaults(func=_cmd_foreground)
    fg.epilog = "Exit code 0: every image done; 1: some failed; 2: none could be."
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
    except OSError as e:  # e.g. an output file that cannot be written
        where = f"{e.filename}: " if e.filename else ""
        print(f"depthpose: error: {where}{e.strerror or e}", file=sys.stderr)
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
