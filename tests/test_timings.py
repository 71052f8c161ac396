"""A result's timings['total'] covers the whole call: the template search included."""

from __future__ import annotations

import time

import depthpose as dp
import numpy as np
from depthpose import synth


def test_total_covers_the_template_search():
    seq = synth.make_sequence(motion="wave", frames=3, seed=1)
    camera = dp.Camera(*(float(v) for v in seq["intrinsics"]), 320, 240)
    estimator = dp.PoseEstimator(camera)
    tracker = dp.PoseTracker(camera, config=dp.PipelineConfig(recheck_every=1))
    for k, step in ((0, estimator.estimate), (0, tracker.update), (1, tracker.update)):
        t0 = time.perf_counter()
        r = step(seq["depth"][k].astype(np.float32) / 1000)
        wall = 1e3 * (time.perf_counter() - t0)
        stages = {name: ms for name, ms in r.timings.items() if name != "total"}
        assert "templates" in stages or "search" in stages, stages
        assert sum(stages.values()) <= r.timings["total"] + 1e-6
        assert r.timings["total"] <= wall
