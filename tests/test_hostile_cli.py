"""The command line works frame by frame: a corrupt, truncated, missing-data or
different-size frame is reported (which, why), every other frame is estimated and
written, and the exit code says how it went (0 all, 1 some failed, 2 none could)."""

from __future__ import annotations

import json

import depthpose as dp
import numpy as np
import pytest
from depthpose import io as dpio
from depthpose import synth
from depthpose.cli import main


@pytest.fixture(scope="module")
def frames():
    seq = synth.make_sequence(motion="wave", frames=4, seed=7)
    fx, fy, cx, cy = (float(v) for v in seq["intrinsics"])
    depth = seq["depth"].astype(np.float32) / 1000
    # The templates are loaded once for the module (the CLI's estimator shares them).
    dp.TemplateDatabase.default(progress=False)
    return depth, [str(v) for v in (fx, fy, cx, cy)]


def _folder(tmp_path, depth, faults: dict[int, str]):
    """A folder of PNG frames, frame k spoiled as ``faults[k]`` says."""
    folder = tmp_path / "frames"
    folder.mkdir()
    for k, d in enumerate(depth):
        path = folder / f"f{k:03d}.png"
        dpio.write_depth(path, d)
        fault = faults.get(k)
        if fault == "corrupt":
            data = bytearray(path.read_bytes())
            data[60:200] = bytes(140)
            path.write_bytes(bytes(data))
        elif fault == "truncated":
            path.write_bytes(path.read_bytes()[:300])
        elif fault == "size":
            dpio.write_depth(path, d[::2, ::2].copy())
        elif fault == "empty":
            dpio.write_depth(path, np.zeros_like(d))
        elif fault == "junk":
            path.write_bytes(b"not a png")
    return folder


def _run(tmp_path, folder, intr, capsys, *extra):
    out = tmp_path / "pred.npz"
    jsonl = tmp_path / "pred.jsonl"
    rc = main(["estimate", str(folder), "--out", str(out), "--jsonl", str(jsonl),
               "--intrinsics", *intr, *extra])  # fmt: skip
    err = capsys.readouterr().err
    lines = [json.loads(line) for line in jsonl.read_text().splitlines()]
    return rc, err, np.load(out), lines


@pytest.mark.parametrize("fault", ["corrupt", "truncated", "size", "empty", "junk"])
def test_estimate_reports_a_bad_frame_and_finishes_the_others(tmp_path, frames, capsys, fault):
    depth, intr = frames
    folder = _folder(tmp_path, depth, {2: fault})
    rc, err, pred, lines = _run(tmp_path, folder, intr, capsys)
    assert rc == 1
    assert "frame 2 (" in err and "f002.png" in err  # which frame, and why
    assert list(pred["failed_frames"]) == [2] and len(pred["errors"]) == 1
    assert np.isnan(pred["joints"][2]).all()
    assert np.isfinite(pred["joints"][[0, 1, 3]]).all()
    assert [line["frame"] for line in lines] == [0, 1, 2, 3]
    assert lines[2]["joints"] is None and lines[2]["error"]
    assert all(line["joints"] is not None for k, line in enumerate(lines) if k != 2)


def test_a_bad_first_frame_does_not_stop_the_sequence(tmp_path, frames, capsys):
    depth, intr = frames
    folder = _folder(tmp_path, depth, {0: "truncated", 3: "size"})
    rc, err, pred, _ = _run(tmp_path, folder, intr, capsys, "--no-track")
    assert rc == 1 and list(pred["failed_frames"]) == [0, 3]
    assert np.isfinite(pred["joints"][[1, 2]]).all()


def test_all_frames_good_exits_0_and_none_exits_2(tmp_path, frames, capsys):
    depth, intr = frames
    folder = _folder(tmp_path, depth[:2], {})
    rc, _, pred, _ = _run(tmp_path, folder, intr, capsys)
    assert rc == 0 and len(pred["failed_frames"]) == 0
    bad = tmp_path / "bad"
    bad.mkdir()
    folder = _folder(bad, depth[:2], {0: "empty", 1: "empty"})
    rc, err, pred, _ = _run(bad, folder, intr, capsys)
    assert rc == 2 and list(pred["failed_frames"]) == [0, 1] and "NoBodyError" in err
    # A folder none of whose frames can be read cannot even be opened.
    worse = tmp_path / "worse"
    worse.mkdir()
    folder = _folder(worse, depth[:2], {0: "junk", 1: "truncated"})
    rc = main(["estimate", str(folder), "--out", str(worse / "p.npz"), "--intrinsics", *intr])
    assert rc == 2 and "none of its 2 depth frames" in capsys.readouterr().err


def test_bad_arguments_exit_2_with_a_message(tmp_path, frames, capsys):
    depth, intr = frames
    folder = _folder(tmp_path, depth[:1], {})
    for args in (["--depth-scale", "1e9"], ["--depth-scale", "0"]):
        rc = main(["estimate", str(folder), "--out", str(tmp_path / "p.npz"),
                   "--intrinsics", *intr, *args])  # fmt: skip
        assert rc == 2 and "--depth-scale" in capsys.readouterr().err
    rc = main(["estimate", str(tmp_path / "nowhere"), "--out", str(tmp_path / "p.npz")])
    assert rc == 2 and "no such file" in capsys.readouterr().err


def test_foreground_goes_image_by_image(tmp_path, frames, capsys):
    depth, _ = frames
    folder = _folder(tmp_path, depth, {1: "corrupt", 2: "size"})
    inputs = sorted(str(p) for p in folder.iterdir())
    out = tmp_path / "fg"
    background = tmp_path / "bg.png"
    dpio.write_depth(background, np.full_like(depth[0], 4.0))
    rc = main(["foreground", *inputs, str(tmp_path / "missing.png"), "--out", str(out),
               "--background", str(background)])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 1
    assert "f001.png" in err and "f002.png" in err and "missing.png" in err
    assert sorted(p.name for p in out.iterdir()) == ["f000_foreground.png", "f003_foreground.png"]
    rc = main(["foreground", str(tmp_path / "missing.png"), "--out", str(out)])
    assert rc == 2
