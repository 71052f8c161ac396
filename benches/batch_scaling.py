"""Scaling of ``depthpose.batch`` on a Dask cluster, against ``depthpose estimate``.

Runs, on the same input (the shared synthetic sequences, or sequences made by
``depthpose.synth`` when ../shared/data is absent):

* ``estimate``: :func:`depthpose.pipeline.estimate_frames` in this process, one sequence
  after the other (what ``depthpose estimate`` does);
* ``batch`` on local clusters of 1 process × 1 thread, 2 processes × 1 thread and
  1 process × 2 threads (native work releases the GIL), each timed from submission to the
  merged results, with the cluster's start-up timed separately;
* Dask's bare per-task latency (a task that does nothing), for scale.

The per-task overhead of the cluster is the 1-worker batch time minus the work its tasks
did (their own timing of the chunk), divided by the number of tasks. Scaling efficiency is
the 2-worker speed-up divided by 2. Usage: ``python benches/batch_scaling.py [--frames N]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

import depthpose
import numpy as np
from depthpose import batch, synth
from depthpose.pipeline import estimate_frames
from depthpose.sequence import open_sequence
from depthpose.templates import TemplateDatabase

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "synth"


def inputs(frames: int | None, tmp: Path) -> list[Path]:
    """The shared sequences (cut to ``frames`` each), else two built-in ones."""
    paths = sorted(SHARED.glob("*.npz")) if SHARED.is_dir() else []
    if not paths:
        for motion in ("walk", "wave"):
            seq = synth.make_sequence(motion=motion, frames=frames or 40)
            synth.save(tmp / f"synth_{motion}.npz", seq)
        return sorted(tmp.glob("synth_*.npz"))
    if frames is None:
        return paths
    out = []
    for p in paths:
        with np.load(p, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
        n = min(frames, data["depth"].shape[0])
        for k in ("depth", "mask", "joints"):
            if k in data:
                data[k] = data[k][:n]
        np.savez(tmp / p.name, **data)
        out.append(tmp / p.name)
    return out


def time_estimate(paths: list[Path]) -> tuple[float, int]:
    t0 = time.perf_counter()
    n = 0
    for p in paths:
        seq = open_sequence(p)
        res = estimate_frames(seq.frames(0, seq.n_frames), seq.camera, background=seq.background)
        n += res.joints.shape[0]
    return time.perf_counter() - t0, n


def noop(x: int) -> int:
    return x


def time_batch(paths: list[Path], workers: int, threads: int, chunk: int) -> dict[str, float]:
    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    cluster = LocalCluster(
        n_workers=workers,
        threads_per_worker=threads,
        processes=True,
        host="127.0.0.1",
        dashboard_address=None,
    )
    client = Client(cluster)
    client.run(lambda: __import__("depthpose"))  # import on every worker before timing
    startup = time.perf_counter() - t0
    try:
        # Bare task latency: 200 tasks that do nothing.
        t1 = time.perf_counter()
        client.gather(client.map(noop, range(200), pure=False))
        latency = (time.perf_counter() - t1) / 200
        task_seconds: list[float] = []
        with tempfile.TemporaryDirectory() as out:
            t2 = time.perf_counter()
            summary = batch.run(
                paths,
                out,
                client=client,
                chunk_frames=chunk,
                progress=False,
                on_chunk_done=lambda info: task_seconds.append(info["seconds"]),
            )
            wall = time.perf_counter() - t2
    finally:
        client.close()
        cluster.close()
    tasks = len(task_seconds)
    return {
        "startup": startup,
        "wall": wall,
        "frames": summary.frames,
        "failed": summary.failed_frames,
        "tasks": tasks,
        "task_work": sum(task_seconds),
        "task_median": statistics.median(task_seconds) if task_seconds else float("nan"),
        "latency": latency,
        "pck": float(np.mean([a["pck"] for a in summary.accuracy.values()]))
        if summary.accuracy
        else float("nan"),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=None, help="frames per sequence (default all)")
    ap.add_argument("--chunk", type=int, default=32, help="frames per chunk (default 32)")
    args = ap.parse_args()
    TemplateDatabase.default(progress=False)  # built once, outside every timing
    with tempfile.TemporaryDirectory() as tmp:
        paths = inputs(args.frames, Path(tmp))
        est_s, n = time_estimate(paths)
        print(f"depthpose {depthpose.__version__}, {os.cpu_count()} cores, load {os.getloadavg()}")
        print(f"input: {len(paths)} sequences, {n} frames, chunks of {args.chunk} frames")
        print(f"estimate (in process): {est_s:.1f} s, {n / est_s:.1f} frames/s")
        rows = {}
        for workers, threads in ((1, 1), (2, 1), (1, 2)):
            r = time_batch(paths, workers, threads, args.chunk)
            rows[(workers, threads)] = r
            print(
                f"batch {workers} proc x {threads} thr: {r['wall']:.1f} s "
                f"({r['frames'] / r['wall']:.1f} frames/s, {r['tasks']} tasks, "
                f"failed {r['failed']}, mean PCK {r['pck']:.3f}), cluster start "
                f"{r['startup']:.1f} s, bare task latency {1e3 * r['latency']:.1f} ms"
            )
        one, two, thr = rows[(1, 1)], rows[(2, 1)], rows[(1, 2)]
        overhead = (one["wall"] - one["task_work"]) / max(one["tasks"], 1)
        print()
        print("| measure | value |")
        print("|---|---|")
        print(f"| estimate, frames/s | {n / est_s:.1f} |")
        for key, r in rows.items():
            fps = r["frames"] / r["wall"]
            print(f"| batch {key[0]} proc × {key[1]} thread, frames/s | {fps:.1f} |")
        print(f"| speed-up 2 workers vs 1 | {one['wall'] / two['wall']:.2f}× |")
        print(f"| scaling efficiency (2 workers) | {100 * one['wall'] / two['wall'] / 2:.0f} % |")
        print(f"| speed-up 2 threads in 1 worker vs 1 | {one['wall'] / thr['wall']:.2f}× |")
        print(f"| 1-worker batch / estimate time | {one['wall'] / est_s:.2f} |")
        print(
            f"| per-task overhead (1 worker, outside the task's work) | {1e3 * overhead:.0f} ms |"
        )
        extra = one["task_work"] / est_s - 1
        print(f"| work inside the tasks vs estimate (overlap warm-up) | {extra:+.0%} |")
        print(f"| bare Dask task latency | {1e3 * one['latency']:.1f} ms |")
        print(f"| local cluster start-up (1 worker) | {one['startup']:.1f} s |")
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"| client peak RSS | {rss:.0f} MB |")
    sys.exit(0)


if __name__ == "__main__":
    main()
