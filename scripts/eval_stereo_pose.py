#!/usr/bin/env python3
"""Pose from stereo pairs on the shared rendered sequences (../shared/data/stereo_person),
with and without the empty-scene pair, tracked and each pair from scratch.

For each sequence and mode it prints PCK@10cm and MPJPE of the joints, the density and
bad-2 of the disparity on the person's pixels (the matcher's output, and what is left
after the fattening removal that the fit sees), and the median time per pair; then the
mean and the worst sequence of each mode. With OpenCV installed (the ``bench`` extra)
it also runs StereoSGBM (64 disparities, block 5, 3-way) on the same pairs, prints its
density and bad-2 on the person's pixels, and the ratio of stereo + tracked pose to
SGBM's matching alone, frame by frame.

Usage::

    python scripts/eval_stereo_pose.py [--data DIR] [--json-out F] [--disparity-sigma PX]
        [--weigh-points] [--config JSON]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import depthpose as dp
import numpy as np
from depthpose import stereo

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "stereo_person"
MODES = ("tracked, background", "tracked", "scratch, background", "scratch")


def disparity_scores(disparity: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> tuple:
    got, want = disparity[mask], truth[mask]
    matched = np.isfinite(got)
    bad = float(np.mean(np.abs(got - want)[matched] > 2)) if matched.any() else float("nan")
    return float(matched.mean()), bad


def sgbm(left: np.ndarray, right: np.ndarray) -> tuple[float, np.ndarray] | None:
    """SGBM's matching time (ms) and disparity (NaN unmatched), or None without OpenCV."""
    try:
        import cv2
    except ImportError:
        return None
    matcher = cv2.StereoSGBM_create(
        0, 64, 5, P1=8 * 25, P2=32 * 25, uniquenessRatio=10, mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY
    )
    t = time.perf_counter()
    fixed = matcher.compute(left, right)
    ms = 1000 * (time.perf_counter() - t)
    disparity = fixed.astype(np.float32) / 16  # 4 fractional bits
    disparity[fixed < 0] = np.nan
    return ms, disparity


def run(
    path: Path,
    mode: str,
    templates: dp.TemplateDatabase,
    noise: dict,
    config: dp.PipelineConfig,
) -> dict:
    data = np.load(path)
    fx, fy, cx, cy = data["intrinsics"]
    h, w = data["left"].shape[1:]
    camera = dp.Camera(fx, fy, cx, cy, w, h)
    background = (data["left_bg"], data["right_bg"]) if "background" in mode else None
    cls = dp.StereoPoseTracker if mode.startswith("tracked") else dp.StereoPoseEstimator
    pipeline = cls(
        camera,
        float(data["baseline"]),
        background=background,
        templates=templates,
        config=config,
        **noise,
    )
    errors, ms, ratios, kept, raw, peer = [], [], [], [], [], []
    for k in range(len(data["left"])):
        left, right = data["left"][k], data["right"][k]
        t = time.perf_counter()
        try:
            res = pipeline.update(left, right)
            errors.append(np.linalg.norm(res.joints - data["joints"][k], axis=1))
        except dp.DepthPoseError:
            errors.append(np.full(15, np.inf))
        ms.append(1000 * (time.perf_counter() - t))
        assert pipeline.disparity is not None
        kept.append(disparity_scores(pipeline.disparity, data["disparity"][k], data["mask"][k]))
        if mode == MODES[0]:
            matched = stereo.match(left, right)
            raw.append(disparity_scores(matched, data["disparity"][k], data["mask"][k]))
            reference = sgbm(left, right)
            if reference is not None:
                peer.append(disparity_scores(reference[1], data["disparity"][k], data["mask"][k]))
                if k > 0:
                    ratios.append(ms[-1] / reference[0])
    e = np.array(errors)
    out = {
        "pck": float(np.mean(e < 0.10)),
        "mpjpe_mm": float(1000 * np.mean(e[np.isfinite(e)])) if np.isfinite(e).any() else None,
        "failed_frames": int(np.sum(~np.isfinite(e).all(axis=1))),
        "density": float(np.mean([d for d, _ in kept])),
        "bad2": float(np.mean([b for _, b in kept])),
        "ms_median": float(np.median(ms)),
    }
    if raw:
        out["matcher_density"] = float(np.mean([d for d, _ in raw]))
        out["matcher_bad2"] = float(np.mean([b for _, b in raw]))
    if peer:
        out["sgbm_density"] = float(np.mean([d for d, _ in peer]))
        out["sgbm_bad2"] = float(np.mean([b for _, b in peer]))
    if ratios:
        out["ratio_to_sgbm_median"] = float(np.median(ratios))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--json-out", type=Path)
    ap.add_argument(
        "--disparity-sigma",
        type=float,
        default=0.25,
        help="the matcher's disparity error (px): the lost test allows for it (default 0.25)",
    )
    ap.add_argument(
        "--weigh-points", action="store_true", help="the fit weighs points by their depth noise"
    )
    ap.add_argument("--config", default=None, help="PipelineConfig fields as JSON")
    args = ap.parse_args()
    config = dp.PipelineConfig(**json.loads(args.config)) if args.config else dp.PipelineConfig()
    paths = sorted(args.data.glob("*.npz"))
    if not paths:
        raise SystemExit(f"no sequences in {args.data}")
    templates = dp.TemplateDatabase.default()
    table: dict[str, dict[str, dict]] = {}
    print("| sequence | mode | PCK@10cm | MPJPE mm | density | bad-2 | ms/pair |")
    print("|---|---|---|---|---|---|---|")
    for path in paths:
        for mode in MODES:
            noise = {"disparity_sigma": args.disparity_sigma, "weigh_points": args.weigh_points}
            r = run(path, mode, templates, noise, config)
            table.setdefault(path.stem, {})[mode] = r
            mpjpe = "—" if r["mpjpe_mm"] is None else f"{r['mpjpe_mm']:.0f}"
            print(
                f"| {path.stem} | {mode} | {r['pck']:.3f} | {mpjpe} | {r['density']:.3f} | "
                f"{100 * r['bad2']:.2f} % | {r['ms_median']:.0f} |",
                flush=True,
            )
    print()
    for mode in MODES:
        pck = {s: table[s][mode]["pck"] for s in table}
        worst = min(pck, key=pck.__getitem__)
        mean = np.mean(list(pck.values()))
        print(f"{mode}: PCK mean {mean:.3f}, worst {pck[worst]:.3f} ({worst})")
    first = [table[s][MODES[0]] for s in table]
    print(
        "matcher on person pixels: density "
        f"{np.mean([r['matcher_density'] for r in first]):.3f}, bad-2 "
        f"{100 * np.mean([r['matcher_bad2'] for r in first]):.2f} %"
    )
    if all("sgbm_bad2" in r for r in first):
        print(
            "SGBM on person pixels: density "
            f"{np.mean([r['sgbm_density'] for r in first]):.3f}, bad-2 "
            f"{100 * np.mean([r['sgbm_bad2'] for r in first]):.2f} %"
        )
    ratios = [r["ratio_to_sgbm_median"] for r in first if "ratio_to_sgbm_median" in r]
    if ratios:
        print(f"stereo + tracked pose / SGBM matching alone: median {np.median(ratios):.2f}x")
    else:
        print("OpenCV not installed: no SGBM comparison (pip install opencv-python-headless)")
    if args.json_out:
        args.json_out.write_text(json.dumps(table, indent=1))


if __name__ == "__main__":
    main()
