"""Size limits, overflow, hangs, panics and silent garbage: each failure the hostile
harness found, and the rule that now holds for it."""

from __future__ import annotations

import time

import depthpose as dp
import numpy as np
import pytest
from depthpose import export, graphcut, viz
from hostile import check_message, fuzz, outcome, refused
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

CAM = dp.Camera(60.0, 60.0, 19.5, 14.5, 40, 30)
MODEL = dp.BodyModel()
POSE = dp.BodyModel.neutral_pose()
DEPTH, _ = MODEL.render_depth(POSE, CAM)


# ---- size limits, checked before anything is allocated or copied ----------------------


def quick(call, limit: str) -> None:
    """``call`` raises ResourceLimitError naming ``limit`` at once (no copy first)."""
    t0 = time.perf_counter()
    e = refused(call, dp.ResourceLimitError)
    assert limit in str(e), str(e)
    assert time.perf_counter() - t0 < 1.0


def test_huge_inputs_are_refused_before_any_copy():
    # Neither array is ever materialised: a copy would take seconds and gigabytes.
    big = np.broadcast_to(np.float64(2.0), (20000, 20000))
    fortran = np.zeros((20000, 20000), order="F")  # untouched pages cost nothing
    long = np.broadcast_to(np.float64(1.0), (40_000_000, 3))
    for a in (big, fortran):
        quick(lambda a=a: dp.depth_to_points(a, CAM), "MAX_IMAGE_PIXELS")
        quick(lambda a=a: dp.stereo.match(a, a), "MAX_IMAGE_PIXELS")
        quick(lambda a=a: dp.stereo.depth_from_disparity(a, 500.0, 0.1), "MAX_ARRAY_ELEMENTS")
        quick(lambda a=a: dp.io.write_depth("/tmp/never-written.png", a), "MAX_IMAGE_PIXELS")
        quick(lambda a=a: viz.colorize_depth(a), "MAX_IMAGE_PIXELS")
    quick(lambda: CAM.project(long), "MAX_ARRAY_ELEMENTS")
    quick(lambda: MODEL.distances(long, POSE), "MAX_ARRAY_ELEMENTS")
    quick(lambda: graphcut.alpha_expansion(long[:, :2], np.zeros((0, 2), int), np.zeros(0)),
          "MAX_ARRAY_ELEMENTS")  # fmt: skip


def test_results_too_large_to_allocate_are_refused_naming_the_limit():
    quick(lambda: MODEL.render_depth(POSE, dp.Camera(100, 100, 1, 1, 32768, 32768)),
          "MAX_IMAGE_PIXELS")  # fmt: skip
    quick(lambda: graphcut.grid_edges(16000, 16000, 8), "MAX_RESULT_BYTES")
    quick(lambda: MODEL.superquadric_meshes(POSE, 1000, 1000), "MAX_RESULT_BYTES")
    quick(lambda: graphcut.Graph(2**27, edge_hint=2**31 - 1), "MAX_RESULT_BYTES")
    # 10,000 labels with a dense pairwise table (never materialised here either).
    pairwise = np.broadcast_to(np.float64(1.0), (10000, 10000))
    no_edges = np.zeros((0, 2), int)
    quick(
        lambda: graphcut.alpha_expansion(
            np.zeros((1, 10000)), no_edges, np.zeros(0), pairwise=pairwise
        ),
        "MAX_LABELS",
    )
    assert graphcut.MAX_LABELS == 1024 and dp.MAX_IMAGE_PIXELS == 2**23


def test_fits_of_more_points_than_the_limit_are_refused_at_once():
    big = dp.Camera(900.0, 900.0, 639.5, 511.5, 1280, 1024)
    depth = np.full((1024, 1280), 2.0, np.float32)
    for call in (
        lambda: dp.fit_pose(depth, big, POSE),
        lambda: dp.fit_poses(depth, big, POSE[None]),
        lambda: dp.fit_shape(depth[None], big, POSE[None]),
        lambda: dp.surface_context(depth, big),
        lambda: dp.TemplateDatabase.default(progress=False).match(depth, big),
    ):
        quick(call, "MAX_FIT_POINTS")
    # A mask of the person keeps the same image within the limit.
    mask = np.zeros(depth.shape, bool)
    mask[400:600, 600:700] = True
    assert dp.surface_context(depth, big, mask)[0].shape[0] > 0


# ---- arithmetic overflow: no hang, no infinite energy --------------------------------


def test_overflowing_weights_are_refused_not_looped_on():
    t0 = time.perf_counter()
    e = refused(
        lambda: graphcut.alpha_expansion(
            np.array([[3.18, 1.35], [0.20, 0.08]]), np.array([[0, 1]]), np.array([1e308]),
            pairwise=np.array([[0.0, 2.0], [2.0, 0.0]]), max_cycles=1,
        ),
        dp.InvalidInputError,
        "weights",
    )  # fmt: skip
    assert "float64" in str(e) and time.perf_counter() - t0 < 1.0


@fuzz(40)
@given(
    st.integers(2, 6),
    st.integers(2, 4),
    st.sampled_from([1.0, 1e10, 1e150, 1e300, 1e307, 1.7e308]),
    st.sampled_from([1.0, 1e154, 1e300, 1.7e308]),
    st.integers(0, 2**31),
    st.booleans(),
)
def test_crf_energies_stay_finite_or_the_problem_is_refused(n, l, w, u, seed, swap):
    rng = np.random.default_rng(seed)
    unary = rng.uniform(0, 1, (n, l)) * u
    edges = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    weights = rng.uniform(0, 1, n - 1) * w
    v = np.minimum(np.abs(np.subtract.outer(np.arange(l), np.arange(l))), 2).astype(float)
    solve = graphcut.alpha_beta_swap if swap else graphcut.alpha_expansion
    t0 = time.perf_counter()
    r = outcome(lambda: solve(unary, edges, weights, pairwise=v, max_cycles=50))
    assert time.perf_counter() - t0 < 5.0
    if not isinstance(r, dp.DepthPoseError):
        labels, energy = r
        assert np.isfinite(energy)
        assert energy == pytest.approx(graphcut.energy(labels, unary, edges, weights, v))


@fuzz(40)
@given(
    st.integers(2, 6),
    st.lists(st.sampled_from([0.0, 1.0, 1e300, 1.7e308, 5e-324]), min_size=4, max_size=12),
)
def test_maxflow_of_huge_capacities_ends(n, caps):
    g = graphcut.Graph(n)
    k = len(caps) // 2
    src = np.arange(k) % n
    dst = (np.arange(k) + 1) % n
    t0 = time.perf_counter()
    r = outcome(lambda: g.add_edges(src, dst, np.array(caps[:k]), np.array(caps[k : 2 * k])))
    r = outcome(
        lambda: g.add_terminal_edges(np.arange(n), np.full(n, caps[0]), np.full(n, caps[-1]))
    )
    flow = outcome(g.maxflow)
    assert time.perf_counter() - t0 < 5.0
    if not isinstance(flow, dp.DepthPoseError) and r is None:
        assert flow >= 0


# ---- panics --------------------------------------------------------------------------


def test_a_result_of_another_image_size_is_refused_not_panicked_on():
    fit = dp.fit_pose(DEPTH, CAM, POSE, config={"max_iterations": 1, "stride": 2,
                                                 "label_all_pixels": False})  # fmt: skip
    small = CAM.scaled(0.5)
    depth, _ = MODEL.render_depth(POSE, small)
    e = refused(lambda: dp.fit.label_all_pixels(depth, small, fit, config={"stride": 2}),
                dp.InvalidInputError, "result")  # fmt: skip
    assert "30x40" in str(e)
    # Same pixel count, other shape: refused too (its labels would not be an image).
    tall = dp.Camera(60.0, 60.0, 14.5, 19.5, 30, 40)
    d2, _ = MODEL.render_depth(POSE, tall)
    refused(lambda: dp.fit.label_all_pixels(d2, tall, fit, config={"stride": 2}),
            dp.InvalidInputError, "result")  # fmt: skip
    refused(lambda: dp.fit_pose(d2, tall, POSE, resume=fit), dp.InvalidInputError, "resume")


def test_a_template_file_with_wrapped_counts_is_refused(tmp_path):
    db = dp.TemplateDatabase.default(progress=False)
    db.save(tmp_path / "db.npz")
    with np.load(tmp_path / "db.npz") as f:
        arrays = {k: f[k] for k in f.files}
    counts = arrays["counts"].copy()
    total = int(counts.sum())
    # Two counts of 2**63 - 1 wrap around to -2; the third makes the sum right again.
    counts[0] = counts[1] = 2**63 - 1
    counts[2] = total - int(counts[3:].sum()) + 2
    arrays["counts"] = counts
    np.savez(tmp_path / "wrapped.npz", **arrays)
    e = refused(lambda: dp.TemplateDatabase.load(tmp_path / "wrapped.npz"), dp.FileFormatError)
    assert "do not fit together" in str(e)


# ---- silent garbage refused ----------------------------------------------------------


def test_absurd_intrinsics_are_refused():
    for fx in (5e-324, 1e-300, 1e300, 0.0, -1.0, np.nan):
        refused(lambda fx=fx: dp.Camera(fx, 60.0, 19.5, 14.5, 40, 30), dp.InvalidInputError, "fx")
    refused(lambda: CAM.scaled(1e-9), dp.InvalidInputError, "factor", "f")


def test_masks_must_be_bool_or_zero_one_integers():
    mask = DEPTH > 0
    rgb = viz.colorize_depth(DEPTH)
    # A uint8 mask of 0/1 is a mask, not fancy indices into the picture's rows.
    assert np.array_equal(viz.overlay_mask(rgb, mask.astype(np.uint8)), viz.overlay_mask(rgb, mask))
    refused(
        lambda: viz.overlay_mask(rgb, mask.astype(np.uint8) * 255), dp.InvalidInputError, "mask"
    )
    # A string array is never cast to bool ('False' would be True).
    words = np.where(mask, "True", "False")
    refused(lambda: viz.overlay_mask(rgb, words), dp.InvalidTypeError, "mask")
    refused(lambda: dp.depth_to_points(DEPTH, CAM, words), dp.InvalidTypeError, "mask")
    refused(
        lambda: dp.depth_to_points(DEPTH, CAM, mask.astype(float)), dp.InvalidInputError, "mask"
    )
    db = dp.TemplateDatabase.default(progress=False)
    est = dp.PoseEstimator(CAM, templates=db)
    refused(lambda: est.estimate(DEPTH, words), dp.InvalidTypeError, "mask")
    refused(lambda: est.estimate(DEPTH, mask.astype(np.int64) * 2), dp.InvalidInputError, "mask")
    tracker = dp.PoseTracker(CAM, templates=db, calibrate=False)
    refused(lambda: tracker.update(DEPTH, words), dp.InvalidTypeError, "mask")


def test_pipeline_arguments_are_checked():
    frames = np.stack([DEPTH, DEPTH])
    from depthpose.pipeline import estimate_frames

    for warmup in (-3, 3, 2.5, "1"):
        r = outcome(lambda w=warmup: estimate_frames(frames, CAM, warmup=w))
        assert isinstance(r, dp.DepthPoseError) and "warmup" in str(r)
    refused(lambda: estimate_frames(frames.astype(object), CAM), dp.InvalidTypeError, "frames")
    refused(lambda: dp.PoseEstimator(CAM, model="x"), dp.InvalidTypeError, "model")
    refused(lambda: dp.PoseEstimator(CAM, templates=3), dp.InvalidTypeError, "templates")
    refused(lambda: dp.TemplateDatabase.build(model=3), dp.InvalidTypeError, "model")


def test_numbers_in_messages_are_brief():
    for call in (
        lambda: dp.Camera(1e300, 60, 19.5, 14.5, 40, 30),
        lambda: dp.FitConfig(potts=1e300),
        lambda: dp.foreground_mask(DEPTH, min_depth=1e300, max_depth=1e301),
        lambda: dp.stereo.depth_from_disparity(np.ones((3, 3)), 1e300, 1e300),
        lambda: graphcut.alpha_expansion(np.ones((2, 2)), np.array([[0, 1]]), np.array([-1e300])),
        lambda: dp.Camera(60, 60, 19.5, 14.5, 10**30, 30),
    ):
        check_message(refused(call))


def test_object_arrays_are_type_errors_not_numpy_errors():
    obj = np.array([[1.0, None, 3.0]], dtype=object)
    for call in (
        lambda: CAM.project(obj),
        lambda: viz.colorize_depth(obj),
        lambda: export.write_bvh("/tmp/x.bvh", MODEL, obj),
        lambda: dp.io.write_pfm("/tmp/x.pfm", obj),
        lambda: dp.pose_from_joints(obj),
    ):
        refused(call, dp.InvalidTypeError)


def test_write_bvh_refuses_bad_rates_and_partly_nan_poses(tmp_path):
    poses = np.stack([POSE, POSE])
    for fps in (0, -1, np.nan, np.inf, "30"):
        r = outcome(lambda f=fps: export.write_bvh(tmp_path / "a.bvh", MODEL, poses, fps=f))
        assert isinstance(r, dp.DepthPoseError) and "fps" in str(r)
    half = poses.copy()
    half[1, 3] = np.nan
    refused(
        lambda: export.write_bvh(tmp_path / "a.bvh", MODEL, half), dp.InvalidInputError, "poses"
    )
    missing = poses.copy()
    missing[1] = np.nan  # a failed frame repeats the previous one
    export.write_bvh(tmp_path / "a.bvh", MODEL, missing, fps=np.float32(25))
    assert "Frame Time: 0.040000" in (tmp_path / "a.bvh").read_text()


def test_numpy_scalars_are_numbers():
    cam = dp.Camera(np.float32(60), np.float64(60), np.int64(19), np.float16(14.5), np.int32(40),
                    np.uint16(30))  # fmt: skip
    assert cam.shape == (30, 40)
    assert dp.stereo.depth_from_disparity(np.ones((2, 2)), np.float32(10), np.int8(1))[0, 0] == 10
    depth = np.where(DEPTH > 0, DEPTH, 0)
    background = np.full_like(depth, 5.0)
    mask = dp.foreground_mask(
        depth, background, min_depth=np.float32(0.5), min_component=np.uint8(5)
    )
    assert mask.any()


@fuzz(30)
@given(hnp.arrays(np.float64, 2, elements=st.floats(allow_nan=True, allow_infinity=True)))
def test_depth_from_disparity_never_returns_garbage(d):
    z = outcome(lambda: dp.stereo.depth_from_disparity(d.reshape(1, 2), 500.0, 0.1))
    if not isinstance(z, dp.DepthPoseError):
        assert np.isfinite(z).all() and (z >= 0).all()


def test_projections_beyond_the_float_range_are_not_returned():
    uv = CAM.project(np.array([[1.0, 1.0, 1e-320], [0.0, 0.0, 2.0]]))
    assert np.isnan(uv[0]).all() and np.isfinite(uv[1]).all()
    refused(
        lambda: CAM.back_project(np.array([[1e300, 0.0]]), np.array([1e300])),
        dp.InvalidInputError,
        "depth",
    )


def test_the_tracker_recovers_after_hostile_frames():
    tracker = dp.PoseTracker(CAM, templates=dp.TemplateDatabase.default(progress=False),
                             calibrate=False)  # fmt: skip
    first = tracker.update(DEPTH)
    for frame in (np.zeros_like(DEPTH), np.full_like(DEPTH, np.nan), -DEPTH, DEPTH[:10],
                  DEPTH.astype(object), np.asfortranarray(DEPTH)):  # fmt: skip
        refused(lambda f=frame: tracker.update(f))
    refused(lambda: tracker.update(DEPTH, np.where(DEPTH > 0, "1", "0")), dp.InvalidTypeError)
    again = tracker.update(DEPTH)
    assert np.isfinite(again.joints).all()
    assert np.abs(again.joints - first.joints).max() < 0.05
