"""Body model bindings: kinematics, limits, distances, Jacobian, renderer, meshes."""

import depthpose
import numpy as np
import pytest
from depthpose._core import BodyModel, Camera, InvalidInputError
from depthpose.body import body_trimesh, ellipsoid_trimeshes

J = {n: i for i, n in enumerate(BodyModel().joint_names)}


def random_pose(rng: np.random.Generator) -> np.ndarray:
    m = BodyModel()
    lo, hi = m.lower_bounds, m.upper_bounds
    p = np.zeros(22)
    p[6:] = lo[6:] + (hi[6:] - lo[6:]) * rng.random(16)
    p[:3] = [0.1, -0.1, 3.0] + 0.2 * rng.standard_normal(3)
    p[3:6] = 0.5 * rng.standard_normal(3)
    return p


def test_names_and_bounds():
    m = BodyModel()
    assert len(m.param_names) == 22 and len(m.joint_names) == 15 and len(m.part_names) == 16
    assert m.joint_names[:4] == ["Head", "Neck", "RShoulder", "LShoulder"]
    # The package exports the same names, defined once in the native core.
    assert depthpose.JOINT_NAMES == m.joint_names
    lo, hi = m.lower_bounds, m.upper_bounds
    assert np.all(np.isinf(lo[:6])) and np.all(np.isinf(hi[:6]))
    assert np.all(lo[6:] < hi[6:])
    n = m.neutral_pose()
    assert np.all((n >= lo) & (n <= hi))
    wild = n.copy()
    wild[6:] = 10.0
    assert np.all(m.clamp_pose(wild)[6:] == hi[6:])


def test_neutral_joints_proportions_and_sides():
    m = BodyModel(1.75)
    j = m.joints(m.neutral_pose())
    assert j.shape == (15, 3)
    hipc = (j[J["RHip"]] + j[J["LHip"]]) / 2
    np.testing.assert_allclose(hipc, [0, 0, 3.0], atol=1e-12)
    # Subject's right side on the image left (camera -x); head up (camera -y).
    for r, l in [
        ("RShoulder", "LShoulder"),
        ("RElbow", "LElbow"),
        ("RHand", "LHand"),
        ("RHip", "LHip"),
        ("RKnee", "LKnee"),
        ("RFoot", "LFoot"),
    ]:
        assert j[J[r]][0] < 0 < j[J[l]][0]
        np.testing.assert_allclose(j[J[r]] * [-1, 1, 1], j[J[l]], atol=1e-12)  # symmetric
    assert j[J["Head"]][1] < j[J["Neck"]][1] < j[J["Torso"]][1] < 0 < j[J["RKnee"]][1]
    bone = lambda a, b: np.linalg.norm(j[J[a]] - j[J[b]])  # noqa: E731
    assert bone("RShoulder", "RElbow") == pytest.approx(0.239)
    assert bone("RElbow", "RHand") == pytest.approx(0.238)
    assert bone("RHip", "RKnee") == pytest.approx(0.443)
    assert bone("RKnee", "RFoot") == pytest.approx(0.401)
    assert bone("RShoulder", "LShoulder") == pytest.approx(0.352)
    assert bone("RHip", "LHip") == pytest.approx(0.232)
    assert j[J["Neck"]][1] - j[J["RShoulder"]][1] == pytest.approx(-0.068)
    # Scales with height.
    j2 = BodyModel(1.4).joints(m.neutral_pose())
    np.testing.assert_allclose((j2 - [0, 0, 3]) / 0.8, j - [0, 0, 3], atol=1e-12)


def test_shape_get_set():
    m = BodyModel()
    s = m.shape
    assert len(s) == len(m.shape_names)
    s2 = s.copy()
    s2[m.shape_names.index("upper_arm_length")] = 0.3
    m.shape = s2
    j = m.joints(m.neutral_pose())
    assert np.linalg.norm(j[J["RElbow"]] - j[J["RShoulder"]]) == pytest.approx(0.3)
    with pytest.raises(InvalidInputError, match="shape"):
        m.shape = np.ones(3)
    with pytest.raises(InvalidInputError, match="shape"):
        m.shape = -s


def test_bad_inputs_name_the_argument():
    m = BodyModel()
    pose = m.neutral_pose()
    with pytest.raises(InvalidInputError, match="^pose"):
        m.joints(pose[:21])
    bad = pose.copy()
    bad[5] = np.nan
    with pytest.raises(InvalidInputError, match="^pose"):
        m.joints(bad)
    with pytest.raises(InvalidInputError, match="^points"):
        m.distances(np.zeros((5, 2), np.float32), pose)
    with pytest.raises(InvalidInputError, match="^labels"):
        m.residuals_and_jacobian(np.zeros((5, 3)), np.zeros(4, np.int64), pose)
    with pytest.raises(InvalidInputError, match="^labels"):
        m.residuals_and_jacobian(np.zeros((2, 3)), np.array([0, 99]), pose)
    with pytest.raises(InvalidInputError, match="height"):
        BodyModel(-1.0)
    assert issubclass(InvalidInputError, ValueError)


def test_distances_match_dense_surface_sampling():
    rng = np.random.default_rng(0)
    m = BodyModel()
    pose = random_pose(rng)
    centres, rots, radii = m.ellipsoids(pose)
    pts = m.joints(pose)[rng.integers(0, 15, 200)] + 0.15 * rng.standard_normal((200, 3))
    d = m.distances(pts.astype(np.float32), pose)
    assert d.shape == (200, 16) and d.dtype == np.float32
    # Dense parametric sampling of two ellipsoids, refined by local minimisation.
    from scipy.optimize import minimize

    for k in (2, 5):
        th, ph = np.meshgrid(np.linspace(0, np.pi, 300), np.linspace(0, 2 * np.pi, 600))
        th, ph = th.ravel(), ph.ravel()

        def surf(t, p):
            loc = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1) * radii[k]
            return loc @ rots[k].T + centres[k]

        s = surf(th, ph)
        p32 = pts.astype(np.float32).astype(np.float64)
        for i in range(0, 200, 10):
            dd = np.linalg.norm(s - p32[i], axis=1)
            b = int(np.argmin(dd))
            res = minimize(
                lambda x: np.linalg.norm(surf(x[0], x[1]) - p32[i]),
                [th[b], ph[b]],
                method="Nelder-Mead",
                options={"xatol": 1e-12, "fatol": 1e-14},
            )
            assert abs(abs(d[i, k]) - res.fun) < 1e-5
            loc = (p32[i] - centres[k]) @ rots[k]
            assert (d[i, k] < 0) == (np.sum((loc / radii[k]) ** 2) < 1)


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(1)
    m = BodyModel()
    for _ in range(3):
        pose = random_pose(rng)
        pts = m.joints(pose)[rng.integers(0, 15, 60)] + 0.1 * rng.standard_normal((60, 3))
        labels = rng.integers(-1, 16, 60)
        r, jac = m.residuals_and_jacobian(pts, labels, pose)
        assert r.shape == (60,) and jac.shape == (60, 22)
        assert np.all(jac[labels < 0] == 0) and np.all(r[labels < 0] == 0)
        h = 1e-6
        for c in range(22):
            if 3 <= c < 6:
                w = np.zeros(3)
                w[c - 3] = h
                pp = m.pose_with_root_increment(pose, w)
                pm = m.pose_with_root_increment(pose, -w)
            else:
                pp, pm = pose.copy(), pose.copy()
                pp[c] += h
                pm[c] -= h
            fd = (
                m.residuals_and_jacobian(pts, labels, pp)[0]
                - m.residuals_and_jacobian(pts, labels, pm)[0]
            ) / (2 * h)
            scale = np.maximum(np.maximum(np.abs(fd), np.abs(jac[:, c])), 1e-3)
            assert np.all(np.abs(fd - jac[:, c]) <= 1e-4 * scale), c


def test_joints_jacobian_matches_finite_differences():
    rng = np.random.default_rng(2)
    m = BodyModel()
    pose = random_pose(rng)
    jac = m.joints_jacobian(pose)
    assert jac.shape == (15, 3, 22)
    h = 1e-6
    for c in (0, 4, 9, 11, 17, 21):
        if 3 <= c < 6:
            w = np.zeros(3)
            w[c - 3] = h
            pp, pm = m.pose_with_root_increment(pose, w), m.pose_with_root_increment(pose, -w)
        else:
            pp, pm = pose.copy(), pose.copy()
            pp[c] += h
            pm[c] -= h
        fd = (m.joints(pp) - m.joints(pm)) / (2 * h)
        np.testing.assert_allclose(jac[:, :, c], fd, atol=1e-6)


def test_render_matches_trimesh_ray_casting():
    trimesh = pytest.importorskip("trimesh")
    pytest.importorskip("rtree")  # trimesh's ray casting without embree needs it
    m = BodyModel()
    pose = m.neutral_pose()
    pose[8] = 0.7  # right arm forward
    pose[11] = 0.9
    cam = Camera(120.0, 120.0, 39.5, 29.5, 80, 60)
    depth, labels = m.render_depth(pose, cam)
    assert depth.shape == (60, 80) and depth.dtype == np.float32 and labels.dtype == np.int16
    assert np.all((depth > 0) == (labels >= 0))
    mesh = trimesh.util.concatenate(ellipsoid_trimeshes(m, pose, subdivisions=5))
    v, u = np.mgrid[0:60, 0:80]
    dirs = np.stack([(u - 39.5) / 120.0, (v - 29.5) / 120.0, np.ones_like(u, float)], -1).reshape(
        -1, 3
    )
    locs, idx, _ = mesh.ray.intersects_location(np.zeros_like(dirs), dirs, multiple_hits=True)
    ref = np.full(len(dirs), np.inf)
    np.minimum.at(ref, idx, locs[:, 2])
    ref = np.where(np.isfinite(ref), ref, 0).reshape(60, 80)
    both = (ref > 0) & (depth > 0)
    assert both.sum() > 300
    # Agreement where both hit, away from grazing silhouette pixels (where a tessellated
    # mesh and the exact quadric differ by more than the facet error).
    err = np.abs(ref - depth)[both]
    assert np.percentile(err, 95) < 1e-3
    assert np.median(err) < 3e-4
    # Hit masks agree except on a thin silhouette band.
    assert np.mean((ref > 0) != (depth > 0)) < 0.02


def test_superquadric_meshes():
    trimesh = pytest.importorskip("trimesh")
    m = BodyModel()
    pose = m.neutral_pose()
    parts = m.superquadric_meshes(pose)
    assert len(parts) == 16
    for v, f in parts:
        tm = trimesh.Trimesh(v, f, process=False)
        assert tm.is_watertight and tm.volume > 0
    body = body_trimesh(m, pose)
    assert body.face_attributes["part"].max() == 15
    j = m.joints(pose)
    lo, hi = body.bounds
    assert np.all(j >= lo - 1e-9) and np.all(j <= hi + 1e-9)


def test_mesh_resolution_is_bounded():
    # 10**6 rings would ask for ~10**12 vertices: refused up front (not a memory abort),
    # by the body model's meshes and the template meshes alike.
    from depthpose import _core

    m = BodyModel()
    for rings, sectors in [(2, 10), (10, 2), (1001, 10), (10**6, 10**6)]:
        with pytest.raises(depthpose.DepthPoseError, match="rings/sectors"):
            m.superquadric_meshes(m.neutral_pose(), rings, sectors)
        with pytest.raises(depthpose.DepthPoseError, match="rings/sectors"):
            _core.TemplateDatabase.template_mesh(0, None, rings=rings, sectors=sectors)
    v, f = m.superquadric_meshes(m.neutral_pose(), 1000, 3)[0]
    assert len(v) > 0 and len(f) > 0


def test_exported_from_package():
    assert depthpose.BodyModel is BodyModel


def test_capped_distances_are_exact_below_the_cap():
    m = BodyModel()
    pose = m.neutral_pose()
    pts = np.random.default_rng(0).normal(size=(300, 3)) * 0.4 + [0, 0, 3]
    exact = m.distances(pts, pose)
    capped = m.distances(pts, pose, cap=0.2)
    below = capped < 0.2
    assert np.array_equal(capped[below], exact[below])
    assert np.all(exact[~below] >= 0.2 - 1e-6) and np.all(capped[~below] <= exact[~below] + 1e-6)
    with pytest.raises(InvalidInputError, match="cap"):
        m.distances(pts, pose, cap=-1.0)
