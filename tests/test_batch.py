"""Batch runs on a real local Dask cluster (loopback): same joints as estimate, a killed
worker loses nothing, a rerun recomputes only missing chunks, failures are recorded."""

from __future__ import annotations

import json
import os
import signal

import depthpose as dp
import numpy as np
import pytest
from depthpose import batch, synth

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("seqs")
    paths = []
    for k, motion in enumerate(["wave", "walk"]):
        seq = synth.make_sequence(motion=motion, frames=12, seed=k)
        p = d / f"{motion}.npz"
        synth.save(p, seq)
        paths.append(p)
    dp.TemplateDatabase.default(progress=False)  # built once, shared through its file
    return paths


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
        dashboard_address=None,
    )  # fmt: skip
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def test_batch_matches_estimate_and_resumes(tmp_path, inputs, client):
    out = tmp_path / "out"
    s = batch.run(inputs, out, client=client, chunk_frames=4, overlap=2, progress=False)
    assert s.chunks_computed == 6 and s.failed_frames == 0, s.report()
    from depthpose.pipeline import estimate_frames
    from depthpose.sequence import open_sequence

    seq = open_sequence(inputs[0])
    ref = estimate_frames(seq.frames(), seq.camera, background=seq.background)
    got = np.load(out / "wave.npz")["joints"]
    err = np.linalg.norm(got - ref.joints, axis=-1)
    assert np.median(err) < 0.02, np.median(err)  # chunk boundaries aside
    # Interrupt and resume: remove two chunk files (as if in flight); only they rerun.
    chunks = sorted((out / ".chunks" / "walk").glob("*.npz"))
    for c in chunks[:2]:
        c.unlink()
    (out / ".chunks" / "walk" / ".junk.npz.123.tmp").write_bytes(b"half written")
    s2 = batch.run(inputs, out, client=client, chunk_frames=4, overlap=2, progress=False)
    assert s2.chunks_computed == 2 and s2.chunks_skipped == 4, s2.report()
    np.testing.assert_allclose(np.load(out / "wave.npz")["joints"], got)


def test_killed_worker_loses_no_frame(tmp_path, inputs, client):
    pids = list(client.run(os.getpid).values())
    killed = []

    def kill_one(info):
        if not killed:
            killed.append(pids[0])
            os.kill(pids[0], signal.SIGKILL)

    out = tmp_path / "out"
    s = batch.run(inputs, out, client=client, chunk_frames=3, overlap=1, progress=False,
                  on_chunk_done=kill_one)  # fmt: skip
    assert killed
    assert s.failed_frames == 0, s.report()
    for p in inputs:
        assert np.isfinite(np.load(out / f"{p.stem}.npz")["joints"]).all()


def test_corrupt_input_and_nan_frame_are_recorded(tmp_path, inputs, client):
    bad = tmp_path / "corrupt.npz"
    bad.write_bytes(b"PK\x03\x04 this is not a zip")
    seq = synth.make_sequence(motion="wave", frames=6, seed=5)
    seq["depth"][2] = 0  # a frame with no reading
    nanseq = tmp_path / "holes.npz"
    synth.save(nanseq, seq)
    out = tmp_path / "out"
    s = batch.run([bad, nanseq, inputs[0]], out, client=client, chunk_frames=3, progress=False)
    assert s.failed_sequences == ["corrupt"]
    assert s.failed_frames == 1
    j = np.load(out / "holes.npz")["joints"]
    assert np.isnan(j[2]).all() and np.isfinite(j[[0, 1, 3, 4, 5]]).all()
    log = [json.loads(x) for x in (out / "holes.log.jsonl").read_text().splitlines()]
    assert log[0]["frame"] == 2 and "NoBody" in log[0]["error"]
    assert np.isfinite(np.load(out / "wave.npz")["joints"]).all()


def test_batch_takes_a_camera_preset(tmp_path, inputs, client):
    """A folder of frames with a camera preset instead of intrinsics, through the CLI's
    --camera; the preset reaches every worker."""
    from depthpose.cli import main
    from depthpose.sequence import open_sequence

    seq = open_sequence(inputs[0])
    folder = tmp_path / "frames"
    folder.mkdir()
    for k, d in enumerate(seq.frames(0, 4)):
        dp.write_depth(folder / f"f{k:03d}.png", d)
    s = batch.run([folder], tmp_path / "out", client=client, chunk_frames=2, overlap=1,
                  camera=dp.Camera.preset("itop"), progress=False)  # fmt: skip
    assert s.failed_frames == 0 and not s.failed_sequences, s.report()
    assert np.isfinite(np.load(tmp_path / "out" / "frames.npz")["joints"]).all()
    with pytest.raises(SystemExit):
        main(["batch", str(folder), "--out", str(tmp_path / "o"), "--camera", "nope"])
