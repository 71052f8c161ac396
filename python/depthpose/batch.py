"""Whole recordings and corpora on a Dask cluster, with nothing lost.

Each sequence is split into chunks of frames. A chunk is one Dask task: it tracks through
its frames, starting ``overlap`` frames early so that the track is re-established before
the first frame it reports (those warm-up frames are computed twice, the price of
independent chunks: with the defaults 4 of every 32 frames, 12 % extra work). Each chunk's
result is written atomically (temporary name, then rename) under ``OUT/.chunks/``; a rerun
skips the chunks whose files exist and verify, so an interrupted run loses at most the
chunks in flight. A worker that dies has its tasks rescheduled by Dask on the others. A
frame that fails is recorded as NaN with its error in ``OUT/NAME.log.jsonl``; the rest of
the sequence still finishes. Finally the chunks are merged per sequence into
``OUT/NAME.npz`` in the layout of ``depthpose estimate``.

Dask is an optional extra: ``pip install 'depthpose[distributed]'``.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from collections.abc import Sequence as Seq
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ._core import DepthPoseError, InvalidInputError, read_npz, write_npz
from .sequence import expand_inputs, open_sequence

if TYPE_CHECKING:
    from .templates import TemplateDatabase

__all__ = ["run", "plan_chunks", "BatchSummary", "process_chunk"]

#: Version of the chunk file layout; chunks of another version are recomputed.
CHUNK_FORMAT = 1
JOINTS = 15
PARAMS = 22


@dataclass
class BatchSummary:
    """What a batch run did."""

    sequences: int = 0
    frames: int = 0
    failed_frames: int = 0
    failed_sequences: list[str] = field(default_factory=list)
    chunks_total: int = 0
    chunks_computed: int = 0
    chunks_skipped: int = 0
    seconds: float = 0.0
    accuracy: dict[str, dict[str, float]] = field(default_factory=dict)

    @property
    def frames_per_second(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else float("nan")

    def report(self) -> str:
        lines = [
            f"sequences {self.sequences}, frames {self.frames}, failed frames "
            f"{self.failed_frames}, chunks {self.chunks_computed} computed / "
            f"{self.chunks_skipped} reused of {self.chunks_total}",
            f"time {self.seconds:.1f} s, {self.frames_per_second:.1f} frames/s",
        ]
        for name in self.failed_sequences:
            lines.append(f"FAILED sequence {name} (see its .log.jsonl)")
        for name, acc in self.accuracy.items():
            lines.append(
                f"{name}: MPJPE {acc['mpjpe_mm']:.1f} mm, PCK@10cm {100 * acc['pck']:.1f} %"
            )
        return "\n".join(lines)


def plan_chunks(n_frames: int, chunk_frames: int) -> list[tuple[int, int]]:
    """[start, stop) ranges covering ``n_frames`` in chunks of ``chunk_frames``."""
    if chunk_frames < 1:
        raise InvalidInputError(f"chunk_frames: must be >= 1, got {chunk_frames}")
    return [(s, min(s + chunk_frames, n_frames)) for s in range(0, n_frames, chunk_frames)]


def _chunk_file(out_dir: Path, name: str, start: int, stop: int) -> Path:
    return out_dir / ".chunks" / name / f"{start:07d}-{stop:07d}.npz"


def _chunk_ok(path: Path, start: int, stop: int) -> bool:
    """A chunk file exists, is complete and covers [start, stop)."""
    if not path.exists():
        return False
    try:
        d = read_npz(path, "a chunk file")
        n = stop - start
        return (
            int(d["format"]) == CHUNK_FORMAT
            and int(d["start"]) == start
            and int(d["stop"]) == stop
            and d["joints"].shape == (n, JOINTS, 3)
            and d["pose"].shape == (n, PARAMS)
            and d["confidence"].shape == (n, JOINTS)
        )
    except Exception:  # truncated or corrupt: recompute
        return False


@lru_cache(maxsize=4)
def _templates(path: str | None) -> TemplateDatabase | None:
    """The template database, loaded once per worker process."""
    if path is None:
        return None
    from .templates import TemplateDatabase

    return TemplateDatabase.load(path)


def process_chunk(spec: dict[str, Any]) -> dict[str, Any]:
    """One Dask task: track frames [start, stop) of a sequence and write the chunk file."""
    from .pipeline import estimate_frames

    t0 = time.perf_counter()
    seq = open_sequence(
        spec["path"], intrinsics=spec.get("intrinsics"), depth_scale=spec["depth_scale"]
    )
    start, stop, overlap = spec["start"], spec["stop"], spec["overlap"]
    lo = max(0, start - overlap) if spec["track"] else start
    frames = seq.frames(lo, stop)
    res = estimate_frames(
        frames,
        seq.camera,
        background=seq.background,
        track=spec["track"],
        templates=_templates(spec.get("templates")),
        warmup=start - lo,
        first_frame=lo,
    )
    out = Path(spec["out"])
    out.parent.mkdir(parents=True, exist_ok=True)
    write_npz(
        out,
        format=np.int64(CHUNK_FORMAT),
        start=np.int64(start),
        stop=np.int64(stop),
        joints=res.joints,
        pose=res.pose,
        confidence=res.confidence,
        errors=np.array(json.dumps(res.errors)),
    )
    return {
        "name": seq.name,
        "start": start,
        "stop": stop,
        "failed": len(res.errors),
        "seconds": time.perf_counter() - t0,
    }


def _merge(
    out_dir: Path,
    name: str,
    n_frames: int,
    ranges: list[tuple[int, int]],
    failed_chunks: dict[tuple[int, int], str],
) -> tuple[np.ndarray, list[dict[str, Any]]]:
    joints = np.full((n_frames, JOINTS, 3), np.nan)
    pose = np.full((n_frames, PARAMS), np.nan)
    conf = np.zeros((n_frames, JOINTS))
    errors: list[dict[str, Any]] = []
    for start, stop in ranges:
        path = _chunk_file(out_dir, name, start, stop)
        if (start, stop) in failed_chunks or not _chunk_ok(path, start, stop):
            msg = failed_chunks.get((start, stop), "chunk result missing")
            errors += [{"frame": f, "error": msg} for f in range(start, stop)]
            continue
        d = read_npz(path, "a chunk file")
        joints[start:stop] = d["joints"]
        pose[start:stop] = d["pose"]
        conf[start:stop] = d["confidence"]
        errors += json.loads(str(d["errors"]))
    from .pipeline import JOINT_NAMES

    write_npz(
        out_dir / f"{name}.npz",
        joints=joints,
        pose=pose,
        confidence=conf,
        joint_names=np.array(JOINT_NAMES),
    )
    log = out_dir / f"{name}.log.jsonl"
    tmp = log.with_name(f".{log.name}.tmp")
    tmp.write_text("".join(json.dumps(e) + "\n" for e in sorted(errors, key=lambda e: e["frame"])))
    os.replace(tmp, log)
    return joints, errors


class _Progress:
    """A progress bar over frames on stderr (tqdm; none when not a terminal)."""

    def __init__(self, total: int, enabled: bool) -> None:
        from ._progress import progress_bar

        self.bar = progress_bar(total, "frames", enabled=enabled and total > 0)

    def add(self, n: int) -> None:
        self.bar.update(n)
        if self.bar.n >= (self.bar.total or 0):
            self.bar.close()


def run(
    inputs: Seq[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    *,
    client: Any = None,
    scheduler: str | None = None,
    n_workers: int | None = None,
    chunk_frames: int = 32,
    overlap: int = 4,
    track: bool = True,
    intrinsics: Seq[float] | None = None,
    camera: Any = None,
    depth_scale: float = 0.001,
    templates: str | os.PathLike[str] | None = None,
    progress: bool = True,
    on_chunk_done: Callable[[dict[str, Any]], None] | None = None,
) -> BatchSummary:
    """Estimates poses for every frame of every input on a Dask cluster.

    ``client``: a ``distributed.Client`` to use; else ``scheduler`` (``tcp://host:port``)
    to connect to; else a local cluster of ``n_workers`` processes (one per core) on
    loopback. ``templates``: a saved template database shared by all workers (default:
    the cached default database, built once here if needed). ``camera``: a ``Camera``
    (or a function of the frames' shape (H, W) returning one) instead of ``intrinsics``,
    as :func:`depthpose.sequence.open_sequence` takes it. ``depth_scale``: metres per
    integer unit.
    """
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError as e:  # pragma: no cover - depends on the extra
        raise DepthPoseError(
            "depthpose batch needs Dask: pip install 'depthpose[distributed]'"
        ) from e
    if overlap < 0:
        raise InvalidInputError(f"overlap: must be >= 0, got {overlap}")
    t0 = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = BatchSummary()
    seqs = []
    for p in expand_inputs([os.fspath(i) for i in inputs]):
        try:
            seqs.append(
                open_sequence(p, intrinsics=intrinsics, depth_scale=depth_scale, camera=camera)
            )
        except DepthPoseError as e:
            name = p.stem if p.suffix else p.name
            summary.failed_sequences.append(name)
            (out / f"{name}.log.jsonl").write_text(
                json.dumps({"frame": None, "error": str(e)}) + "\n"
            )
    summary.sequences = len(seqs) + len(summary.failed_sequences)
    if templates is None:
        from .templates import TemplateDatabase

        # Build (or load) the cached default once here; workers load it from its file.
        TemplateDatabase.default(progress=progress)
        templates = TemplateDatabase.default_path()
    else:
        from .templates import TemplateDatabase

        # A missing or corrupt file fails here, once, with its own error, not in every
        # worker's task.
        TemplateDatabase.load(templates)
    specs: list[dict[str, Any]] = []
    plans: dict[str, list[tuple[int, int]]] = {}
    for seq in seqs:
        plans[seq.name] = plan_chunks(seq.n_frames, chunk_frames)
        for start, stop in plans[seq.name]:
            summary.chunks_total += 1
            path = _chunk_file(out, seq.name, start, stop)
            if _chunk_ok(path, start, stop):
                summary.chunks_skipped += 1
                continue
            specs.append(
                dict(
                    path=os.fspath(seq.path),
                    start=start,
                    stop=stop,
                    overlap=overlap,
                    track=track,
                    intrinsics=(
                        list(seq.camera.intrinsics)
                        if camera is not None
                        else None
                        if intrinsics is None
                        else list(intrinsics)
                    ),
                    depth_scale=depth_scale,
                    templates=os.fspath(templates),
                    out=os.fspath(path),
                )
            )
    bar = _Progress(sum(s["stop"] - s["start"] for s in specs), progress)
    failed_chunks: dict[str, dict[tuple[int, int], str]] = {s.name: {} for s in seqs}
    own_cluster = None
    if specs:
        if client is None:
            if scheduler:
                client = Client(scheduler)  # type: ignore[no-untyped-call]
            else:
                own_cluster = LocalCluster(  # type: ignore[no-untyped-call]
                    n_workers=n_workers or os.cpu_count() or 1,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    dashboard_address=None,
                )
                client = Client(own_cluster)  # type: ignore[no-untyped-call]
        try:
            futures = [
                client.submit(
                    process_chunk,
                    s,
                    key=f"depthpose-chunk-{k}-{time.time_ns()}",
                    retries=2,
                    pure=False,
                )
                for k, s in enumerate(specs)
            ]
            by_key = {f.key: s for f, s in zip(futures, specs, strict=False)}
            for fut in as_completed(futures):  # type: ignore[no-untyped-call]
                spec = by_key[fut.key]
                try:
                    info = fut.result()
                    summary.chunks_computed += 1
                    if on_chunk_done is not None:
                        on_chunk_done(info)
                except Exception as e:  # the chunk failed even after retries
                    name = Path(spec["out"]).parent.name
                    failed_chunks[name][(spec["start"], spec["stop"])] = f"{type(e).__name__}: {e}"
                bar.add(spec["stop"] - spec["start"])
        finally:
            if own_cluster is not None:
                client.close()
                own_cluster.close()
    from .metrics import evaluate

    for seq in seqs:
        joints, errors = _merge(
            out, seq.name, seq.n_frames, plans[seq.name], failed_chunks[seq.name]
        )
        summary.frames += seq.n_frames
        summary.failed_frames += len(errors)
        if seq.gt_joints is not None and seq.gt_joints.shape == joints.shape:
            summary.accuracy[seq.name] = evaluate(joints, seq.gt_joints)
    summary.seconds = time.perf_counter() - t0
    return summary
