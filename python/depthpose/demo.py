"""``depthpose demo``: the tracker on a built-in synthetic sequence, with its accuracy
against the exact joints, the frame rate, results and pictures."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from . import viz
from ._core import Camera
from ._progress import progress_bar
from .cloud import foreground_mask
from .metrics import evaluate

__all__ = ["run"]


def run(out: Path, frames: int = 30, motion: str = "wave") -> int:
    from . import synth
    from .pipeline import PoseTracker
    from .templates import TemplateDatabase

    out.mkdir(parents=True, exist_ok=True)
    print(f"depthpose demo: synthetic '{motion}' sequence, {frames} frames", flush=True)
    seq = synth.make_sequence(motion=motion, frames=frames, seed=0)
    fx, fy, cx, cy = (float(v) for v in seq["intrinsics"])
    depth_mm = seq["depth"]
    camera = Camera(fx, fy, cx, cy, depth_mm.shape[2], depth_mm.shape[1])
    background = seq["background"].astype(np.float32) / 1000
    templates = TemplateDatabase.default(progress=True)
    tracker = PoseTracker(camera, templates=templates, background=background)

    joints = np.full((frames, 15, 3), np.nan)
    times: list[float] = []
    ious: list[float] = []
    pictures: list[np.ndarray] = []
    bar = progress_bar(frames, "frames")
    for t in range(frames):
        depth = depth_mm[t].astype(np.float32) / 1000
        t0 = time.perf_counter()
        res = tracker.update(depth)
        times.append(time.perf_counter() - t0)
        joints[t] = res.joints
        mask = foreground_mask(depth, background)
        gt_mask = seq["mask"][t]
        ious.append((mask & gt_mask).sum() / max((mask | gt_mask).sum(), 1))
        if t % max(frames // 6, 1) == 0 and len(pictures) < 6:
            pic = viz.overlay_labels(viz.colorize_depth(depth), res.labels)
            pictures.append(viz.draw_skeleton(pic, res.joints, camera, confidence=res.confidence))
        bar.update(1)
    bar.close()
    acc = evaluate(joints, seq["joints"])
    times_ms = 1000 * np.asarray(times)
    steady = times_ms[1:] if len(times_ms) > 1 else times_ms
    np.savez(
        out / "result.npz", joints=joints, gt_joints=seq["joints"],
        joint_names=np.array(seq["joint_names"]),
    )  # fmt: skip
    viz.save_png(out / "frames.png", viz.montage(pictures, columns=3))
    summary = {
        "frames": frames,
        "foreground_iou": float(np.mean(ious)),
        "mpjpe_mm": acc["mpjpe_mm"],
        "pck_10cm": acc["pck"],
        "first_frame_ms": float(times_ms[0]),
        "median_tracked_frame_ms": float(np.median(steady)),
        "frames_per_second": float(1000 / np.median(steady)),
        "lost_frames": tracker.lost_frames,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(f"foreground IoU      {summary['foreground_iou']:.3f}")
    print(f"MPJPE               {summary['mpjpe_mm']:.1f} mm")
    print(f"PCK@10cm            {100 * summary['pck_10cm']:.1f} %")
    print(f"first frame         {summary['first_frame_ms']:.1f} ms (template search + EM)")
    print(
        f"tracked frames      {summary['median_tracked_frame_ms']:.1f} ms median "
        f"({summary['frames_per_second']:.0f} frames/s)"
    )
    print(f"wrote {out}/frames.png, result.npz, summary.json")
    return 0
