"""Camera presets (API and CLI) and the command line's arguments: --help everywhere,
templates build/info, --glob and skipped files, --depth-scale in units per metre, the
body shape in the output, progress only on a terminal."""

from __future__ import annotations

import re

import depthpose as dp
import numpy as np
import pytest
from depthpose import io as dpio
from depthpose import synth
from depthpose.cli import main

PRESETS = {  # name: (width, height, fx)
    "kinect-v1": (640, 480, 580.0),
    "kinect-v1-qvga": (320, 240, 290.0),
    "kinect-v2": (512, 424, 365.4),
    "azure-kinect": (640, 576, 504.0),
    "realsense-d435": (640, 480, 384.2),
    "itop": (320, 240, 285.71),
}


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_camera_preset(name):
    cam = dp.Camera.preset(name)
    width, height, fx = PRESETS[name]
    assert (cam.width, cam.height) == (width, height)
    assert cam.fx == pytest.approx(fx) and cam.fy == pytest.approx(fx)
    assert 0.4 * width < cam.cx < 0.6 * width and 0.4 * height < cam.cy < 0.6 * height
    assert dp.Camera.preset(name.upper().replace("-", "_")) == cam


def test_camera_presets_and_bad_names():
    assert sorted(dp.Camera.presets()) == sorted(PRESETS)
    assert dp.Camera.preset("itop") == dp.Camera.itop()
    assert dp.Camera.preset("kinect-v1") == dp.Camera.kinect_v1()
    with pytest.raises(dp.InvalidInputError, match="^name: .*kinect-v3.*azure-kinect"):
        dp.Camera.preset("kinect-v3")
    with pytest.raises(dp.InvalidTypeError, match="name"):
        dp.Camera.preset(3)


@pytest.fixture(scope="module")
def frames():
    seq = synth.make_sequence(motion="wave", frames=10, seed=7)
    dp.TemplateDatabase.default(progress=False)
    return seq


def _folder(path, depth, scale=0.001):
    path.mkdir()
    for k, d in enumerate(depth):
        dpio.write_depth(path / f"f{k:03d}.png", d, scale=scale)
    return path


def test_every_command_answers_help(capsys):
    commands = ("demo", "estimate", "estimate-stereo", "batch", "stereo", "templates")
    for command in (*commands, "foreground"):
        with pytest.raises(SystemExit) as e:
            main([command, "--help"])
        assert e.value.code == 0, command
        assert f"usage: depthpose {command}" in capsys.readouterr().out
    with pytest.raises(SystemExit) as e:
        main(["templates", "info", "--out", "x.npz"])
    assert e.value.code == 2


def test_templates_info_reads_a_file(tmp_path, capsys):
    assert main(["templates", "info", str(tmp_path / "none.npz")]) == 2
    assert "none.npz" in capsys.readouterr().err


def test_estimate_with_a_camera_preset(tmp_path, frames, capsys):
    depth = frames["depth"][:2].astype(np.float32) / 1000
    folder = _folder(tmp_path / "f", depth)
    by_name = tmp_path / "name.npz"
    rc = main(["estimate", str(folder), "--out", str(by_name), "--camera", "itop", "--no-track"])
    assert rc == 0
    intr = [str(v) for v in dp.Camera.itop().intrinsics]
    by_numbers = tmp_path / "numbers.npz"
    rc = main(["estimate", str(folder), "--out", str(by_numbers), "--intrinsics", *intr,
               "--no-track"])  # fmt: skip
    assert rc == 0
    np.testing.assert_allclose(np.load(by_name)["joints"], np.load(by_numbers)["joints"])
    # 320x240 frames are half a Kinect v1's: the preset is resampled to them.
    rc = main(["estimate", str(folder), "--out", str(tmp_path / "k.npz"),
               "--camera", "kinect-v1", "--no-track"])  # fmt: skip
    assert rc == 0
    capsys.readouterr()
    rc = main(["estimate", str(folder), "--out", str(tmp_path / "a.npz"),
               "--camera", "azure-kinect"])  # fmt: skip
    assert rc == 2 and "--camera azure-kinect" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["estimate", str(folder), "--out", str(tmp_path / "a.npz"), "--camera", "nope"])


def test_estimate_takes_pipeline_settings(tmp_path, frames, capsys):
    path = tmp_path / "seq.npz"
    n = len(frames["depth"])
    synth.save(path, {k: v[:2] if np.ndim(v) and len(v) == n else v for k, v in frames.items()})
    outs = {}
    for name, extra in (("default", []), ("coarse", ["--config", '{"working_focal": 150}'])):
        outs[name] = tmp_path / f"{name}.npz"
        assert main(["estimate", str(path), "--out", str(outs[name]), "--no-track", *extra]) == 0
    # A coarser working resolution gives other joints: the setting reached the pipeline.
    assert not np.allclose(np.load(outs["default"])["joints"], np.load(outs["coarse"])["joints"])
    # With --learn-background the two merge.
    out = str(tmp_path / "learn.npz")
    config = ["--config", '{"candidates": 6}', "--learn-background"]
    assert main(["estimate", str(path), "--out", out, *config]) == 0
    capsys.readouterr()
    bad = {
        "{bad": "not valid JSON",
        "[1]": "expected a JSON object",
        '{"foo": 1}': "foo: not a PipelineConfig setting",
        '{"candidates": "x"}': "candidates: expected an integer",
    }
    for text, message in bad.items():
        assert main(["estimate", str(path), "--out", out, "--config", text]) == 2
        assert f"--config: {message}" in capsys.readouterr().err, text


def test_foreground_with_a_camera_preset(tmp_path, frames):
    depth = frames["depth"][:1].astype(np.float32) / 1000
    folder = _folder(tmp_path / "f", depth)
    out = tmp_path / "fg"
    assert main(["foreground", str(folder / "f000.png"), "--out", str(out), "--camera",
                 "itop"]) == 0  # fmt: skip
    assert (out / "f000_foreground.png").exists()


def test_estimate_glob_and_skipped_files(tmp_path, frames, capsys):
    depth = frames["depth"][:2].astype(np.float32) / 1000
    folder = _folder(tmp_path / "f", depth)
    dp.viz.save_png(folder / "a_thumbnail.png", np.zeros((40, 60, 3), np.uint8))
    dpio.write_depth(folder / "b_small.png", depth[0][::4, ::4].copy())  # another size
    (folder / "notes.npy").write_bytes(b"not numpy")
    out = tmp_path / "all.npz"
    rc = main(["estimate", str(folder), "--out", str(out), "--camera", "itop"])
    err = capsys.readouterr().err
    assert rc == 1  # some frames failed, the others are estimated
    pred = np.load(out)
    assert list(pred["failed_frames"]) == [0, 1, 4]
    assert "a_thumbnail.png" in err and "b_small.png" in err and "notes.npy" in err
    assert np.isfinite(pred["joints"][[2, 3]]).all()
    out = tmp_path / "glob.npz"
    rc = main(["estimate", str(folder), "--out", str(out), "--camera", "itop", "--glob", "f*.png"])
    assert rc == 0 and np.load(out)["joints"].shape == (2, 15, 3)
    rc = main(["estimate", str(folder), "--out", str(out), "--camera", "itop", "--glob", "*.tif"])
    assert rc == 2 and "*.tif" in capsys.readouterr().err


def test_depth_scale_counts_units_per_metre(tmp_path, frames, capsys):
    depth = frames["depth"][:1].astype(np.float32) / 1000
    mm = _folder(tmp_path / "mm", depth)
    tenth = _folder(tmp_path / "tenth", depth, scale=0.0001)  # 0.1 mm units
    assert dpio.read_depth(tenth / "f000.png", scale=0.0001).max() == pytest.approx(
        depth.max(), abs=1e-4
    )
    outs = []
    for folder, args in ((mm, []), (mm, ["--depth-scale", "1000"]),
                         (tenth, ["--depth-scale", "10000"])):  # fmt: skip
        out = tmp_path / f"{folder.name}{len(args)}.npz"
        assert main(["estimate", str(folder), "--out", str(out), "--camera", "itop",
                     "--no-track", *args]) == 0  # fmt: skip
        outs.append(np.load(out)["joints"])
    np.testing.assert_allclose(outs[1], outs[0])
    np.testing.assert_allclose(outs[2], outs[0], atol=0.01)
    capsys.readouterr()
    # The metres-per-unit value of other tools is refused with a hint.
    rc = main(["estimate", str(mm), "--out", str(tmp_path / "x.npz"), "--camera", "itop",
               "--depth-scale", "0.001"])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 2 and "--depth-scale" in err and "1000 for millimetres" in err


def test_estimate_saves_the_body_shape(tmp_path, frames, capsys):
    """The output's pose and shape give its joints back: after the tracker's shape
    calibration (frame 8 on) as before it."""
    path = tmp_path / "seq.npz"
    synth.save(path, frames)
    out = tmp_path / "pred.npz"
    assert main(["estimate", str(path), "--out", str(out)]) == 0
    pred = np.load(out)
    shape, pose, joints = pred["shape"], pred["pose"], pred["joints"]
    assert shape.shape[0] == 10 and np.isfinite(shape).all()
    assert not np.allclose(shape[-1], dp.BodyModel().shape)  # calibrated by the end
    for k in range(10):
        model = dp.BodyModel()
        model.shape = shape[k]
        np.testing.assert_allclose(model.joints(pose[k]), joints[k], atol=1e-3)
    # Progress is drawn on a terminal only: pytest's stderr is not one. The frame that
    # calibrated the shape is reported whatever stderr is.
    err = capsys.readouterr().err
    assert "100%" not in err
    assert re.search(r"^frame 8: body shape calibrated in \d+ ms$", err, re.M), err
