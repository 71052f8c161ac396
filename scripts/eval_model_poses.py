#!/usr/bin/env python3
"""From-scratch accuracy on random human poses of the body model itself.

Each pose is drawn at random: a subject of 1.55–1.95 m at 2.5–3.6 m from the camera,
turned by any yaw (0–360°) and leaning a little; each arm anywhere in a human range
(shoulder flexion −35° to 165°, abduction 0–135°, rotation ±45°, elbow 0–130°); one leg
in three raised, kicked or bent (hip flexion −35° to 115°, abduction 0–57°, knee
0–130°), the other about standing. The body model renders its depth (ITOP-like camera,
320×240), Gaussian depth noise is added, and ``PoseEstimator.estimate`` reads it from
scratch with the rendered mask. The joints are exact, so every error is the search's or
the fit's, never the model's: the check covers poses, turns and sizes that the shared
sequences do not hold (kicks at any turn, arms in any pose, backs of every view).

Usage::

    python scripts/eval_model_poses.py [--poses N] [--seed S] [--noise MM] [--pitch DEG]
        [--no-mask] [--json-out F]

It prints the mean PCK@10cm, MPJPE, the share of poses whose torso joint is more than
15 cm off, the per-joint PCK, and the worst poses (index, yaw, raised leg, errors).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import depthpose as dp
import numpy as np
from scipy.spatial.transform import Rotation

#: Human ranges (radians) of each arm's shoulder flexion, abduction, rotation and elbow.
ARM_RANGE = np.array([[-0.6, 2.9], [0.0, 2.35], [-0.8, 0.8], [0.0, 2.3]])
#: ... of a raised leg's hip flexion, abduction and knee.
RAISED_LEG_RANGE = np.array([[-0.6, 2.0], [0.0, 1.0], [0.0, 2.3]])
#: ... of a standing leg.
STANDING_LEG_RANGE = np.array([[-0.2, 0.3], [0.0, 0.25], [0.0, 0.4]])
TORSO = dp.JOINT_NAMES.index("Torso")


def _uniform(rng: np.random.Generator, ranges: np.ndarray) -> np.ndarray:
    return rng.uniform(ranges[:, 0], ranges[:, 1])


def random_pose(
    rng: np.random.Generator, model: dp.BodyModel, pitch: float
) -> tuple[np.ndarray, float, int]:
    """A random human pose of `model` (see the module docs), its yaw (degrees) and which
    leg is raised (0 none, 1 right, 2 left)."""
    names = model.param_names
    pose = np.asarray(model.neutral_pose(), float)
    pose[0] = rng.uniform(-0.3, 0.3)
    pose[2] = rng.uniform(2.5, 3.6)
    yaw = rng.uniform(0.0, 2 * np.pi)
    lean = Rotation.from_euler("xz", rng.normal(0.0, 0.08, 2))
    root = Rotation.from_euler("x", pitch) * Rotation.from_euler("y", yaw) * lean
    pose[3:6] = root.as_rotvec()
    pose[names.index("neck_flexion")] = rng.normal(0.0, 0.15)
    pose[names.index("neck_lateral")] = rng.normal(0.0, 0.15)
    for side in ("r", "l"):
        first = names.index(f"{side}_shoulder_flexion")
        pose[first : first + 4] = _uniform(rng, ARM_RANGE)
    raised = int(rng.integers(0, 3))
    for k, side in enumerate(("r", "l")):
        first = names.index(f"{side}_hip_flexion")
        ranges = RAISED_LEG_RANGE if raised == k + 1 else STANDING_LEG_RANGE
        pose[first : first + 3] = _uniform(rng, ranges)
    return np.asarray(model.clamp_pose(pose)), float(np.degrees(yaw)), raised


def rendered(
    model: dp.BodyModel,
    pose: np.ndarray,
    camera: dp.Camera,
    rng: np.random.Generator,
    noise_mm: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The depth (metres, Gaussian noise of `noise_mm` added, 0 off the body) and the
    mask of `model` rendered at `pose`."""
    depth, labels = model.render_depth(pose, camera)
    mask = labels >= 0
    noise = rng.normal(0.0, noise_mm / 1000, depth.shape)
    return np.where(mask, depth + noise, 0.0).astype(np.float32), mask


def add_rendering_options(ap: argparse.ArgumentParser) -> None:
    """The options of every probe that renders the body model: the random generator's
    seed, the depth noise of `rendered`, whether the estimator gets the mask, and the
    JSON output."""
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--noise", type=float, default=5.0, help="depth noise sigma (mm)")
    ap.add_argument("--no-mask", action="store_true", help="segment the person automatically")
    ap.add_argument("--json-out", type=Path)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--poses", type=int, default=100)
    ap.add_argument("--pitch", type=float, default=0.0, help="camera pitch (degrees)")
    add_rendering_options(ap)
    args = ap.parse_args(argv)

    rng = np.random.default_rng(args.seed)
    camera = dp.Camera.preset("itop")
    estimator = dp.PoseEstimator(camera)
    rows = []
    for i in range(args.poses):
        height = round(float(rng.uniform(1.55, 1.95)), 2)
        model = dp.BodyModel(height=height)
        pose, yaw, raised = random_pose(rng, model, np.radians(args.pitch))
        depth, mask = rendered(model, pose, camera, rng, args.noise)
        res = estimator.estimate(depth, None if args.no_mask else mask)
        errors = np.linalg.norm(res.joints - np.asarray(model.joints(pose)), axis=1)
        rows.append(
            {
                "pose": i,
                "yaw": yaw,
                "raised_leg": raised,
                "height_m": height,
                "pck": float(np.mean(errors < 0.1)),
                "mpjpe_mm": float(errors.mean() * 1000),
                "torso_m": float(errors[TORSO]),
                "discrepancy": float(res.discrepancy),
                "errors_m": errors.tolist(),
            }
        )
    errors = np.array([r["errors_m"] for r in rows])
    pck = float(np.mean(errors < 0.1))
    mpjpe = float(errors.mean() * 1000)
    torso_off = float(np.mean(errors[:, TORSO] > 0.15))
    per_joint = dict(zip(dp.JOINT_NAMES, np.mean(errors < 0.1, axis=0).tolist(), strict=True))
    print(
        f"{len(rows)} poses: PCK@10cm {pck:.3f}, MPJPE {mpjpe:.1f} mm, torso more than "
        f"15 cm off in {100 * torso_off:.1f} % of poses"
    )
    print("per joint:", ", ".join(f"{n} {p:.2f}" for n, p in per_joint.items()))
    print("worst poses:")
    for r in sorted(rows, key=lambda r: r["pck"])[:5]:
        print(
            f"  pose {r['pose']:3d}  yaw {r['yaw']:5.0f}°  raised leg {r['raised_leg']}  "
            f"PCK {r['pck']:.2f}  MPJPE {r['mpjpe_mm']:.0f} mm  "
            f"discrepancy {r['discrepancy']:.3f}"
        )
    if args.json_out:
        summary = {
            "pck": pck,
            "mpjpe_mm": mpjpe,
            "torso_off_15cm": torso_off,
            "per_joint_pck": per_joint,
        }
        args.json_out.write_text(json.dumps({"summary": summary, "poses": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
