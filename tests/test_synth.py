"""Synthetic sequences of the body model."""

import json

import numpy as np
import pytest
from depthpose import synth
from depthpose._core import BodyModel, Camera, InvalidInputError


@pytest.mark.parametrize("motion", sorted(synth.MOTIONS))
def test_keys_shapes_dtypes_and_joints_in_mask(motion):
    seq = synth.make_sequence(motion, frames=6, seed=3, distance=3.5)
    assert seq["depth"].shape == (6, 240, 320) and seq["depth"].dtype == np.uint16
    assert seq["background"].shape == (240, 320) and seq["background"].dtype == np.uint16
    assert seq["mask"].shape == (6, 240, 320) and seq["mask"].dtype == bool
    assert seq["joints"].shape == (6, 15, 3) and seq["joints"].dtype == np.float32
    assert seq["labels"].shape == (6, 240, 320) and seq["labels"].dtype == np.int16
    assert list(seq["joint_names"])[:2] == ["Head", "Neck"]
    meta = json.loads(str(seq["meta"]))
    assert meta["motion"] == motion and meta["seed"] == 3
    fx, fy, cx, cy = seq["intrinsics"]
    j = seq["joints"].astype(float)
    u = np.round(fx * j[..., 0] / j[..., 2] + cx).astype(int)
    v = np.round(fy * j[..., 1] / j[..., 2] + cy).astype(int)
    inside = (u >= 0) & (u < 320) & (v >= 0) & (v < 240)
    assert inside.all()
    t = np.arange(6)[:, None].repeat(15, 1)
    # Every joint lies inside its body, so it projects onto the silhouette (1 px slack).
    m = seq["mask"]
    near = np.zeros_like(inside)
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            near |= m[t, np.clip(v + dv, 0, 239), np.clip(u + du, 0, 319)]
    assert near.mean() > 0.97
    # Person pixels: mostly read, with depth close to the clean render.
    d = seq["depth"].astype(float) / 1000
    read = m & (d > 0)
    assert read.sum() / m.sum() > 0.9
    assert m.sum(axis=(1, 2)).min() > 1000
    # Background pixels show floor/wall behind the person.
    assert np.median(seq["background"][seq["background"] > 0]) / 1000 > 3.0


def test_deterministic_and_noise_free_option():
    a = synth.make_sequence("walk", frames=3, seed=7)
    b = synth.make_sequence("walk", frames=3, seed=7)
    c = synth.make_sequence("walk", frames=3, seed=8)
    assert np.array_equal(a["depth"], b["depth"]) and not np.array_equal(a["depth"], c["depth"])
    clean = synth.make_sequence("walk", frames=3, noise=0.0)
    # Without noise the person's depth is the exact render (mm rounding).
    assert np.all(clean["depth"][clean["mask"]] > 0)


def test_noise_statistics_follow_the_sensor_model():
    clean = synth.make_sequence("arm_raise", frames=2, noise=0.0, seed=1)
    noisy = synth.make_sequence("arm_raise", frames=2, noise=1.0, seed=1)
    m = clean["mask"] & (noisy["depth"] > 0)
    diff = (noisy["depth"][m].astype(float) - clean["depth"][m]) / 1000
    z = clean["depth"][m] / 1000
    # At ~3 m: sigma(3) = 1.2 + 1.9*2.6^2 = 14 mm, quantisation step ~19 mm.
    assert 0.005 < np.std(diff) < 0.03
    assert abs(np.median(diff)) < 0.01
    assert np.all(z > 2) and np.all(z < 4)
    # Some person and edge pixels lost (dropouts, shadow), but not many.
    lost = 1 - m.sum() / clean["mask"].sum()
    assert 0.003 < lost < 0.1


def test_the_clean_person_is_the_render_of_its_pose():
    seq = synth.make_sequence("walk", frames=2, noise=0.0, view_deg=20, seed=0)
    fx, fy, cx, cy = seq["intrinsics"]
    cam = Camera(fx, fy, cx, cy, 320, 240)
    model = BodyModel(1.75)
    for f in range(2):
        depth, labels = model.render_depth(seq["poses"][f], cam)
        m = seq["mask"][f]
        np.testing.assert_array_equal(seq["labels"][f][m], labels[m])
        assert np.abs(seq["depth"][f][m] / 1000 - depth[m]).max() < 0.0006
        np.testing.assert_allclose(seq["joints"][f], model.joints(seq["poses"][f]), atol=1e-6)
    # Motions are periodic in their phase.
    np.testing.assert_array_equal(synth.motion_pose("wave", 1.25), synth.motion_pose("wave", 0.25))


def test_turn_and_view_rotate_the_body():
    side = synth.make_sequence("wave", frames=1, view_deg=90, noise=0)
    j = side["joints"][0]
    # Left side toward the camera: the left shoulder is nearer than the right.
    assert j[3, 2] < j[2, 2] - 0.2


def test_save_load_roundtrip(tmp_path):
    seq = synth.make_sequence("squat", frames=2, camera=Camera.itop().scaled(0.5))
    p = tmp_path / "s.npz"
    synth.save(p, seq)
    back = synth.load(p)
    assert back["depth"].shape == (2, 120, 160)
    for k in seq:
        assert np.array_equal(back[k], seq[k])


def test_bad_arguments():
    with pytest.raises(InvalidInputError, match="motion"):
        synth.make_sequence("moonwalk")
    with pytest.raises(InvalidInputError, match="distance"):
        synth.make_sequence(distance=-1.0)
    with pytest.raises(InvalidInputError, match="frames"):
        synth.make_sequence(frames=0)
    with pytest.raises(InvalidInputError, match="wall_distance"):
        synth.make_sequence(distance=3.0, wall_distance=3.2)
    with pytest.raises(InvalidInputError, match="motion"):
        synth.motion_pose("moonwalk", 0.0)
