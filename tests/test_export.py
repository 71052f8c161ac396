"""Exports: BVH that recomposes to the fitted segment rotations, meshes, JSON lines."""

from __future__ import annotations

import json

import depthpose as dp
import numpy as np
import pytest
from depthpose import export

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
    assert sorted(names) == sorted(model.part_names)
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
            local = export._rot("z", z) @ export._rot("x", x) @ export._rot("y", y)
            world[name] = local if parent is None else world[parent] @ local
            want = flip @ frames[list(model.part_names).index(name), :3, :3] @ flip
            np.testing.assert_allclose(world[name], want, atol=1e-5, err_msg=name)
        np.testing.assert_allclose(motion[f, :3], flip @ frames[3, :3, 3], atol=1e-5)


def test_bvh_bad_input(tmp_path):
    model = BodyModel()
    with pytest.raises(dp.DepthPoseError, match="poses"):
        export.write_bvh(tmp_path / "x.bvh", model, np.zeros((3, 5)))
    with pytest.raises(dp.DepthPoseError, match="NaN"):
        export.write_bvh(tmp_path / "x.bvh", model, np.full((3, 22), np.nan))


def test_mesh_export_round_trip(tmp_path):
    import trimesh

    model = BodyModel()
    pose = np.asarray(model.neutral_pose())
    for suffix in ("ply", "glb"):
        path = tmp_path / f"body.{suffix}"
        export.save_mesh(path, model, pose)
        mesh = trimesh.load(path, force="mesh")
        assert len(mesh.vertices) > 1000
        height = mesh.bounds[1, 1] - mesh.bounds[0, 1]
        assert 1.5 < height < 1.95, height
    with pytest.raises(dp.DepthPoseError, match="mesh format"):
        export.save_mesh(tmp_path / "body.xyz", model, pose)


def test_jsonl(tmp_path):
    class Result:  # what write_jsonl reads of a PoseResult (native, not constructible)
        def to_dict(self):
            return {"pose": [0.0] * 22, "joints": np.ones((15, 3)).tolist(), "energy": 1.5}

    export.write_jsonl(tmp_path / "r.jsonl", [Result(), None])
    lines = (tmp_path / "r.jsonl").read_text().splitlines()
    assert json.loads(lines[0])["joints"][0] == [1.0, 1.0, 1.0]
    assert json.loads(lines[1])["joints"] is None
