#!/usr/bin/env python3
"""End-to-end accuracy and speed of ``depthpose.pipeline.estimate_frames`` on the shared
synthetic sequences.

For every sequence (``../shared/data/synth/*.npz`` by default): tracked over every frame
(every ``--track-step``-th: N times the motion per frame), and from scratch over every
``--step``-th frame, each with the sequence's background
frame and the default template database. Scored with ``depthpose.metrics.evaluate``
(the definitions of ``shared/tools/eval_pose.py``: MPJPE over finite predictions,
PCK@10cm with NaN counted as wrong). Prints per-sequence, per-joint and overall tables,
the median per-frame times of ``PoseEstimator.estimate`` and ``PoseTracker.update``
(tracked frames, tracked frames whose lost-track test or periodic re-check ran the
template search, and re-initialised / switched frames separately) and the peak resident memory.

    python scripts/eval_pipeline.py                       # everything
    python scripts/eval_pipeline.py --mode track --seq walk_left --frames 20
    python scripts/eval_pipeline.py --json-out figures.json
    python scripts/eval_pipeline.py --mode track --height 1.60 --calibrate on
    python scripts/eval_pipeline.py --mode track --no-background --learn-background
    python scripts/eval_pipeline.py --mirror              # the corpus in a mirror
    python scripts/eval_pipeline.py --mode track --track-step 3   # 3× the motion per frame

The person's mask of each frame is scored against the sequence's ground-truth ``mask``
(intersection over union, a failed frame counting 0), over every frame and from frame
``--iou-from`` on (after a learned background's warm-up), with the median times of the
segmentation stage (``timings["foreground"]``) and of learning the background
(``timings["background"]``). ``--learn-background`` sets
``PipelineConfig.learn_background`` (used by the tracker without a background frame).

Shape calibration (``PoseTracker``, tracked mode): ``--calibrate auto`` (the tracker's
default: on unless a model is given), ``on`` or ``off``; ``--height H`` starts from
``BodyModel(height=H)`` instead of the default model. The calibrating frame's time
(``timings["calibration"]``) is reported separately, with the fitted shape factors.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "data" / "synth"


def _peak_rss_mib() -> float:
    # ru_maxrss is KiB on Linux, bytes on macOS.
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / (1024 * 1024) if sys.platform == "darwin" else rss / 1024


class Scene(NamedTuple):
    """A sequence's frames with what scores them."""

    camera: Any
    background: np.ndarray | None
    depth: np.ndarray
    gt: np.ndarray
    masks: np.ndarray | None


def _load(path: Path, frames: int | None, start: int, mirror: bool) -> Scene:
    from depthpose.sequence import open_sequence

    seq = open_sequence(path)
    stop = seq.n_frames if frames is None else min(seq.n_frames, start + frames)
    depth = seq.frames(start, stop)
    gt = np.asarray(seq.gt_joints[start:stop], np.float64)
    with np.load(path) as d:
        masks = np.asarray(d["mask"][start:stop], bool) if "mask" in d.files else None
    scene = Scene(seq.camera, seq.background, depth, gt, masks)
    return _mirrored(scene) if mirror else scene


def _mirrored(scene: Scene) -> Scene:
    """The scene in a mirror: every image flipped left-right and the joints mirrored to
    match, left and right exchanged (the subject's mirror image, seen from the mirrored
    view: views, turns and limb poses the corpus does not hold)."""
    from depthpose.pipeline import JOINT_NAMES

    cam = scene.camera
    side = {"R": "L", "L": "R"}
    other = [
        JOINT_NAMES.index(side[n[0]] + n[1:]) if n[0] in side and n[1].isupper() else k
        for k, n in enumerate(JOINT_NAMES)
    ]
    gt = scene.gt[:, other].copy()
    # Pixel column u goes to W − 1 − u: x/z = (u − cx)/fx becomes (W − 1 − u − cx)/fx.
    gt[..., 0] = (cam.width - 1 - 2 * cam.cx) * gt[..., 2] / cam.fx - gt[..., 0]

    def flip(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.ascontiguousarray(a[..., ::-1])

    return Scene(cam, flip(scene.background), flip(scene.depth), gt, flip(scene.masks))


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.count_nonzero(a | b)
    return float(np.count_nonzero(a & b) / union) if union else 1.0


def _upsampled(depth, camera, background, u: int):
    """Each pixel repeated u×u times, the intrinsics scaled to match (a sensor of u times
    the resolution seeing the same scene)."""
    if u == 1:
        return depth, camera, background
    depth = depth.repeat(u, axis=1).repeat(u, axis=2)
    background = None if background is None else background.repeat(u, axis=0).repeat(u, axis=1)
    return depth, camera.scaled(u), background


def _run(scene: Scene, templates, config, *, track: bool, step: int, track_step: int = 1,
         model=None, calibrate=None, background=True, upsample=1):  # fmt: skip
    from depthpose.pipeline import estimate_frames

    sources: list[str] = []
    masks = scene.masks
    idx = np.arange(0, scene.depth.shape[0], track_step if track else step)
    # Mask IoU per frame (a failed frame keeps 0) and the segmentation stage's times.
    ious = np.zeros(len(idx))
    seg_ms: list[float] = []
    learn_ms: list[float] = []

    def on_frame(k, res):
        if masks is not None:
            gt_mask = masks[idx[k]].repeat(upsample, axis=0).repeat(upsample, axis=1)
            ious[k] = _iou(np.asarray(res.mask, bool), gt_mask)
        if "foreground" in res.timings:
            seg_ms.append(res.timings["foreground"])
        if "background" in res.timings:
            learn_ms.append(res.timings["background"])
        # "tracking+search": a tracked frame whose re-check / lost-track search kept it.
        kept = res.source == "tracking" and "search" in res.timings
        if "calibration" in res.timings:
            sources.append("calibration")
        else:
            sources.append("tracking+search" if kept else res.source)

    bg = scene.background if background else None
    frames, camera, bg = _upsampled(scene.depth[idx], scene.camera, bg, upsample)
    t0 = time.perf_counter()
    r = estimate_frames(
        frames,
        camera,
        background=bg,
        track=track,
        templates=templates,
        config=config,
        on_frame=on_frame,
        model=model,
        calibrate=calibrate if track else None,
    )
    wall = time.perf_counter() - t0
    # Whole-call times (estimate_frames times each step, joint confidences included).
    times: dict[str, list[float]] = {}
    for src, sec in zip(sources, r.seconds, strict=True):
        times.setdefault(src, []).append(1000 * sec)
    return idx, r, times, wall, (ious if masks is not None else None), seg_ms, learn_ms


def _fmt_row(cells, widths):
    return " | ".join(str(c).ljust(w) for c, w in zip(cells, widths, strict=False))


def _table(header, rows):
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
    lines = [_fmt_row(header, widths), "-+-".join("-" * w for w in widths)]
    lines += [_fmt_row(r, widths) for r in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder of sequence .npz")
    ap.add_argument("--seq", nargs="*", default=None, help="substrings of sequence names")
    ap.add_argument("--mode", choices=["both", "track", "scratch"], default="both")
    ap.add_argument("--step", type=int, default=2, help="from scratch: every STEP-th frame")
    ap.add_argument(
        "--track-step",
        type=int,
        default=1,
        help="tracked: every N-th frame (N times the motion per frame, as at 1/N of the "
        "frame rate; default 1)",
    )
    ap.add_argument("--frames", type=int, default=None, help="first N frames of each")
    ap.add_argument("--start", type=int, default=0, help="first frame of each sequence")
    ap.add_argument("--config", default=None, help="PipelineConfig fields as JSON")
    ap.add_argument("--per-joint", action="store_true", help="print the per-joint table")
    ap.add_argument("--per-frame", action="store_true", help="print per-frame MPJPE/source")
    ap.add_argument("--json-out", type=Path, default=None)
    ap.add_argument(
        "--height",
        type=float,
        default=None,
        help="start from BodyModel(height=H) (default: the default model)",
    )
    ap.add_argument(
        "--calibrate",
        choices=["auto", "on", "off"],
        default="auto",
        help="tracker shape calibration (auto: on unless --height is given)",
    )
    ap.add_argument(
        "--depth-weight",
        type=float,
        default=0.0,
        help="templates with the relief channel of this weight (default 0: the default database)",
    )
    ap.add_argument(
        "--background",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="use the sequence's frame of the empty scene (--no-background: segment "
        "the person automatically)",
    )
    ap.add_argument(
        "--upsample",
        type=int,
        default=1,
        help="repeat each pixel N×N times and scale the intrinsics to match (2: the "
        "sequences at 640×480)",
    )
    ap.add_argument(
        "--learn-background",
        action="store_true",
        help="PipelineConfig(learn_background=True): the tracker learns the scene's "
        "background over the frames (without a background frame)",
    )
    ap.add_argument(
        "--mirror",
        action="store_true",
        help="score each sequence mirrored left-right (images flipped, joints mirrored "
        "with left and right exchanged): views the corpus does not hold",
    )
    ap.add_argument(
        "--iou-from", type=int, default=10, help="mask IoU also from this frame on (default 10)"
    )
    args = ap.parse_args(argv)
    if args.step < 1:
        ap.error("--step must be >= 1")
    if args.track_step < 1:
        ap.error("--track-step must be >= 1")
    if args.upsample < 1:
        ap.error("--upsample must be >= 1")

    import depthpose as dp
    from depthpose.metrics import evaluate
    from depthpose.pipeline import JOINT_NAMES, PipelineConfig

    files = sorted(args.data.glob("*.npz"))
    if args.seq:
        files = [f for f in files if any(s in f.stem for s in args.seq)]
    if not files:
        print(f"no sequences under {args.data}", file=sys.stderr)
        return 2
    config = PipelineConfig(**json.loads(args.config)) if args.config else PipelineConfig()
    if args.learn_background:
        config = config.replace(learn_background=True)
    if args.depth_weight:
        templates = dp.TemplateDatabase.build(depth_weight=args.depth_weight, progress=False)
    else:
        templates = dp.TemplateDatabase.default(progress=False)
    rss_templates = _peak_rss_mib()
    modes = ["track", "scratch"] if args.mode == "both" else [args.mode]

    preds: dict[str, list[np.ndarray]] = {m: [] for m in modes}
    gts: dict[str, list[np.ndarray]] = {m: [] for m in modes}
    times: dict[str, list[float]] = {
        "update": [], "kept": [], "reinit": [], "estimate": [], "calibration": [],
        "segment_track": [], "segment_scratch": [], "learn": [],
    }  # fmt: skip
    model = None if args.height is None else dp.BodyModel(height=args.height)
    calibrate = {"auto": None, "on": True, "off": False}[args.calibrate]
    rows = []
    settings = {
        k: v if isinstance(v, (int, float, bool, type(None))) else repr(v)
        for k, v in config.as_dict().items()
    }
    summary: dict = {"sequences": {}, "config": settings, "height": args.height,
                     "calibrate": args.calibrate, "upsample": args.upsample,
                     "track_step": args.track_step}  # fmt: skip
    for f in files:
        scene = _load(f, args.frames, args.start, args.mirror)
        depth, gt = scene.depth, scene.gt
        row = [f.stem, str(depth.shape[0])]
        summary["sequences"][f.stem] = {}
        for m in modes:
            idx, r, t, wall, ious, seg_ms, learn_ms = _run(
                scene, templates, config, track=m == "track", step=args.step,
                track_step=args.track_step, model=model, calibrate=calibrate,
                background=args.background, upsample=args.upsample,
            )  # fmt: skip
            times[f"segment_{m}"] += seg_ms
            times["learn"] += learn_ms
            acc = evaluate(r.joints, gt[idx])
            preds[m].append(r.joints)
            gts[m].append(gt[idx])
            if m == "track":
                times["update"] += t.get("tracking", [])
                times["kept"] += t.get("tracking+search", [])
                times["reinit"] += t.get("templates", [])
                times["calibration"] += t.get("calibration", [])
            else:
                times["estimate"] += t.get("templates", [])
            row += [f"{acc['mpjpe_mm']:.1f}", f"{acc['pck']:.3f}"]
            summary["sequences"][f.stem][m] = {**acc, "wall_s": wall,
                                               "reinit": len(t.get("templates", []))}  # fmt: skip
            if ious is not None:
                late = ious[idx >= args.iou_from]
                summary["sequences"][f.stem][m].update(
                    mask_iou=float(ious.mean()),
                    mask_iou_late=float(late.mean()) if late.size else float("nan"),
                )
                row += [f"{ious.mean():.3f}"]
            else:
                row += ["-"]
            if m == "track":
                sf = r.shape_factors
                summary["sequences"][f.stem][m].update(
                    shape_factors=None if sf is None else [float(v) for v in sf],
                    calibration_frame=r.calibration_frame,
                    calibration_error=r.calibration_error,
                )
                if sf is not None:
                    print(f"{f.stem}: calibrated at frame {r.calibration_frame}, factors "
                          + " ".join(f"{v:.3f}" for v in sf), flush=True)  # fmt: skip
                elif r.calibration_error:
                    print(f"{f.stem}: calibration failed: {r.calibration_error}", flush=True)
            if args.per_frame:
                err = 1000 * np.linalg.norm(r.joints - gt[idx], axis=-1).mean(-1)
                print(f"{f.stem} {m}: " + " ".join(f"{e:.0f}" for e in err), flush=True)
        rows.append(row)
        print(_table(["sequence", "frames"] + [f"{m} {k}" for m in modes for k in
                                                ("MPJPE", "PCK", "IoU")], [row]).splitlines()[-1],
              flush=True)  # fmt: skip

    # Mean over sequences and the worst sequence (by PCK), per mode.
    mean_row = ["mean over sequences", ""]
    worst_row = ["worst sequence", ""]
    for m in modes:
        per = summary["sequences"]
        mp = [per[name][m]["mpjpe_mm"] for name in per]
        pk = [per[name][m]["pck"] for name in per]
        worst = min(per, key=lambda name, m=m: per[name][m]["pck"])
        summary[f"{m}_mean_over_sequences"] = {"mpjpe_mm": float(np.mean(mp)),
                                               "pck": float(np.mean(pk))}  # fmt: skip
        summary[f"{m}_worst_sequence"] = {"name": worst, **per[worst][m]}
        mean_row += [f"{np.mean(mp):.1f}", f"{np.mean(pk):.3f}"]
        worst_row += [f"{per[worst][m]['mpjpe_mm']:.1f}", f"{per[worst][m]['pck']:.3f} ({worst})"]
        if all("mask_iou" in per[name][m] for name in per):
            for key in ("mask_iou", "mask_iou_late"):
                v = [per[name][m][key] for name in per]
                worst_iou = min(per, key=lambda name, m=m, key=key: per[name][m][key])
                summary[f"{m}_mean_over_sequences"][key] = float(np.mean(v))
                summary[f"{m}_worst_{key}"] = {"name": worst_iou, key: per[worst_iou][m][key]}
            iou_w = summary[f"{m}_worst_mask_iou"]
            mean_row += [f"{summary[f'{m}_mean_over_sequences']['mask_iou']:.3f}"]
            worst_row += [f"{iou_w['mask_iou']:.3f} ({iou_w['name']})"]
        else:
            mean_row += ["-"]
            worst_row += ["-"]
    overall = ["all frames", str(sum(int(r[1]) for r in rows))]
    per_joint = {}
    for m in modes:
        p, g = np.concatenate(preds[m]), np.concatenate(gts[m])
        acc = evaluate(p, g)
        summary[m] = acc
        overall += [f"**{acc['mpjpe_mm']:.1f}**", f"**{acc['pck']:.3f}**", ""]
        valid = np.isfinite(p).all(-1)
        err = np.linalg.norm(np.where(valid[..., None], p, 0.0) - g, axis=-1)
        per_joint[m] = [
            (
                1000 * err[valid[:, j], j].mean() if valid[:, j].any() else np.nan,
                float((valid[:, j] & (err[:, j] <= 0.10 + 1e-9)).mean()),
            )
            for j in range(len(JOINT_NAMES))
        ]
    header = ["sequence", "frames"] + [
        f"{m} {k}" for m in modes for k in ("MPJPE mm", "PCK", "mask IoU")
    ]
    print()
    print(_table(header, [*rows, overall, mean_row, worst_row]))
    for m in modes:
        p, g = np.concatenate(preds[m]), np.concatenate(gts[m])
        torso = np.linalg.norm(p[:, 8] - g[:, 8], axis=-1)
        off = float(np.mean(~(torso <= 0.15)))
        summary[f"{m}_torso_off_15cm"] = off
        print(f"{m}: torso joint more than 15 cm off in {100 * off:.1f} % of frames")
        means = summary[f"{m}_mean_over_sequences"]
        if "mask_iou_late" in means:
            w = summary[f"{m}_worst_mask_iou_late"]
            print(f"{m}: mask IoU from frame {args.iou_from} on: mean over sequences "
                  f"{means['mask_iou_late']:.3f}, worst {w['mask_iou_late']:.3f} "
                  f"({w['name']})")  # fmt: skip
    if args.per_joint:
        print()
        jrows = [
            [name] + [f"{per_joint[m][j][0]:.1f} / {per_joint[m][j][1]:.3f}" for m in modes]
            for j, name in enumerate(JOINT_NAMES)
        ]
        print(_table(["joint"] + [f"{m} MPJPE mm / PCK" for m in modes], jrows))
    summary["per_joint"] = {
        m: {n: {"mpjpe_mm": e, "pck": p} for n, (e, p) in zip(JOINT_NAMES, v, strict=False)}
        for m, v in per_joint.items()
    }

    print()
    trows = []
    for k, label in [
        ("update", "PoseTracker.update, tracked frame"),
        ("kept", "PoseTracker.update, tracked frame + search (kept)"),
        ("reinit", "PoseTracker.update, (re-)initialised frame"),
        ("calibration", "PoseTracker.update, frame that ran the shape calibration"),
        ("estimate", "PoseEstimator.estimate (from scratch)"),
        ("segment_track", "segmentation (timings['foreground']), tracked"),
        ("segment_scratch", "segmentation (timings['foreground']), from scratch"),
        ("learn", "learning the background (timings['background'])"),
    ]:
        v = times[k]
        if v:
            trows.append([label, f"{np.median(v):.1f}", str(len(v))])
            summary[f"median_{k}_ms"] = float(np.median(v))
    all_update = times["update"] + times["kept"] + times["reinit"] + times["calibration"]
    if all_update:
        trows.append(["PoseTracker.update, all frames (mean)", f"{np.mean(all_update):.1f}",
                      str(len(all_update))])  # fmt: skip
        summary["mean_update_all_ms"] = float(np.mean(all_update))
    print(_table(["timing", "median ms", "frames"], trows))
    peak = _peak_rss_mib()
    summary["peak_rss_mib"] = peak
    summary["rss_after_templates_mib"] = rss_templates
    load = os.getloadavg()
    summary["load"] = load
    print(
        f"\npeak resident memory {peak:.0f} MiB (after loading the templates: "
        f"{rss_templates:.0f} MiB); load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f}"
    )
    if args.json_out:
        args.json_out.write_text(json.dumps(summary, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
