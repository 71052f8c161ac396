#!/usr/bin/env python3
"""How good is the template search alone as an initial pose? PCK@10cm of the placed
template's joints (no EM) on the shared synthetic sequences.

For every frame of every sequence (``../shared/data/synth/*.npz`` by default) the
default template database is matched against the depth with the ground-truth mask
(``TemplateDatabase.match``, ``top_k`` candidates), and the joints of each candidate,
placed at the observed body (``Candidate.joints``), are scored against the ``joints``
key with the definitions of ``shared/tools/eval_pose.py`` (``depthpose.metrics``).
Prints per sequence the PCK of the best-ranked candidate and of the best of the top-k
(the candidate with the most joints within 10 cm, per frame).

    python scripts/template_pck.py [--data DIR] [--top-k 5]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import depthpose as dp
import numpy as np
from depthpose.metrics import evaluate
from depthpose.sequence import open_sequence

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "data" / "synth"


def sequence_pck(path: Path, db: dp.TemplateDatabase, top_k: int) -> tuple[int, float, float]:
    """(frames, PCK of the top-1 candidate, PCK of the best of the top-k)."""
    seq = open_sequence(path)
    with np.load(path) as d:
        masks = d["mask"]
    top1, best = [], []
    for frame, mask, gt in zip(seq.frames(), masks, seq.gt_joints, strict=True):
        cands = db.match(frame, seq.camera, mask=mask, top_k=top_k)
        joints = [np.asarray(c.joints, np.float64) for c in cands]
        hits = [(np.linalg.norm(j - gt, axis=1) <= 0.10).sum() for j in joints]
        top1.append(joints[0])
        best.append(joints[int(np.argmax(hits))])
    return (
        seq.n_frames,
        evaluate(np.asarray(top1), seq.gt_joints)["pck"],
        evaluate(np.asarray(best), seq.gt_joints)["pck"],
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder of sequence .npz")
    ap.add_argument("--top-k", type=int, default=5, help="candidates per frame")
    args = ap.parse_args(argv)
    paths = sorted(args.data.glob("*.npz"))
    if not paths:
        print(f"no sequences in {args.data}")
        return 1
    db = dp.TemplateDatabase.default(progress=False)
    rows, n_all, sums = [], 0, np.zeros(2)
    for p in paths:
        n, p1, pk = sequence_pck(p, db, args.top_k)
        rows.append((p.stem, p1, pk))
        n_all += n
        sums += n * np.array([p1, pk])
    print(f"| sequence | PCK@10cm top-1 | best of top-{args.top_k} |")
    print("|---|---|---|")
    for name, p1, pk in rows:
        print(f"| {name} | {p1:.3f} | {pk:.3f} |")
    print(f"| all ({n_all} frames) | **{sums[0] / n_all:.3f}** | {sums[1] / n_all:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
