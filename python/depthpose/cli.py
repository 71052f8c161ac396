"""The ``depthpose`` command line."""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

import numpy as np

from . import Camera, DepthPoseError, InvalidInputError, PipelineConfig, PoseResult, __version__

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


#: Help of ``--depth-scale``: the Open3D convention.
#: A frame of a sequence: a depth image, or a stereo pair.
_Frame = TypeVar("_Frame")

_DEPTH_SCALE_HELP = (
    "integer depth units per metre (Open3D's depth_scale): 1000 for millimetres "
    "(default), 10000 for 0.1 mm; metres = raw / depth_scale. Float files are metres."
)


def _metres_per_unit(depth_scale: float) -> float:
    """The readers' scale (metres per unit) of ``--depth-scale`` (units per metre)."""
    from ._core import MAX_DEPTH_SCALE, MIN_DEPTH_SCALE

    low, high = 1.0 / MAX_DEPTH_SCALE, 1.0 / MIN_DEPTH_SCALE
    if not (np.isfinite(depth_scale) and low <= depth_scale <= high):
        hint = " (it counts units per metre: 1000 for millimetres)" if depth_scale < 1 else ""
        raise InvalidInputError(
            f"--depth-scale: must be in [{low:g}, {high:g}] units per metre, "
            f"got {depth_scale:g}{hint}"
        )
    return 1.0 / depth_scale


def _preset(name: str, shape: tuple[int, int], what: str) -> Camera:
    """The camera preset ``name`` for images of ``shape`` (H, W): the preset itself, or
    the preset resampled when the images have its aspect ratio at another size."""
    cam = Camera.preset(name)
    if cam.shape == shape:
        return cam
    factor = shape[1] / cam.width
    if abs(cam.height * factor - shape[0]) < 0.5:
        return cam.scaled(factor)
    raise InvalidInputError(
        f"--camera {name}: the preset is {cam.width}x{cam.height} pixels but {what} is "
        f"{shape[1]}x{shape[0]}"
    )


def _cmd_foreground(args: argparse.Namespace) -> int:
    """Foreground masks of depth frames, written as pictures, image by image: an image
    that fails is reported and the others are written."""
    from . import foreground_mask, read_depth, viz

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scale = _metres_per_unit(args.depth_scale)
    background = read_depth(args.background, scale=scale) if args.background else None
    done = failed = 0
    for path in args.inputs:
        try:
            depth = read_depth(path, scale=scale)
            camera = _preset(args.camera, depth.shape, path) if args.camera else None
            mask = foreground_mask(depth, background, camera=camera)
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


def _pipeline_config(text: str | None) -> PipelineConfig:
    """``--config``: PipelineConfig fields as a JSON object (default: the defaults)."""
    import json

    if text is None:
        return PipelineConfig()
    try:
        fields = json.loads(text)
    except json.JSONDecodeError as e:
        raise InvalidInputError(f"--config: not valid JSON ({e})") from None
    if not isinstance(fields, dict):
        raise InvalidInputError(
            f"--config: expected a JSON object of PipelineConfig fields, got {text!r}"
        )
    try:
        return PipelineConfig(**fields)
    except DepthPoseError as e:
        raise type(e)(f"--config: {e}") from None


def _cmd_estimate(args: argparse.Namespace) -> int:
    """Poses of every frame of a sequence, a folder of frames or one image, frame by
    frame: a frame that cannot be read or estimated is reported (which, why) and
    recorded as NaN; the others are estimated and written."""
    from .pipeline import PoseEstimator, PoseTracker
    from .sequence import open_sequence

    if args.camera is not None and args.intrinsics is not None:
        raise InvalidInputError("--camera: give either --camera or --intrinsics, not both")
    if args.learn_background and not args.track:
        raise InvalidInputError(
            "--learn-background: needs --track (the background is learned over the frames)"
        )
    seq = open_sequence(
        args.input,
        intrinsics=args.intrinsics,
        depth_scale=_metres_per_unit(args.depth_scale),
        camera=(lambda shape: _preset(args.camera, shape, args.input)) if args.camera else None,
        pattern=args.glob,
    )
    out = Path(args.out)
    _check_writable(out)
    status: Callable[[], str] | None = None
    config = _pipeline_config(args.config)
    if args.learn_background:
        config = config.replace(learn_background=True)
    if args.track:
        tracker = PoseTracker(seq.camera, background=seq.background, config=config)
        step, reset = tracker.update, tracker.reset

        def status() -> str:
            return "calibrating the body shape" if tracker.calibrating else ""

    else:
        estimator = PoseEstimator(seq.camera, background=seq.background, config=config)
        step, reset = estimator.estimate, None

    def picture(depth: np.ndarray, res: PoseResult) -> np.ndarray:
        from . import viz

        pic = viz.overlay_labels(viz.colorize_depth(depth), res.labels)
        return viz.draw_skeleton(pic, res.joints, seq.camera, confidence=res.confidence)

    return _run_frames(
        args, seq.iter_frames(), seq.n_frames, step, reset, picture, seq.frame_name,
        seq.gt_joints, status,
    )  # fmt: skip


def _cmd_estimate_stereo(args: argparse.Namespace) -> int:
    """Poses of rectified stereo pairs (a .npz of pairs, a folder of pairs, or a left and
    a right image), pair by pair, as ``estimate`` does for depth frames."""
    from .stereo_pose import StereoPoseEstimator, StereoPoseTracker
    from .stereo_sequence import open_stereo

    if args.camera is not None and args.intrinsics is not None:
        raise InvalidInputError("--camera: give either --camera or --intrinsics, not both")
    seq = open_stereo(
        args.input,
        args.right,
        baseline=args.baseline,
        doffs=args.doffs,
        intrinsics=args.intrinsics,
        camera=(lambda shape: _preset(args.camera, shape, args.input)) if args.camera else None,
        background=tuple(args.background) if args.background else None,
    )
    out = Path(args.out)
    _check_writable(out)
    kind = StereoPoseTracker if args.track else StereoPoseEstimator
    tracker = kind(
        seq.camera, seq.baseline, doffs=seq.doffs, background=seq.background,
        max_disparity=args.max_disparity,
    )  # fmt: skip
    reset = tracker.reset if args.track else None

    def step(pair: tuple[np.ndarray, np.ndarray]) -> PoseResult:
        return tracker.update(*pair)

    def picture(pair: tuple[np.ndarray, np.ndarray], res: PoseResult) -> np.ndarray:
        from . import viz

        gray = np.asarray(pair[0], dtype=np.float64)
        if gray.ndim == 3:
            gray = gray[..., :3].mean(axis=2)
        top = 255.0 if gray.max(initial=0.0) > 1.0 else 1.0
        rgb = np.repeat((np.clip(gray / top, 0, 1) * 255).astype(np.uint8)[..., None], 3, 2)
        pic = viz.overlay_labels(rgb, res.labels)
        return viz.draw_skeleton(pic, res.joints, seq.camera, confidence=res.confidence)

    return _run_frames(
        args, seq.iter_pairs(), seq.n_frames, step, reset, picture, seq.frame_name,
        seq.gt_joints,
    )  # fmt: skip


def _run_frames(
    args: argparse.Namespace,
    frames: Iterator[tuple[int, _Frame | Exception]],
    n: int,
    step: Callable[[_Frame], PoseResult],
    reset: Callable[[], None] | None,
    picture: Callable[[_Frame, PoseResult], np.ndarray],
    frame_name: Callable[[int], str],
    gt_joints: np.ndarray | None,
    status: Callable[[], str] | None = None,
) -> int:
    """Runs ``step`` over ``frames`` (each a frame or the error reading it raised) and
    writes ``args.out`` (and ``args.viz``, ``args.jsonl``): a frame that fails is
    reported and recorded as NaN, ``reset`` (a tracker's) runs after it, and the other
    frames are estimated and written. ``status()`` (a tracker's state, e.g. that it is
    calibrating) is shown beside the progress bar; the frame that calibrates the body
    shape is reported on stderr."""
    import json

    from ._progress import progress_bar
    from .body import BodyModel
    from .pipeline import JOINT_NAMES

    viz_dir = Path(args.viz) if args.viz else None
    if viz_dir:
        viz_dir.mkdir(parents=True, exist_ok=True)
    jsonl = open(args.jsonl, "w") if args.jsonl else None  # noqa: SIM115
    joints = np.full((n, 15, 3), np.nan)
    pose = np.full((n, 22), np.nan)
    confidence = np.zeros((n, 15))
    shape: np.ndarray | None = None  # (n, S) once the first frame gives S
    errors: list[tuple[int, str]] = []
    t0 = time.perf_counter()
    bar = progress_bar(n, "frames")
    try:
        for k, frame in frames:
            bar.update(1)
            try:
                if isinstance(frame, Exception):
                    raise frame
                res = step(frame)
                if status is not None:
                    bar.set_postfix_str(status(), refresh=False)
                if "calibration" in res.timings:
                    ms = res.timings["calibration"]
                    bar.write(f"frame {k}: body shape calibrated in {ms:.0f} ms", file=sys.stderr)
                if viz_dir:
                    from . import viz

                    viz.save_png(viz_dir / f"frame_{k:05d}.png", picture(frame, res))
            except Exception as e:  # one frame's failure must not stop the others
                if reset is not None:
                    reset()
                joints[k], pose[k], confidence[k] = np.nan, np.nan, 0.0
                errors.append((k, _failure(e)))
                if jsonl:
                    jsonl.write(json.dumps({"frame": k, "joints": None, "error": errors[-1][1]}))
                    jsonl.write("\n")
                continue
            joints[k], pose[k], confidence[k] = res.joints, res.pose, res.confidence
            if shape is None:
                shape = np.full((n, len(res.shape)), np.nan)
            shape[k] = res.shape
            if jsonl:
                jsonl.write(json.dumps({"frame": k, **res.to_dict()}) + "\n")
    finally:
        bar.close()
        if jsonl:
            jsonl.close()
    for k, message in errors:
        print(f"frame {k} ({frame_name(k)}): {message}", file=sys.stderr)
    np.savez(
        Path(args.out), joints=joints, pose=pose, confidence=confidence,
        joint_names=np.array(JOINT_NAMES),
        shape=shape if shape is not None else np.full((n, len(BodyModel().shape)), np.nan),
        failed_frames=np.array([k for k, _ in errors], np.int64),
        errors=np.array([m for _, m in errors], dtype=str),
    )  # fmt: skip
    dt = time.perf_counter() - t0
    done = n - len(errors)
    print(f"{done}/{n} frames estimated in {dt:.1f} s ({n / max(dt, 1e-9):.1f} frames/s)")
    if gt_joints is not None and gt_joints.shape == joints.shape:
        from .metrics import evaluate

        acc = evaluate(joints, gt_joints)
        print(f"against the sequence's joints: MPJPE {acc['mpjpe_mm']:.1f} mm, "
              f"PCK@10cm {100 * acc['pck']:.1f} %")  # fmt: skip
    return _exit_code(done, len(errors))


def _cmd_batch(args: argparse.Namespace) -> int:
    from .batch import run

    if args.camera is not None and args.intrinsics is not None:
        raise InvalidInputError("--camera: give either --camera or --intrinsics, not both")
    camera = (lambda shape: _preset(args.camera, shape, "the frames")) if args.camera else None
    summary = run(
        args.inputs, args.out, scheduler=args.scheduler, n_workers=args.workers,
        chunk_frames=args.chunk_frames, overlap=args.overlap, track=args.track,
        intrinsics=args.intrinsics, camera=camera,
        depth_scale=_metres_per_unit(args.depth_scale), templates=args.templates,
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
        path = Path(args.file) if args.file else TemplateDatabase.default_path()
        db = TemplateDatabase.load(path)
        print(f"{path}: {len(db)} templates")
    return 0


def _presets() -> list[str]:
    from . import Camera

    return list(Camera.presets())


_CAMERA_HELP = (
    "a sensor's intrinsics by name: " + ", ".join(_presets()) + " (resampled to images "
    "of another size with its aspect ratio, such as a Kinect v1's at 320x240)"
)


def _camera_args(p: argparse.ArgumentParser) -> None:
    """--intrinsics, --camera and --depth-scale of a command that reads depth frames."""
    p.add_argument(
        "--intrinsics", type=float, nargs=4, metavar=("FX", "FY", "CX", "CY"),
        help="pinhole intrinsics in pixels (a .npz sequence carries its own)",
    )  # fmt: skip
    p.add_argument("--camera", metavar="NAME", choices=_presets(), help=_CAMERA_HELP)
    p.add_argument("--depth-scale", type=float, default=1000.0, help=_DEPTH_SCALE_HELP)


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
    est.add_argument(
        "--learn-background",
        action="store_true",
        help="tracking without a background frame: learn the scene's static background "
        "over the frames and segment the person in front of it once it is known",
    )
    _camera_args(est)
    est.add_argument(
        "--config",
        metavar="JSON",
        help="PipelineConfig fields as a JSON object, e.g. "
        '\'{"candidates": 8, "hypotheses": 40}\' for a wider search (offline)',
    )
    est.add_argument(
        "--glob",
        metavar="PATTERN",
        help="for a folder: the frames to read, e.g. 'depth_*.png' (default: every .png, "
        ".tif, .tiff, .npy, .pfm, .u16)",
    )
    est.set_defaults(func=_cmd_estimate)
    est.epilog = (
        "Frames are estimated one by one: a frame that cannot be read or estimated (a "
        "file in the folder that is not a depth image, too) is reported on stderr and "
        "recorded as NaN (its index and error are in the output's failed_frames and "
        "errors). The output also holds each frame's body shape ('shape', the model's "
        "shape values): BodyModel() with .shape set to it gives the frame's joints back "
        "from its 'pose'. Tracked, the progress bar says while the body shape is being "
        "calibrated, and the frame that calibrates it is reported on stderr. "
        "Exit code 0: every frame estimated; 1: some failed; "
        "2: none could be (or the input could not be opened)."
    )

    es = sub.add_parser("estimate-stereo", help="poses of rectified stereo pairs")
    es.add_argument(
        "input",
        help=".npz of pairs (keys left, right, intrinsics, baseline, optional left_bg, "
        "right_bg), a folder of pairs (left/ and right/, or *left* beside *right* images), "
        "or the left image",
    )
    es.add_argument("right", nargs="?", help="the right image, when INPUT is the left one")
    es.add_argument("--out", required=True, help="output .npz (joints, pose, confidence)")
    es.add_argument("--viz", help="folder for a picture of each pair")
    es.add_argument("--jsonl", help="also write one JSON line per pair here")
    es.add_argument(
        "--track",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="track through the pairs (default) or estimate each pair",
    )
    es.add_argument("--baseline", type=float, help="camera distance, metres (a .npz has it)")
    es.add_argument("--doffs", type=float, help="disparity offset, pixels (default 0)")
    es.add_argument(
        "--intrinsics", type=float, nargs=4, metavar=("FX", "FY", "CX", "CY"),
        help="the left camera's pinhole intrinsics in pixels (a .npz carries its own)",
    )  # fmt: skip
    es.add_argument("--camera", metavar="NAME", choices=_presets(), help=_CAMERA_HELP)
    es.add_argument(
        "--background", nargs=2, metavar=("LEFT", "RIGHT"),
        help="the empty scene's pair (optional: the person is found without one)",
    )  # fmt: skip
    es.add_argument("--max-disparity", type=int, help="largest disparity searched")
    es.set_defaults(func=_cmd_estimate_stereo)
    es.epilog = (
        "Each pair is matched (Growing Correspondence Seeds), its disparity becomes depth, "
        "and the depth goes through the same pipeline as 'estimate'; the output has the "
        "same keys. A pair that cannot be read or estimated is reported and recorded as "
        "NaN. Exit code 0: every pair estimated; 1: some failed; 2: none could be."
    )

    bat = sub.add_parser("batch", help="many sequences on a Dask cluster, resumable")
    bat.add_argument("inputs", nargs="+", help="sequences (.npz), frame folders or globs")
    bat.add_argument("--out", required=True, help="output folder")
    bat.add_argument("--scheduler", help="address of a Dask scheduler (tcp://host:port)")
    bat.add_argument("--workers", type=int, help="local workers (default: one per core)")
    bat.add_argument("--chunk-frames", type=int, default=32)
    bat.add_argument("--overlap", type=int, default=4, help="warm-up frames per chunk")
    bat.add_argument("--track", action=argparse.BooleanOptionalAction, default=True)
    _camera_args(bat)
    bat.add_argument("--templates", help="a saved template database to share")
    bat.set_defaults(func=_cmd_batch)

    # Its own parser (depthpose.stereo.cli_stereo) reads the arguments, --help included:
    # main() hands it everything after "stereo".
    st = sub.add_parser("stereo", help="disparity (and depth) of a rectified stereo pair",
                        add_help=False)  # fmt: skip
    st.set_defaults(func=_cmd_stereo, stereo_args=[])

    tp = sub.add_parser("templates", help="build or inspect the template database")
    tps = tp.add_subparsers(dest="action", required=True)
    tpb = tps.add_parser("build", help="build the database and save it")
    tpb.add_argument("--out", help="file to write (default: the cache file used by default)")
    tpi = tps.add_parser("info", help="load a saved database and describe it")
    tpi.add_argument("file", nargs="?", help="file to read (default: the cache file)")
    tp.set_defaults(func=_cmd_templates)

    fg = sub.add_parser("foreground", help="foreground masks of depth images, as pictures")
    fg.add_argument("inputs", nargs="+", help="depth images (.png, .npy, .pfm, .u16)")
    fg.add_argument("--out", required=True, help="output folder")
    fg.add_argument("--background", help="depth image of the empty scene")
    fg.add_argument("--camera", metavar="NAME", choices=_presets(), help=_CAMERA_HELP)
    fg.add_argument("--depth-scale", type=float, default=1000.0, help=_DEPTH_SCALE_HELP)
    fg.set_defaults(func=_cmd_foreground)
    fg.epilog = "Exit code 0: every image done; 1: some failed; 2: none could be."
    return p


def _cmd_demo(args: argparse.Namespace) -> int:
    from . import demo

    return demo.run(Path(args.out), frames=args.frames)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if args.command == "stereo":
        args.stereo_args = extra
    elif extra:
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
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
