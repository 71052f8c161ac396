"""The scripts in ``examples/`` run as documented and give the right answers."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from types import ModuleType

import depthpose as dp
import numpy as np
import pytest
import trimesh
from depthpose import synth
from PIL import Image
from test_stereo_pipeline import BASELINE, make_pair

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def example(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def walk() -> dict[str, np.ndarray]:
    return synth.make_sequence(motion="walk", frames=10, seed=3)


def test_every_example_is_tested() -> None:
    tested = {"track_depth_folder", "stereo_pair_to_pose", "export_to_blender"}
    assert {p.stem for p in EXAMPLES.glob("*.py")} == tested


def test_track_depth_folder_tracks_every_frame_and_skips_a_bad_file(
    tmp_path: Path, walk: dict[str, np.ndarray], capsys: pytest.CaptureFixture[str]
) -> None:
    for k, depth in enumerate(walk["depth"]):
        dp.write_depth(tmp_path / f"depth_{k:03d}.png", depth.astype(np.float32) / 1000)
    (tmp_path / "depth_999.png").write_bytes(b"not a png")
    rc = example("track_depth_folder").main([str(tmp_path), "--camera", "itop"])
    out, err = capsys.readouterr()
    assert rc == 0
    lines = [line for line in out.splitlines() if line.startswith("frame")]
    assert len(lines) == len(walk["depth"])
    assert "depth_999.png: skipped" in err and "10/11 frames tracked" in err
    # The printed head is the true head within 10 cm (the synthetic joints are exact).
    head = walk["joints"][-1][0]
    printed = np.array(json.loads(lines[-1].split("head ")[1].split(" hands")[0]))
    assert np.linalg.norm(printed - head) < 0.1


def test_stereo_pair_to_pose_prints_the_joints(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    left, right, _, joints, camera, _ = make_pair()
    Image.fromarray(left).save(tmp_path / "left.png")
    Image.fromarray(right).save(tmp_path / "right.png")
    picture = tmp_path / "pose.png"
    argv = [str(tmp_path / "left.png"), str(tmp_path / "right.png"), "--intrinsics",
            *(repr(v) for v in camera.intrinsics), "--baseline", repr(BASELINE),
            "--picture", str(picture)]  # fmt: skip
    assert example("stereo_pair_to_pose").main(argv) == 0
    out = capsys.readouterr().out
    rows = [line.split() for line in out.splitlines() if " confidence " in line]
    assert [r[0] for r in rows] == dp.BodyModel().joint_names
    got = np.array([[float(r[2]), float(r[4]), float(r[6])] for r in rows])
    assert np.linalg.norm(got - joints, axis=1).max() < 0.1
    assert Image.open(picture).size == (camera.width, camera.height)


def test_export_to_blender_writes_files_that_open(
    tmp_path: Path, walk: dict[str, np.ndarray]
) -> None:
    bvhio = pytest.importorskip("bvhio")
    seq = tmp_path / "walk.npz"
    synth.save(seq, walk)
    out = tmp_path / "export"
    assert example("export_to_blender").main([str(seq), "--out", str(out)]) == 0
    root = bvhio.readAsHierarchy(str(out / "motion.bvh"))
    assert root.Name == "Hips"
    mesh = trimesh.load(out / "body.glb", force="mesh")
    # y up: the head end of the body is the top of the mesh.
    assert mesh.vertices[:, 1].max() > mesh.vertices[:, 1].min() + 1.4
    saved = np.load(out / "joints.npz")
    assert saved["joints"].shape == (len(walk["depth"]), 15, 3)
    assert np.nanmean(np.linalg.norm(saved["joints"] - walk["joints"], axis=2)) < 0.1
