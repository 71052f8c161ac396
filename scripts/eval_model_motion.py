#!/usr/bin/env python3
"""Tracked accuracy on random motions of the body model itself: spins, flips, kicks.

Each sequence runs through random human poses of the body model (those of
``eval_model_poses.py``), one every ``--key`` frames, blended smoothly between them
(joint angles linearly, the body's orientation by spherical interpolation). On top of
that the body turns: about its vertical axis at a random rate up to ``--spin`` degrees
per frame (a spin, a turning walk), and, in every ``--flip-every``-th sequence, once
head over heels about a horizontal axis over ``--flip-frames`` frames (a flip). The
body model renders its depth (ITOP-like camera, 320×240), Gaussian depth noise is
added, and ``PoseTracker`` follows it from the first frame (body size and shape found
by the tracker, as for a new user). The joints are exact, so every error is the
tracker's: the check covers turns, flips and limb motions that the shared sequences do
not hold.

Usage::

    python scripts/eval_model_motion.py [--sequences N] [--frames F] [--key K]
        [--spin DEG] [--flip-every N] [--seed S] [--noise MM] [--no-mask] [--json-out F]

It prints per sequence and overall the PCK@10cm, MPJPE, the share of frames whose torso
joint is more than 15 cm off and how many frames ran the search, then the per-joint PCK.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import depthpose as dp
import numpy as np
from scipy.spatial.transform import Rotation, Slerp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from eval_model_poses import TORSO, add_rendering_options, random_pose, rendered  # noqa: E402


def random_motion(
    rng: np.random.Generator, model: dp.BodyModel, args: argparse.Namespace, flip: bool
) -> tuple[np.ndarray, float]:
    """(frames, 22) poses of `model` (random key poses blended, turned and maybe flipped)
    and its turn per frame (degrees)."""
    keys = [random_pose(rng, model, 0.0)[0] for _ in range(args.frames // args.key + 2)]
    # The key poses share one place and a slow drift, not a jump per key: sideways, and
    # toward or away from the camera within the poses' range of distances.
    start = keys[0][:3].copy()
    end = np.array([rng.uniform(-0.3, 0.3), start[1], rng.uniform(2.5, 3.6)])
    drift = (end - start) / args.frames
    spin = np.radians(rng.uniform(-args.spin, args.spin))
    yaw0 = rng.uniform(0.0, 2 * np.pi)
    key_t = np.arange(len(keys)) * args.key
    # The key poses' own yaws are dropped: the turn comes from the spin alone.
    key_rot = Rotation.from_rotvec(
        [
            (Rotation.from_euler("y", -_yaw(k)) * Rotation.from_rotvec(k[3:6])).as_rotvec()
            for k in keys
        ]
    )
    slerp = Slerp(key_t, key_rot)
    flip_axis = Rotation.from_euler("y", rng.uniform(0.0, 2 * np.pi)).apply([1.0, 0.0, 0.0])
    flip_start = rng.integers(args.key, max(args.key + 1, args.frames - args.flip_frames))
    poses = []
    for t in range(args.frames):
        k, w = divmod(t, args.key)
        w /= args.key
        pose = (1 - w) * keys[k] + w * keys[k + 1]
        pose[:3] = start + drift * t
        turn = Rotation.from_euler("y", yaw0 + spin * t)
        if flip and flip_start <= t < flip_start + args.flip_frames:
            angle = 2 * np.pi * (t - flip_start) / args.flip_frames
            # Head over heels about the body's centre, lifted off the ground meanwhile.
            turn = Rotation.from_rotvec(angle * flip_axis) * turn
            pose[1] -= 0.3 * np.sin(np.pi * (t - flip_start) / args.flip_frames)
        pose[3:6] = (turn * slerp([t])[0]).as_rotvec()
        poses.append(np.asarray(model.clamp_pose(pose)))
    return np.array(poses), float(np.degrees(spin))


def _yaw(pose: np.ndarray) -> float:
    """The yaw of a pose's root (radians): the heading of its forward axis."""
    forward = Rotation.from_rotvec(pose[3:6]).apply([0.0, 0.0, 1.0])
    return float(np.arctan2(forward[0], forward[2]))


def _mpjpe_mm(errors: np.ndarray) -> float:
    """The mean joint error (mm) over the frames read (a missed frame's errors are inf)."""
    read = np.isfinite(errors[:, 0])
    return float(errors[read].mean() * 1000) if read.any() else float("nan")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sequences", type=int, default=12)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--key", type=int, default=10, help="frames between key poses")
    ap.add_argument("--spin", type=float, default=12.0, help="largest turn (degrees/frame)")
    ap.add_argument("--flip-every", type=int, default=3, help="every N-th sequence flips")
    ap.add_argument("--flip-frames", type=int, default=30, help="frames of a whole flip")
    ap.add_argument("--config", default=None, help="PipelineConfig fields as JSON")
    add_rendering_options(ap)
    args = ap.parse_args(argv)

    rng = np.random.default_rng(args.seed)
    camera = dp.Camera.preset("itop")
    config = dp.PipelineConfig(**json.loads(args.config)) if args.config else None
    rows = []
    all_errors = []
    for s in range(args.sequences):
        height = round(float(rng.uniform(1.55, 1.95)), 2)
        model = dp.BodyModel(height=height)
        flip = args.flip_every > 0 and s % args.flip_every == args.flip_every - 1
        poses, spin = random_motion(rng, model, args, flip)
        tracker = dp.PoseTracker(camera, config=config)
        errors = []
        searched = 0
        for pose in poses:
            depth, mask = rendered(model, pose, camera, rng, args.noise)
            truth = np.asarray(model.joints(pose))
            try:
                res = tracker.update(depth, None if args.no_mask else mask)
            except dp.NoBodyError:
                # Too little of the body in view (it turned or drifted out): a miss.
                errors.append(np.full(len(truth), np.inf))
                continue
            searched += "search" in res.timings
            errors.append(np.linalg.norm(res.joints - truth, axis=1))
        e = np.array(errors)
        all_errors.append(e)
        rows.append(
            {
                "sequence": s,
                "height_m": height,
                "flip": flip,
                "spin_deg": spin,
                "pck": float(np.mean(e < 0.1)),
                "mpjpe_mm": _mpjpe_mm(e),
                "missed": int(np.sum(~np.isfinite(e[:, 0]))),
                "torso_off_15cm": float(np.mean(e[:, TORSO] > 0.15)),
                "searched": searched,
                "frame_pck": np.mean(e < 0.1, axis=1).tolist(),
            }
        )
        r = rows[-1]
        print(
            f"sequence {s:2d}  {height:.2f} m  spin {spin:5.1f}°  {'flip' if flip else '    '}  "
            f"PCK {r['pck']:.3f}  MPJPE {r['mpjpe_mm']:5.1f} mm  "
            f"torso off {100 * r['torso_off_15cm']:4.1f} %  searched {searched}  "
            f"missed {r['missed']}",
            flush=True,
        )
    errors = np.concatenate(all_errors)
    pcks = [r["pck"] for r in rows]
    worst = int(np.argmin(pcks))
    per_joint = dict(zip(dp.JOINT_NAMES, np.mean(errors < 0.1, axis=0).tolist(), strict=True))
    summary = {
        "pck_mean": float(np.mean(pcks)),
        "pck_worst": pcks[worst],
        "worst_sequence": worst,
        "mpjpe_mm": _mpjpe_mm(errors),
        "torso_off_15cm": float(np.mean(errors[:, TORSO] > 0.15)),
        "per_joint_pck": per_joint,
    }
    print(
        f"{len(rows)} sequences: PCK@10cm {summary['pck_mean']:.3f} (worst {pcks[worst]:.3f}, "
        f"sequence {worst}), MPJPE {summary['mpjpe_mm']:.1f} mm, torso more than 15 cm off "
        f"in {100 * summary['torso_off_15cm']:.1f} % of frames"
    )
    print("per joint:", ", ".join(f"{n} {p:.2f}" for n, p in per_joint.items()))
    if args.json_out:
        args.json_out.write_text(json.dumps({"summary": summary, "sequences": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
