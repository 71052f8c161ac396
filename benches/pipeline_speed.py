#!/usr/bin/env python3
"""Per-frame time of the whole pipeline on shared synthetic sequences: tracked frames of
``PoseTracker.update`` (those that ran no template search) and ``PoseEstimator.estimate``
from scratch, at the sequences' 320×240 and, with ``--upsample 2``, at 640×480 (each
pixel repeated, intrinsics doubled), with or without the sequence's background frame.

    python benches/pipeline_speed.py                          # this build
    python benches/pipeline_speed.py --json-out speed.json
    python benches/pipeline_speed.py --other /path/to/other/python --rounds 3

``--other`` runs the same measurement with another interpreter (another build of
depthpose installed there) alternately with this one, round by round, and prints the
ratio of the medians: builds compared in the same minutes on the same machine.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "synth"
SEQUENCES = ["dm_walk_front", "cmu131_01_walk_left", "dm_jump_oblique_r_noise0"]


def measure(names: list[str], upsample: int, background: bool, scratch_step: int) -> dict:
    import depthpose as dp

    tracked, scratch = [], []
    for name in names:
        d = np.load(DATA / f"{name}.npz")
        depth = d["depth"]
        fx, fy, cx, cy = (float(v) for v in d["intrinsics"])
        cam = dp.Camera(fx, fy, cx, cy, depth.shape[2], depth.shape[1])
        bg = d["background"] if background else None
        if upsample > 1:
            u = upsample
            depth = depth.repeat(u, axis=1).repeat(u, axis=2)
            bg = None if bg is None else bg.repeat(u, axis=0).repeat(u, axis=1)
            cam = cam.scaled(u)
        tr = dp.PoseTracker(cam, background=bg)
        for k in range(depth.shape[0]):
            t0 = time.perf_counter()
            r = tr.update(depth[k])
            dt = time.perf_counter() - t0
            timings = r.timings
            if r.source == "tracking" and "search" not in timings and "calibration" not in timings:
                tracked.append(dt)
        est = dp.PoseEstimator(cam, background=bg)
        for k in range(0, depth.shape[0], scratch_step):
            t0 = time.perf_counter()
            est.estimate(depth[k])
            scratch.append(time.perf_counter() - t0)
    return {
        "tracked_ms": 1000 * float(np.median(tracked)),
        "tracked_frames": len(tracked),
        "estimate_ms": 1000 * float(np.median(scratch)),
        "estimate_frames": len(scratch),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seq", nargs="*", default=SEQUENCES)
    ap.add_argument("--upsample", type=int, default=1)
    ap.add_argument("--background", action=argparse.BooleanOptionalAction, default=True)
    ap.add_argument("--step", type=int, default=4, help="from scratch: every STEP-th frame")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--other", help="another Python interpreter to compare with")
    ap.add_argument("--json-out", type=Path)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    run = [args.seq, args.upsample, args.background, args.step]
    if args.child:
        print(json.dumps(measure(*run)))
        return 0
    bg = "--background" if args.background else "--no-background"
    child = [__file__, "--child", "--upsample", str(args.upsample), "--step", str(args.step),
             bg, "--seq", *args.seq]  # fmt: skip
    rows: dict[str, list[dict]] = {"this": [], "other": []}
    for _ in range(args.rounds):
        for who, python in [("this", sys.executable), ("other", args.other)]:
            if python is None:
                continue
            out = subprocess.run([python, *child], capture_output=True, text=True, check=True)
            rows[who].append(json.loads(out.stdout.strip().splitlines()[-1]))
            print(who, rows[who][-1], flush=True)
    summary: dict = {"settings": {"sequences": args.seq, "upsample": args.upsample,
                                  "background": args.background}}  # fmt: skip
    for who, r in rows.items():
        if r:
            summary[who] = {k: float(np.median([x[k] for x in r])) for k in r[0]}
    if rows["other"]:
        for k in ("tracked_ms", "estimate_ms"):
            ratio = summary["this"][k] / summary["other"][k]
            summary[f"{k}_ratio"] = ratio
            print(f"{k}: this {summary['this'][k]:.2f}, other {summary['other'][k]:.2f}, "
                  f"ratio {ratio:.3f}")  # fmt: skip
    if args.json_out:
        args.json_out.write_text(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
