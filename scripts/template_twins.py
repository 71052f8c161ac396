#!/usr/bin/env python3
"""Templates whose depth images cannot be told apart: the ceiling of top-1 retrieval.

Renders every template pose of the default database with the ellipsoid body model
(ITOP camera, every 3rd pixel), and joins two templates when their depth images differ
by less than ``--tolerance`` (default 2 mm) in mean absolute depth over the union of
their silhouettes (a pixel inside one silhouette only counts 0.2 m). Prints the groups
of indistinguishable templates and the best expected top-1 rate of *any* method that
sees only the depth image, when each query is a render of one template and ties are
broken by chance: one pick per group, so (number of groups) / (number of templates).

    python scripts/template_twins.py [--tolerance 0.002]
"""

from __future__ import annotations

import argparse
from collections import Counter

import depthpose as dp
import numpy as np
from depthpose.templates import VIEWS

#: Depth difference (m) counted for a pixel inside one silhouette only.
MISMATCH = 0.2
#: Every STEP-th pixel of every STEP-th row is compared.
STEP = 3


def renders(db: dp.TemplateDatabase) -> tuple[np.ndarray, np.ndarray]:
    poses = np.asarray(db.poses)
    cam, model = dp.Camera.itop(), dp.BodyModel()
    images = []
    for p in poses:
        depth, _ = model.render_depth(p, cam)
        d = np.asarray(depth)[::STEP, ::STEP]
        images.append(np.where(np.isfinite(d) & (d > 0), d, 0.0).ravel())
    x = np.asarray(images, np.float32)
    return x, x > 0


def groups(x: np.ndarray, fg: np.ndarray, tolerance: float) -> list[int]:
    """Union-find roots of the templates joined by the tolerance."""
    n = len(x)
    parent = list(range(n))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for i in range(n):
        union = fg[i] | fg
        diff = np.where(fg[i] & fg, np.abs(x[i] - x), MISMATCH)
        mean = np.where(union, diff, 0.0).sum(1) / np.maximum(union.sum(1), 1)
        for j in np.nonzero(mean < tolerance)[0]:
            parent[find(i)] = find(int(j))
    return [find(i) for i in range(n)]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--tolerance", type=float, default=0.002, help="mean |dz| (m)")
    args = p.parse_args(argv)
    db = dp.TemplateDatabase.default(progress=False)
    x, fg = renders(db)
    roots = groups(x, fg, args.tolerance)
    sizes = Counter(roots)
    n = len(roots)
    print(f"{n} templates, {len(sizes)} groups within {args.tolerance * 1000:.1f} mm")
    print("group sizes:", dict(sorted(Counter(sizes.values()).items())))
    views = db.views
    for v, name in enumerate(VIEWS):
        paired = sum(1 for i in range(n) if views[i] == v and sizes[roots[i]] > 1)
        print(f"  {name}: {paired} in a group of 2 or more")
    print(f"top-1 ceiling for any depth-only method: {len(sizes) / n:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
