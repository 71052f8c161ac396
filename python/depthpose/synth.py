"""Synthetic depth sequences of the ellipsoid body model moving in a room.

`make_sequence` renders a motion (walk, wave, squat, turn, arm_raise) with the native
renderer, adds a floor and a back wall, and applies a Kinect-v1-like sensor model:
axial noise sigma(z) = 1.2 mm + 1.9 mm (z - 0.4)^2, disparity quantisation (f = 580 px
at 640 columns, baseline 7.5 cm, 1/8 px), a projector shadow to the image left of the
body, dropouts on the far side of depth edges and ~1 % random dropouts. The result uses
the key layout of the shared synthetic data (depth uint16 mm, background, mask, joints,
intrinsics, joint_names, fps, meta) plus `poses` (T, 22) and `labels` (T, H, W) int16,
the ground-truth part of every pixel. Deterministic for a seed; no external data.
"""

from __future__ import annotations

import json
import math
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from depthpose._core import (
    BodyModel,
    Camera,
    FileFormatError,
    InvalidInputError,
    _rotation_matrix,
    _rotation_vector,
)

__all__ = ["MOTIONS", "make_sequence", "save", "load", "motion_pose"]

# Kinect v1 sensor constants.
KINECT_FOCAL_640 = 580.0  # px at 640 columns
KINECT_BASELINE = 0.075  # m, projector to the camera's +x side
DISPARITY_STEP = 1.0 / 8.0  # px
NOISE_SIGMA_0 = 0.0012  # m
NOISE_SIGMA_2 = 0.0019  # m per m^2
NOISE_Z_0 = 0.4  # m
EDGE_STEP = 0.05  # m: a neighbour this much nearer makes a pixel the far side of an edge
EDGE_DROP = 0.5  # probability at noise 1
RANDOM_DROP = 0.01  # probability at noise 1
SHADOW_MARGIN = 0.05  # m
MAX_DEPTH_MM = 65535

_P = {name: i for i, name in enumerate(BodyModel().param_names)}


def _blank() -> np.ndarray:
    pose = BodyModel.neutral_pose()
    pose[:6] = 0.0
    return pose


def _walk(t: float) -> np.ndarray:
    """One gait cycle per second of phase; swing knee flexes, arms swing opposite."""
    p = _blank()
    ph = 2.0 * math.pi * t
    p[_P["r_hip_flexion"]] = 0.45 * math.sin(ph)
    p[_P["l_hip_flexion"]] = -0.45 * math.sin(ph)
    p[_P["r_knee_flexion"]] = 0.1 + 0.6 * max(0.0, math.sin(ph + 0.8))
    p[_P["l_knee_flexion"]] = 0.1 + 0.6 * max(0.0, -math.sin(ph + 0.8))
    p[_P["r_shoulder_flexion"]] = -0.35 * math.sin(ph)
    p[_P["l_shoulder_flexion"]] = 0.35 * math.sin(ph)
    p[_P["r_elbow_flexion"]] = 0.3 + 0.15 * max(0.0, -math.sin(ph))
    p[_P["l_elbow_flexion"]] = 0.3 + 0.15 * max(0.0, math.sin(ph))
    return p


def _wave(t: float) -> np.ndarray:
    p = _blank()
    ph = 2.0 * math.pi * t
    p[_P["r_shoulder_abduction"]] = 2.3
    p[_P["r_shoulder_rotation"]] = -0.3
    p[_P["r_elbow_flexion"]] = 0.9 + 0.5 * math.sin(2.0 * ph)
    p[_P["neck_lateral"]] = 0.1 * math.sin(ph)
    return p


def _squat(t: float) -> np.ndarray:
    p = _blank()
    s = 0.5 * (1.0 - math.cos(2.0 * math.pi * t))
    p[_P["r_hip_flexion"]] = p[_P["l_hip_flexion"]] = 1.5 * s
    p[_P["r_knee_flexion"]] = p[_P["l_knee_flexion"]] = 2.0 * s
    p[_P["r_shoulder_flexion"]] = p[_P["l_shoulder_flexion"]] = 1.4 * s
    p[_P["neck_flexion"]] = -0.3 * s
    return p


def _arm_raise(t: float) -> np.ndarray:
    p = _blank()
    s = 0.5 * (1.0 - math.cos(2.0 * math.pi * t))
    p[_P["r_shoulder_abduction"]] = p[_P["l_shoulder_abduction"]] = 0.12 + 2.7 * s
    p[_P["r_elbow_flexion"]] = p[_P["l_elbow_flexion"]] = 0.1
    return p


def _turn(t: float) -> np.ndarray:
    p = _walk(0.0)
    p[_P["r_elbow_flexion"]] = p[_P["l_elbow_flexion"]] = 0.2
    return p


# Joint angles of each motion at phase t in [0, 1).
MOTIONS: dict[str, Callable[[float], np.ndarray]] = {
    "walk": _walk,
    "wave": _wave,
    "squat": _squat,
    "turn": _turn,
    "arm_raise": _arm_raise,
}
# Extra yaw (degrees) over the sequence, and forward travel (m) toward the camera.
_YAW_SWEEP = {"turn": 180.0}
_TRAVEL = {"walk": 0.8}
# Squats lean the trunk forward (radians at the bottom of the squat).
_SQUAT_LEAN = 0.5


def motion_pose(motion: str, t: float) -> np.ndarray:
    """Joint angles of `motion` at phase `t` (root parts zero)."""
    if motion not in MOTIONS:
        raise InvalidInputError(f"motion: unknown motion {motion!r}; choose from {sorted(MOTIONS)}")
    return MOTIONS[motion](t % 1.0)


def _check(name: str, value: float, lo: float, hi: float) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and lo <= value <= hi):
        raise InvalidInputError(f"{name}: must be a number within {lo}..{hi}, got {value!r}")
    return float(value)


def _scene_depth(camera: Camera, r_wc: np.ndarray, cam_height: float, wall: float) -> np.ndarray:
    """Depth (z) of the floor (y_world = cam_height) and back wall (z_world = wall)."""
    fx, fy, cx, cy = camera.intrinsics
    v, u = np.mgrid[0 : camera.height, 0 : camera.width].astype(float)
    d = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)], -1) @ r_wc.T
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = np.where(d[..., 1] > 1e-9, cam_height / d[..., 1], np.inf)
        back = np.where(d[..., 2] > 1e-9, wall / d[..., 2], np.inf)
    z = np.minimum(floor, back)
    return np.where(np.isfinite(z), z, 0.0)


def _sensor(z: np.ndarray, camera: Camera, noise: float, rng: np.random.Generator) -> np.ndarray:
    """Applies the Kinect-like sensor model to a clean depth image (metres, 0 = none)."""
    if noise <= 0.0:
        return z.copy()
    out = z.copy()
    valid = out > 0
    fx = camera.fx
    fb = fx * KINECT_BASELINE
    # Projector shadow: a z-buffer seen from the projector (+x), per row in projector
    # columns u - f*b/z; pixels behind a nearer surface there get no pattern.
    rows, cols = np.nonzero(valid)
    zz = out[rows, cols]
    pcol = np.round(cols - fb / zz).astype(np.int64)
    pcol_c = np.clip(pcol, -camera.width, 2 * camera.width - 1) + camera.width
    pbuf = np.full((camera.height, 3 * camera.width), np.inf)
    np.minimum.at(pbuf, (rows, pcol_c), zz)
    shadow = pbuf[rows, pcol_c] < zz - SHADOW_MARGIN
    out[rows[shadow], cols[shadow]] = 0.0
    # Far side of depth edges.
    far = np.zeros_like(valid)
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        nb = np.roll(z, (dy, dx), axis=(0, 1))
        far |= valid & (nb > 0) & (nb < z - EDGE_STEP)
    drop = far & (rng.random(z.shape) < EDGE_DROP * min(1.0, noise))
    drop |= rng.random(z.shape) < RANDOM_DROP * noise
    out[drop] = 0.0
    # Axial noise, then disparity quantisation at the native Kinect resolution.
    valid = out > 0
    zv = out[valid]
    sigma = noise * (NOISE_SIGMA_0 + NOISE_SIGMA_2 * (zv - NOISE_Z_0) ** 2)
    zv = zv + rng.normal(0.0, 1.0, zv.shape) * sigma
    fb_native = KINECT_FOCAL_640 * KINECT_BASELINE
    disp = np.round(fb_native / np.maximum(zv, 0.05) / DISPARITY_STEP) * DISPARITY_STEP
    out[valid] = fb_native / np.maximum(disp, DISPARITY_STEP)
    return out


def make_sequence(
    motion: str = "wave",
    frames: int = 30,
    camera: Camera | None = None,
    distance: float = 3.0,
    view_deg: float = 0.0,
    noise: float = 1.0,
    seed: int = 0,
    height: float = 1.75,
    fps: float = 30.0,
    cycles: float = 1.0,
    camera_height: float = 1.2,
    tilt_deg: float = 5.0,
    wall_distance: float | None = None,
) -> dict[str, np.ndarray]:
    """Renders `frames` frames of `motion` seen from `camera` (default: the ITOP-like
    320x240 camera). The subject's hip centre starts `distance` m ahead, yawed by
    `view_deg` (0 = facing the camera, +90 = left side toward it). Returns a dict with
    the shared synthetic data's keys (see the module docs)."""
    if motion not in MOTIONS:
        raise InvalidInputError(f"motion: unknown motion {motion!r}; choose from {sorted(MOTIONS)}")
    if not isinstance(frames, int) or not 1 <= frames <= 10000:
        raise InvalidInputError(f"frames: must be an int within 1..10000, got {frames!r}")
    distance = _check("distance", distance, 0.8, 8.0)
    view = math.radians(_check("view_deg", view_deg, -360.0, 360.0))
    noise = _check("noise", noise, 0.0, 10.0)
    fps = _check("fps", fps, 0.1, 1000.0)
    cycles = _check("cycles", cycles, 0.0, 100.0)
    camera_height = _check("camera_height", camera_height, 0.2, 3.0)
    tilt = math.radians(_check("tilt_deg", tilt_deg, -45.0, 45.0))
    wall = (
        distance + 1.5
        if wall_distance is None
        else _check("wall_distance", wall_distance, 1.0, 20.0)
    )
    if wall <= distance + 0.5:
        raise InvalidInputError("wall_distance: the wall must be at least 0.5 m behind the subject")
    camera = Camera.itop() if camera is None else camera
    if not isinstance(camera, Camera):
        raise InvalidInputError(f"camera: expected a depthpose.Camera, got {type(camera).__name__}")
    model = BodyModel(height)
    rng = np.random.default_rng(seed)

    # World: x right, y down (floor at y = camera_height), z forward, camera at the
    # origin pitched down by `tilt`; r_wc maps camera directions to world.
    r_wc = np.array(
        [[1, 0, 0], [0, math.cos(tilt), math.sin(tilt)], [0, -math.sin(tilt), math.cos(tilt)]],
        float,
    )
    r_cw = r_wc.T
    shape = dict(zip(model.shape_names, model.shape, strict=False))
    ankle_height = shape["ankle_height"]

    h, w = camera.height, camera.width
    depth = np.zeros((frames, h, w), np.uint16)
    mask = np.zeros((frames, h, w), bool)
    labels = np.full((frames, h, w), -1, np.int16)
    joints = np.zeros((frames, 15, 3), np.float32)
    poses = np.zeros((frames, 22))
    scene = _scene_depth(camera, r_wc, camera_height, wall)
    for f in range(frames):
        t = f / max(frames, 1) * cycles
        pose = motion_pose(motion, t)
        yaw = view + math.radians(_YAW_SWEEP.get(motion, 0.0)) * f / max(frames - 1, 1)
        lean = _SQUAT_LEAN * 0.5 * (1.0 - math.cos(2.0 * math.pi * t)) if motion == "squat" else 0.0
        # Body axes in the world: yaw about the vertical, then lean forward (the
        # body's -z is its front: a positive rotation about body x tips the head forward).
        yawed = _rotation_matrix(np.array([0.0, yaw, 0.0]))
        r_world = yawed @ _rotation_matrix(np.array([lean, 0.0, 0.0]))
        travel = _TRAVEL.get(motion, 0.0) * f / max(frames - 1, 1)
        forward = yawed @ np.array([0.0, 0.0, -1.0])
        hip_w = np.array([0.0, 0.0, distance]) + travel * forward
        # Put the lower ankle on the floor.
        pose[0:3] = r_cw @ hip_w
        pose[3:6] = _rotation_vector(r_cw @ r_world)
        j_world = model.joints(pose) @ r_wc.T
        lowest = max(j_world[13, 1], j_world[14, 1])
        hip_w[1] += camera_height - ankle_height - lowest
        pose[0:3] = r_cw @ hip_w
        poses[f] = pose
        body, lab = model.render_depth(pose, camera)
        body = body.astype(float)
        person = (body > 0) & ((scene == 0) | (body < scene))
        clean = np.where(person, body, scene)
        noisy = _sensor(clean, camera, noise, rng)
        depth[f] = np.clip(np.round(noisy * 1000.0), 0, MAX_DEPTH_MM).astype(np.uint16)
        mask[f] = person
        labels[f] = np.where(person, lab, -1)
        joints[f] = model.joints(pose).astype(np.float32)
    background = np.clip(np.round(_sensor(scene, camera, noise, rng) * 1000.0), 0, MAX_DEPTH_MM)
    meta = {
        "generator": "depthpose.synth",
        "motion": motion,
        "frames": frames,
        "cycles": cycles,
        "subject_height": height,
        "view_deg": view_deg,
        "distance": distance,
        "camera_height": camera_height,
        "tilt_deg": tilt_deg,
        "wall_distance": wall,
        "noise": noise,
        "seed": seed,
        "joints": "anatomical: Head = head centre, Neck = base of neck, Hand = wrist, "
        "Foot = ankle, Torso = mid-spine",
    }
    return {
        "depth": depth,
        "background": background.astype(np.uint16),
        "mask": mask,
        "joints": joints,
        "intrinsics": np.array(camera.intrinsics, np.float64),
        "joint_names": np.array(model.joint_names),
        "fps": np.array(fps, np.float64),
        "meta": np.array(json.dumps(meta)),
        "poses": poses,
        "labels": labels,
    }


def save(path: str | Path, seq: dict[str, np.ndarray]) -> None:
    """Writes a sequence as a compressed .npz in the shared data's layout."""
    arrays: dict[str, Any] = dict(seq)  # no key is one of savez's own keywords
    np.savez_compressed(path, **arrays)


def load(path: str | Path) -> dict[str, np.ndarray]:
    """Reads a sequence written by `save` (or a shared synthetic sequence)."""
    try:
        with np.load(path, allow_pickle=False) as d:
            return {k: d[k] for k in d.files}
    except FileNotFoundError:
        from .io import missing_file

        raise missing_file(path) from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise FileFormatError(f"{path}: not a sequence file ({e})") from None
