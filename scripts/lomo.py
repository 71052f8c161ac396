#!/usr/bin/env python3
"""Leave-one-motion-out check of the pipeline's settings on the shared synthetic corpus.

Every setting in a grid of ``PipelineConfig`` variants is evaluated on the whole corpus
with ``scripts/eval_pipeline.py`` (tracked and from scratch; each variant's results are
cached as JSON). Then, for each motion (the sequences sharing a mocap source), the
variant with the best score on the *other* motions is chosen and the left-out motion is
scored with it. The left-out scores, over every sequence, are what the settings are
worth on motions they were not chosen on; the in-sample scores of the default settings
stand beside them. A large gap means the settings fit the corpus rather than people.

The score of a variant on a set of sequences is the mean over those sequences of the
mean of the tracked and the from-scratch PCK@10cm.

The default grid moves the pipeline's tuned thresholds and weights one at a time, to a
lower and a higher value: the lost-track ratio and margin, the tracking prior, the pose
prior, the hypothesis switch margin, the CRF's Potts weight, and the range of body sizes
searched from scratch.

Usage::

    python scripts/lomo.py [--cache DIR] [--grid FILE.json] [--json-out FILE]
        [-- eval_pipeline options, e.g. --step 4]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import eval_pipeline  # noqa: E402

#: One-at-a-time variants around the defaults: (name, PipelineConfig fields).
DEFAULT_GRID: list[tuple[str, dict]] = [
    ("default", {}),
    ("lost_ratio=1.3", {"lost_ratio": 1.3}),
    ("lost_ratio=2.0", {"lost_ratio": 2.0}),
    ("lost_discrepancy=0.35", {"lost_discrepancy": 0.35}),
    ("lost_discrepancy=0.7", {"lost_discrepancy": 0.7}),
    ("prior_weight=30", {"prior_weight": 30.0}),
    ("prior_weight=300", {"prior_weight": 300.0}),
    ("pose_prior_weight=0.002", {"pose_prior_weight": 0.002}),
    ("pose_prior_weight=0.0125", {"pose_prior_weight": 0.0125}),
    ("switch_margin=0.05", {"switch_margin": 0.05}),
    ("switch_margin=0.2", {"switch_margin": 0.2}),
    ("potts=0.15", {"fit": {"potts": 0.15}}),
    ("potts=0.6", {"fit": {"potts": 0.6}}),
    ("size_range=0", {"size_range": 0.0}),
    ("size_range=0.25", {"size_range": 0.25}),
]


def motion_of(path: Path) -> str:
    """The mocap source of a sequence (its meta's ``motion_source``) without folders."""
    meta = json.loads(str(np.load(path)["meta"]))
    return Path(meta["motion_source"]).stem


def evaluate(name: str, fields: dict, cache: Path, extra: list[str]) -> dict:
    """eval_pipeline's summary of one variant, from the cache or run now."""
    out = cache / f"{name}.json"
    if not out.exists():
        print(f"evaluating {name} ...", file=sys.stderr, flush=True)
        argv = ["--config", json.dumps(fields), "--json-out", str(out), *extra]
        with contextlib.redirect_stdout(io.StringIO()):
            rc = eval_pipeline.main(argv)
        if rc != 0:
            raise SystemExit(f"eval_pipeline failed on {name} (exit {rc})")
    return json.loads(out.read_text())


def scores(summary: dict) -> dict[str, dict[str, float]]:
    """Per sequence: tracked PCK, from-scratch PCK and their mean."""
    out = {}
    for seq, r in summary["sequences"].items():
        track, scratch = r["track"]["pck"], r["scratch"]["pck"]
        out[seq] = {"track": track, "scratch": scratch, "both": (track + scratch) / 2}
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=eval_pipeline.DEFAULT_DATA)
    ap.add_argument("--cache", type=Path, default=Path("lomo-cache"))
    ap.add_argument("--grid", type=Path, help='JSON list of ["name", {fields}] variants')
    ap.add_argument("--json-out", type=Path)
    ap.add_argument("extra", nargs="*", help="options passed to eval_pipeline.py")
    args = ap.parse_args()
    grid = [tuple(v) for v in json.loads(args.grid.read_text())] if args.grid else DEFAULT_GRID
    args.cache.mkdir(parents=True, exist_ok=True)
    extra = ["--data", str(args.data), *args.extra]
    results = {name: scores(evaluate(name, fields, args.cache, extra)) for name, fields in grid}
    sequences = sorted(results["default"])
    motions = {s: motion_of(args.data / f"{s}.npz") for s in sequences}

    rows, left_out = [], {}
    for motion in sorted(set(motions.values())):
        held = [s for s in sequences if motions[s] == motion]
        rest = [s for s in sequences if motions[s] != motion]
        chosen = max(grid, key=lambda v: np.mean([results[v[0]][s]["both"] for s in rest]))[0]
        for s in held:
            left_out[s] = {**results[chosen][s], "chosen": chosen}
        rows.append((motion, chosen, held))

    print("| motion | chosen on the other motions | sequence | tracked PCK (default) | "
          "scratch PCK (default) |")  # fmt: skip
    print("|---|---|---|---|---|")
    for motion, chosen, held in rows:
        for s in held:
            d, lo = results["default"][s], left_out[s]
            print(f"| {motion} | {chosen} | {s} | {lo['track']:.3f} ({d['track']:.3f}) | "
                  f"{lo['scratch']:.3f} ({d['scratch']:.3f}) |")  # fmt: skip
    summary: dict = {"grid": [name for name, _ in grid], "sequences": left_out}
    print()
    for mode in ("track", "scratch"):
        lo = {s: left_out[s][mode] for s in sequences}
        d = {s: results["default"][s][mode] for s in sequences}
        best = max(grid, key=lambda v: np.mean([results[v[0]][s][mode] for s in sequences]))[0]
        b = {s: results[best][s][mode] for s in sequences}
        worst = min(lo, key=lo.__getitem__)
        print(f"{mode}: leave-one-motion-out mean {np.mean(list(lo.values())):.3f}, worst "
              f"{lo[worst]:.3f} ({worst}); default settings in-sample "
              f"{np.mean(list(d.values())):.3f}, worst {min(d.values()):.3f}; best variant "
              f"in-sample {best} {np.mean(list(b.values())):.3f}")  # fmt: skip
        summary[mode] = {
            "lomo_mean": float(np.mean(list(lo.values()))),
            "lomo_worst": [worst, lo[worst]],
            "default_mean": float(np.mean(list(d.values()))),
            "default_worst": float(min(d.values())),
            "best_in_sample": [best, float(np.mean(list(b.values())))],
        }
    if args.json_out:
        args.json_out.write_text(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
