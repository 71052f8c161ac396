"""Exports: BVH that recomposes to the fitted segment rotations, meshes, JSON lines."""

from __future__ import annotations

import json

import depthpose as dp
import numpy as np
import pytest
from depthpose import export
from scipy.spatial.transform import Rotation

BodyModel = pytest.importorskip("depthpose.body").BodyModel


def random_poses(model, n, seed=0):
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(model.lower_bounds), np.asarray(model.upper_bounds)
    poses = []
    for _ in range(n):
        p = np.asarray(model.neutral_pose(), np.float64).copy()
        p[6:] = rng.uniform(lo[6:], hi[6:]) * 0.6
        p[3:6] = rng.normal(0, 0.5, 3)
        p[:3] += rng.normal(0, 0.2, 3)
        poses.append(p)
    return np.array(poses)


def parse_bvh(text):
    names, parents, stack, channels = [], [], [], []
    lines = text.splitlines()
    k = 0
    while lines[k].strip() != "MOTION":
        tok = lines[k].split()
        if tok and tok[0] in ("ROOT", "JOINT"):
            names.append(tok[1])
            parents.append(stack[-1] if stack else None)
        elif tok and tok[0] == "CHANNELS":
            channels.append(int(tok[1]))
        elif tok and tok[0] == "{":
            stack.append(names[-1] if names else None)
        elif tok and tok[0] == "}":
            stack.pop()
        elif tok and tok[0] == "End":
            names.append(None)  # placeholder to keep the brace stack aligned
            parents.append(None)
        k += 1
    keep = [i for i, n in enumerate(names) if n is not None]
    names = [names[i] for i in keep]
    parents = [parents[i] for i in keep]
    n_frames = int(lines[k + 1].split()[1])
    motion = np.array([[float(v) for v in ln.split()] for ln in lines[k + 3 : k + 3 + n_frames]])
    return names, parents, channels, motion


def test_bvh_recomposes_segment_rotations(tmp_path):
    model = BodyModel()
    poses = random_poses(model, 4)
    path = tmp_path / "seq.bvh"
    export.write_bvh(path, model, poses, fps=30)
    names, parents, channels, motion = parse_bvh(path.read_text())
    assert sorted(names) == sorted(export.BVH_NAMES.values())
    part = {export.BVH_NAMES[n]: n for n in model.part_names}
    assert motion.shape == (4, sum(channels))
    flip = np.diag([1.0, -1.0, -1.0])
    for f, pose in enumerate(poses):
        frames = np.asarray(model.segment_transforms(pose))
        world = {}
        col = 0
        for name, parent, nch in zip(names, parents, channels, strict=False):
            vals = motion[f, col : col + nch]
            col += nch
            z, x, y = vals[-3:]
            # Intrinsic Z-X-Y: Rz(z) @ Rx(x) @ Ry(y), as BVH channels compose.
            local = Rotation.from_euler("ZXY", [z, x, y], degrees=True).as_matrix()
            world[name] = local if parent is None else world[parent] @ local
            want = flip @ frames[list(model.part_names).index(part[name]), :3, :3] @ flip
            np.testing.assert_allclose(world[name], want, atol=1e-5, err_msg=name)
        np.testing.assert_allclose(motion[f, :3], flip @ frames[3, :3, 3], atol=1e-5)


def test_bvh_bad_input(tmp_path):
    model = BodyModel()
    with pytest.raises(dp.DepthPoseError, match="poses"):
        export.write_bvh(tmp_path / "x.bvh", model, np.zeros((3, 5)))
    with pytest.raises(dp.DepthPoseError, match="NaN"):
        export.write_bvh(tmp_path / "x.bvh", model, np.full((3, 22), np.nan))


FLIP = np.diag([1.0, -1.0, -1.0])
HEAD, R_FOOT, L_FOOT = 0, 13, 14


def test_bvh_round_trips_through_bvhio(tmp_path):
    """pose -> BVH -> a BVH library's skeleton: every joint where the model puts it
    (y-up), within 1 mm; standard names; End Sites that reach beyond their joint."""
    bvhio = pytest.importorskip("bvhio")
    model = BodyModel()
    poses = random_poses(model, 3, seed=4)
    path = tmp_path / "seq.bvh"
    export.write_bvh(path, model, poses)
    text = path.read_text()
    for name in (
        "Hips",
        "Spine",
        "Neck",
        "Head",
        "LeftArm",
        "LeftForeArm",
        "LeftHand",
        "RightArm",
        "LeftUpLeg",
        "LeftLeg",
        "LeftFoot",
        "RightUpLeg",
        "RightFoot",
    ):
        assert f"JOINT {name}\n" in text or f"ROOT {name}\n" in text, name
    ends = [ln.split()[1:] for k, ln in enumerate(text.splitlines())
            if "OFFSET" in ln and "End Site" in text.splitlines()[k - 2]]  # fmt: skip
    assert len(ends) == 5  # head, hands, feet
    head, r_hand, l_hand, r_foot, l_foot = np.array(ends, float)  # in the file's order
    assert head[1] > 0.03  # the top of the head
    assert r_hand[1] < -0.1 and l_hand[1] < -0.1  # the finger tips, down the arm
    assert r_foot[2] > 0.05 and l_foot[2] > 0.05  # the toes, forward
    root = bvhio.readAsHierarchy(str(path))
    joints = {j.Name: j for j, _, _ in root.layout()}
    index = {export.BVH_NAMES[n]: k for k, n in enumerate(model.part_names)}
    for f, pose in enumerate(poses):
        root.loadPose(f)
        frames = np.asarray(model.segment_transforms(pose))
        for name, k in index.items():
            got = np.array(joints[name].PositionWorld)
            np.testing.assert_allclose(got, FLIP @ frames[k, :3, 3], atol=1e-3, err_msg=name)
        # Upright: the head above the feet in +y.
        want = model.joints(pose) @ FLIP
        assert want[HEAD, 1] > want[[R_FOOT, L_FOOT], 1].max()


def test_bvh_holds_unseen_legs_at_rest(tmp_path):
    model = BodyModel()
    poses = random_poses(model, 3, seed=5)
    confidence = np.ones((3, 15))
    confidence[1, [9, 11, 13]] = 0.0  # frame 1: the right hip, knee and foot unseen
    export.write_bvh(tmp_path / "conf.bvh", model, poses, confidence=confidence)
    rest = poses.copy()
    rest[1, 16:19] = 0.0  # the right hip (2) and knee at their rest angles
    export.write_bvh(tmp_path / "rest.bvh", model, rest)
    assert (tmp_path / "conf.bvh").read_text() == (tmp_path / "rest.bvh").read_text()
    export.write_bvh(tmp_path / "plain.bvh", model, poses)
    assert (tmp_path / "plain.bvh").read_text() != (tmp_path / "rest.bvh").read_text()
    with pytest.raises(dp.InvalidInputError, match="confidence"):
        export.write_bvh(tmp_path / "x.bvh", model, poses, confidence=np.ones((2, 15)))


@pytest.mark.parametrize("suffix", ["ply", "glb", "gltf", "obj"])
def test_mesh_export_is_upright(tmp_path, suffix):
    """A mesh export opens upright (y up): the top of the mesh is the head, its bottom
    the feet, at the model's joints turned 180° about x."""
    import trimesh

    model = BodyModel()
    pose = np.asarray(model.neutral_pose()).copy()
    pose[:3] = [0.3, -0.2, 3.0]  # off centre, so that y-down and y-up differ
    path = tmp_path / f"body.{suffix}"
    export.save_mesh(path, model, pose)
    mesh = trimesh.load(path, force="mesh")
    assert len(mesh.vertices) > 1000
    joints = model.joints(pose) @ FLIP
    top, bottom = mesh.bounds[1, 1], mesh.bounds[0, 1]
    assert 1.5 < top - bottom < 1.95
    assert joints[HEAD, 1] < top < joints[HEAD, 1] + 0.2
    assert joints[[R_FOOT, L_FOOT], 1].min() - 0.15 < bottom < joints[[R_FOOT, L_FOOT], 1].min()
    assert abs(mesh.bounds.mean(0)[2] - joints[:, 2].mean()) < 0.3  # z towards the camera
    camera = tmp_path / f"camera.{suffix}"
    export.save_mesh(camera, model, pose, y_up=False)
    down = trimesh.load(camera, force="mesh")
    np.testing.assert_allclose(down.bounds[0, 1], -top, atol=1e-4)


def test_gltf_exports_side_by_side(tmp_path):
    """A .gltf is one self-contained file: two in a folder do not overwrite each other."""
    import trimesh

    model = BodyModel()
    a, b = np.asarray(model.neutral_pose()).copy(), np.asarray(model.neutral_pose()).copy()
    b[0] += 1.0
    export.save_mesh(tmp_path / "a.gltf", model, a)
    export.save_mesh(tmp_path / "b.gltf", model, b)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.gltf", "b.gltf"]
    xa = trimesh.load(tmp_path / "a.gltf", force="mesh").bounds.mean(0)[0]
    xb = trimesh.load(tmp_path / "b.gltf", force="mesh").bounds.mean(0)[0]
    assert abs(xb - xa - 1.0) < 1e-3


def test_mesh_export_bad_input(tmp_path):
    model = BodyModel()
    pose = np.asarray(model.neutral_pose())
    with pytest.raises(dp.DepthPoseError, match="mesh format"):
        export.save_mesh(tmp_path / "body.xyz", model, pose)
    with pytest.raises(dp.InvalidTypeError, match="y_up"):
        export.save_mesh(tmp_path / "body.ply", model, pose, y_up="yes")


def test_export_comes_with_the_package():
    import subprocess
    import sys

    code = "import depthpose; print(depthpose.export.write_bvh.__name__)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.strip() == "write_bvh", out.stderr


def test_jsonl(tmp_path):
    class Result:  # what write_jsonl reads of a PoseResult (native, not constructible)
        def to_dict(self):
            return {"pose": [0.0] * 22, "joints": np.ones((15, 3)).tolist(), "energy": 1.5}

    export.write_jsonl(tmp_path / "r.jsonl", [Result(), None])
    lines = (tmp_path / "r.jsonl").read_text().splitlines()
    assert json.loads(lines[0])["joints"][0] == [1.0, 1.0, 1.0]
    assert json.loads(lines[1])["joints"] is None


def test_jsonl_lines_are_what_json_dumps_writes(tmp_path):
    fields = {"pose": [0.1, 1e-5, float("nan"), -0.0], "name": 'é"x\n', "ok": True,
              "none": None, "n": 3, "big": 1e300, "nested": {"a": [1, 2.5]}}  # fmt: skip

    class Result:
        def to_dict(self):
            return fields

    export.write_jsonl(tmp_path / "r.jsonl", [Result(), None, Result()])
    want = [json.dumps({"frame": 0, **fields}), json.dumps({"frame": 1, "joints": None}),
            json.dumps({"frame": 2, **fields})]  # fmt: skip
    assert (tmp_path / "r.jsonl").read_text().splitlines() == want
    with pytest.raises(dp.InvalidTypeError, match=r"results\[1\]"):
        export.write_jsonl(tmp_path / "x.jsonl", [None, object()])
    assert not (tmp_path / "x.jsonl").exists()
