"""Every public function against hostile arguments: wrong Python types, huge and
negative integers, NaN/inf/huge/denormal numbers, arrays of the wrong dtype, shape or
size. The contract (see ``hostile.outcome``): a result, or a ``DepthPoseError`` naming
the argument; a wrong Python type is also a ``TypeError``; nothing else escapes."""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import depthpose as dp
import numpy as np
import pytest
from depthpose import export, graphcut, stereo, viz
from hostile import BAD_INTS, BAD_REALS, WRONG_TYPES, fuzz, outcome
from hypothesis import given
from hypothesis import strategies as st

CAM = dp.Camera(60.0, 60.0, 19.5, 14.5, 40, 30)
MODEL = dp.BodyModel()
POSE = dp.BodyModel.neutral_pose()
DEPTH, _ = MODEL.render_depth(POSE, CAM)
MASK = DEPTH > 0
POINTS = np.array([[0.0, 0.0, 3.0], [0.1, -0.2, 2.9]], np.float32)
IMG = np.random.default_rng(0).integers(0, 255, (30, 40), np.uint8)
UNARY = np.array([[0.0, 1.0], [1.0, 0.0], [0.5, 0.5]])
EDGES = np.array([[0, 1], [1, 2]])
WEIGHTS = np.array([1.0, 2.0])
RGB = np.zeros((6, 5, 3), np.uint8)
BVH = Path(tempfile.gettempdir()) / f"depthpose-hostile-{id(MODEL)}.bvh"
FIT = dp.fit_pose(DEPTH, CAM, POSE, config={"max_iterations": 1, "recentred_start": False})

#: What each kind of argument is given besides wrong Python types.
INTS = BAD_INTS + [0, 1, 3, np.int64(7), np.uint8(2), 2.5, np.float64(3.0), True]
REALS = BAD_REALS + [0.0, -1.0, np.float32(0.5), np.int32(2), 10**30, True]
ARRAYS = [
    np.zeros(0),
    np.zeros((0, 3)),
    np.ones(3),
    np.ones((2, 2, 2)),
    np.full((3, 3), np.nan),
    np.full((3, 3), np.inf),
    np.array([[1, 2, "x"]], object),
    np.array([["a", "b", "c"]]),
    np.ones((2, 3), complex),
    np.ones((2, 3), bool),
    np.ones((2, 3), np.float16),
    np.ones((2, 3), ">f8"),
    np.array(["2020-01-01"], "datetime64[D]"),
    np.broadcast_to(np.float64(1.0), (20000, 20000)),
    np.broadcast_to(np.float32(1.0), (40000, 40000, 3)),
]
DEPTHS = [
    DEPTH.astype(np.float64),
    (DEPTH * 1000).astype(np.uint16),
    DEPTH.astype(np.int32),
    DEPTH.astype(np.float16),
    -DEPTH,
    np.where(MASK, np.inf, 0).astype(np.float32),
    np.zeros_like(DEPTH),
    np.full_like(DEPTH, np.nan),
    np.full_like(DEPTH, 1e30),
    np.full_like(DEPTH, 1e-40),
    DEPTH[:20],
    np.asfortranarray(DEPTH),
    DEPTH[None],
    np.broadcast_to(np.float32(2.0), (20000, 20000)),
]
MASKS = [
    MASK.astype(np.uint8),
    MASK.astype(np.uint8) * 255,
    MASK.astype(np.float64),
    np.where(MASK, "True", "False"),
    np.zeros_like(MASK),
    MASK[:, :10],
    MASK.astype(object),
]


@dataclass
class Api:
    """One public function: how to call it from keyword arguments, its valid
    arguments, and what kind each argument is."""

    call: Callable[..., Any]
    args: dict[str, Any]
    kinds: dict[str, str]
    #: Arguments not named in messages (the native name differs), if any.
    aliases: dict[str, tuple[str, ...]] = field(default_factory=dict)


def api(call: Callable[..., Any], **spec: tuple[str, Any]) -> Api:
    return Api(call, {k: v for k, (_, v) in spec.items()}, {k: t for k, (t, _) in spec.items()})


APIS: dict[str, Api] = {
    "Camera": api(
        dp.Camera,
        fx=("real", 60.0),
        fy=("real", 60.0),
        cx=("real", 19.5),
        cy=("real", 14.5),
        width=("int", 40),
        height=("int", 30),
    ),
    "Camera.from_intrinsics": api(
        dp.Camera.from_intrinsics,
        intrinsics=("array", [60.0, 60.0, 19.5, 14.5]),
        shape=("pair", (30, 40)),
    ),
    "Camera.scaled": api(lambda factor: CAM.scaled(factor), factor=("real", 0.5)),
    "Camera.project": api(lambda points: CAM.project(points), points=("array", POINTS)),
    "Camera.back_project": api(
        lambda pixels, depth: CAM.back_project(pixels, depth),
        pixels=("array", np.ones((2, 2))),
        depth=("array", np.ones(2)),
    ),
    "depth_to_points": api(
        dp.depth_to_points, depth=("depth", DEPTH), camera=("camera", CAM), mask=("mask", MASK)
    ),
    "surface_normals": api(
        dp.surface_normals,
        depth=("depth", DEPTH),
        camera=("camera", CAM),
        mask=("mask", MASK),
        radius=("int", 2),
    ),
    "pixel_graph": api(
        dp.pixel_graph,
        depth=("depth", DEPTH),
        camera=("camera", CAM),
        mask=("mask", MASK),
        connectivity=("int", 8),
    ),
    "foreground_mask": api(
        dp.foreground_mask,
        depth=("depth", DEPTH),
        background=("depth", DEPTH + 0.5),
        min_depth=("real", 0.3),
        max_step=("real", 0.25),
        min_component=("int", 10),
        large_share=("real", 0.3),
        attach_depth=("real", 0.5),
        min_joined_piece=("int", 0),
    ),
    "point_cloud": api(
        dp.point_cloud,
        depth=("depth", DEPTH),
        camera=("camera", CAM),
        mask=("mask", MASK),
        normal_radius=("int", 2),
    ),
    "BodyModel": api(dp.BodyModel, height=("real", 1.7)),
    "BodyModel.joints": api(MODEL.joints, pose=("array", POSE)),
    "BodyModel.joints_jacobian": api(MODEL.joints_jacobian, pose=("array", POSE)),
    "BodyModel.distances": api(
        MODEL.distances, points=("array", POINTS), pose=("array", POSE), cap=("real", 0.5)
    ),
    "BodyModel.residuals_and_jacobian": api(
        MODEL.residuals_and_jacobian,
        points=("array", POINTS),
        labels=("array", np.array([0, 3])),
        pose=("array", POSE),
    ),
    "BodyModel.depth_discrepancies": api(
        MODEL.depth_discrepancies,
        poses=("array", POSE[None]),
        depth=("depth", DEPTH),
        mask=("mask", MASK),
        camera=("camera", CAM),
        cap=("real", 0.1),
    ),
    "BodyModel.render_depth": api(MODEL.render_depth, pose=("array", POSE), camera=("camera", CAM)),
    "BodyModel.superquadric_meshes": api(
        MODEL.superquadric_meshes, pose=("array", POSE), rings=("int", 4), sectors=("int", 5)
    ),
    "BodyModel.with_shape_factors": api(MODEL.with_shape_factors, factors=("array", np.ones(12))),
    "BodyModel.pose_with_root_increment": api(
        dp.BodyModel.pose_with_root_increment, pose=("array", POSE), omega=("array", np.zeros(3))
    ),
    "BodyModel.clamp_pose": api(MODEL.clamp_pose, pose=("array", POSE)),
    "fit_pose": api(
        dp.fit_pose,
        depth=("depth", DEPTH),
        camera=("camera", CAM),
        init_pose=("array", POSE),
        mask=("mask", MASK),
        model=("object", MODEL),
        prior=("array", POSE),
        prior_weight=("real", 10.0),
        config=("object", {"max_iterations": 1}),
        resume=("object", FIT),
    ),
    "fit_poses": api(
        dp.fit_poses,
        depth=("depth", DEPTH),
        camera=("camera", CAM),
        init_poses=("array", POSE[None]),
        config=("object", {"max_iterations": 1}),
    ),
    "label_all_pixels": api(
        dp.fit.label_all_pixels,
        depth=("depth", DEPTH),
        camera=("camera", CAM),
        result=("object", FIT),
        config=("object", {"stride": 2}),
    ),
    "pose_from_joints": api(
        dp.pose_from_joints, joints=("array", MODEL.joints(POSE)), init=("array", POSE)
    ),
    "FitConfig": api(
        dp.FitConfig,
        sigma=("real", 0.02),
        potts=("real", 0.3),
        max_iterations=("int", 5),
        stride=("int", 2),
        loss=("str", "huber"),
        loss_scale=("real", 0.03),
        label_all_pixels=("flag", True),
        expansion_cycles=("int", 2),
    ),
    "fit_shape": api(
        dp.fit_shape,
        depths=("array", DEPTH[None]),
        camera=("camera", CAM),
        poses=("array", POSE[None]),
        iterations=("int", 1),
        lm_iterations=("int", 1),
        bounds=("pair", (0.8, 1.2)),
        config=("object", {"max_iterations": 1}),
    ),
    "Graph": api(graphcut.Graph, n_nodes=("int", 3), dtype=("object", int), edge_hint=("int", 2)),
    "grid_edges": api(graphcut.grid_edges, h=("int", 3), w=("int", 4), connectivity=("int", 8)),
    "alpha_expansion": api(
        graphcut.alpha_expansion,
        unary=("array", UNARY),
        edges=("array", EDGES),
        weights=("array", WEIGHTS),
        pairwise=("array", np.array([[0.0, 1.0], [1.0, 0.0]])),
        init=("array", np.array([0, 1, 0])),
        max_cycles=("int", 3),
    ),
    "alpha_beta_swap": api(
        graphcut.alpha_beta_swap,
        unary=("array", UNARY),
        edges=("array", EDGES),
        weights=("array", WEIGHTS),
        max_cycles=("int", 3),
    ),
    "energy": api(
        graphcut.energy,
        labels=("array", np.array([0, 1, 1])),
        unary=("array", UNARY),
        edges=("array", EDGES),
        weights=("array", WEIGHTS),
    ),
    "stereo.match": api(
        stereo.match,
        left=("array", IMG),
        right=("array", np.roll(IMG, -2, 1)),
        max_disparity=("int", 5),
        window=("int", 5),
        threshold=("real", 0.5),
        num_seeds=("int", 20),
        seed=("int", 1),
        seeds=("array", np.array([[10.0, 5.0, 2.0]])),
        min_segment=("int", 5),
        similarity=("str", "ncc"),
        lr_check=("flag", False),
        half_occlusion=("flag", True),
    ),
    "StereoPoseTracker": api(
        dp.StereoPoseTracker,
        camera=("camera", CAM),
        baseline=("real", 0.12),
        doffs=("real", 0.0),
        max_disparity=("int", 16),
        fattening=("flag", True),
        disparity_tolerance=("real", 1.0),
        disparity_sigma=("real", 0.25),
        weigh_points=("flag", False),
    ),
    "StereoPoseTracker.update": api(
        lambda left, right, mask: dp.StereoPoseTracker(CAM, 0.12).update(left, right, mask),
        left=("array", IMG),
        right=("array", np.roll(IMG, -2, 1)),
        mask=("mask", MASK),
    ),
    "stereo.depth_from_disparity": api(
        stereo.depth_from_disparity,
        disparity=("array", IMG.astype(np.float32)),
        focal=("real", 500.0),
        baseline=("real", 0.1),
        doffs=("real", 0.0),
    ),
    "surface_context": api(
        dp.surface_context,
        depth=("depth", DEPTH),
        camera=("camera", CAM),
        mask=("mask", MASK),
        samples=("int", 30),
        radial_bins=("int", 3),
        angular_bins=("int", 4),
        seed=("int", 1),
        depth_weight=("real", 0.5),
    ),
    "viz.colorize_depth": api(viz.colorize_depth, depth=("array", DEPTH), near=("real", 1.0)),
    "viz.overlay_mask": api(
        viz.overlay_mask, rgb=("array", RGB), mask=("mask", RGB[..., 0] > 0), alpha=("real", 0.5)
    ),  # fmt: skip
    "viz.overlay_labels": api(
        viz.overlay_labels, rgb=("array", RGB), labels=("array", np.zeros((6, 5), np.int16))
    ),
    "viz.draw_skeleton": api(
        viz.draw_skeleton,
        rgb=("array", np.zeros((30, 40, 3), np.uint8)),
        joints=("array", MODEL.joints(POSE)),
        camera=("camera", CAM),
        width=("int", 2),
    ),
    "viz.montage": api(viz.montage, images=("object", [RGB, RGB]), columns=("int", 2)),
    "export.write_bvh": api(
        lambda model, poses, fps: export.write_bvh(BVH, model, poses, fps),
        model=("object", MODEL),
        poses=("array", np.stack([POSE, POSE])),
        fps=("real", 30.0),
    ),
}

#: Hostile values for an argument of each kind.
HOSTILE: dict[str, list[Any]] = {
    "int": INTS,
    "real": REALS,
    "array": ARRAYS,
    "depth": DEPTHS + ARRAYS[-3:],
    "mask": MASKS,
    "camera": [dp.Camera(60, 60, 19.5, 14.5, 20, 15), CAM.intrinsics],
    "object": [1, "x", np.zeros(3), dp.FitConfig],
    "pair": [(1,), (1, 2, 3), "ab", (2**200, 1), (np.nan, 1)],
    "str": ["", "unknown", "x" * 10000],
    "flag": [1, 0, np.True_, "True"],
}

CASES = [(name, arg) for name, a in APIS.items() for arg in a.kinds]


def run(name: str, arg: str, value: Any) -> Any:
    a = APIS[name]
    args = dict(a.args)
    args[arg] = value
    names = (arg, *a.aliases.get(arg, ()))
    r = outcome(lambda: a.call(**args))
    if isinstance(r, dp.DepthPoseError) and not isinstance(r, dp.NoBodyError):
        msg = str(r)
        # The argument is named, or (a whole-call problem) another argument of the call.
        assert any(n in msg for n in names) or any(k in msg for k in args), (name, arg, msg)
    return r


@pytest.mark.parametrize(("name", "arg"), CASES, ids=[f"{n}-{a}" for n, a in CASES])
def test_wrong_python_types_are_type_errors_naming_the_argument(name, arg):
    for value in WRONG_TYPES:
        if value is None and arg not in ("fx", "pose", "depth", "points", "unary", "camera"):
            continue  # None is the documented default of many arguments
        r = run(name, arg, value)
        kind = APIS[name].kinds[arg]
        if kind == "str" and isinstance(value, str):
            continue  # the right type: a value error when not a known name
        if kind in ("int", "real", "camera", "flag", "str") and value is not None:
            assert isinstance(r, TypeError), (name, arg, value, r)


@fuzz(60)
@given(st.sampled_from(CASES), st.data())
def test_hostile_values_give_a_result_or_a_clear_error(case, data):
    name, arg = case
    value = data.draw(st.sampled_from(HOSTILE[APIS[name].kinds[arg]]))
    run(name, arg, value)


@pytest.mark.parametrize(("name", "arg"), [c for c in CASES if APIS[c[0]].kinds[c[1]] == "int"])
def test_integers_beyond_any_range_are_named_not_overflow_errors(name, arg):
    for value in (2**127, 2**200, -(2**130), 10**400):
        r = run(name, arg, value)
        if isinstance(r, dp.DepthPoseError):
            assert arg in str(r) and len(str(r)) < 300


def test_the_valid_arguments_of_the_catalogue_are_valid():
    for name, a in APIS.items():
        r = outcome(lambda a=a: a.call(**a.args))
        assert not isinstance(r, dp.DepthPoseError), (name, r)
