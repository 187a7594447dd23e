#!/usr/bin/env python3
"""Made-up blade faces for judging the search on more than the four NASA faces.

A speed change that alters what `decompose` finds must be judged on coverage curves, and the
search is chaotic: a tolerance 1% off moves a blade's final coverage by up to 3 points. Four
real faces cannot tell a lever that costs coverage from one that is noise; these add a family
of smooth free-form faces like a compressor blade's, none of them an exact envelope, each
fixed by its seed (NumPy's PCG64, so the same bytes on every machine with the same NumPy).

A face: span v in [0, H] along z, chord u in [0, 1] across. The section is a cambered line
(a parabola skewed by a cubic term, its height a fraction of the chord that changes along
the span), the chord shrinks toward the tip,
and the section turns about z by a twist that grows non-linearly with the span (a ruled or
developable face it is not), with lean and sweep of the stacking line. Sizes in mm, about
those of tests/data's faces.

Usage: freeform_parts.py SEED OUT.stl [--rows N] [--cols N]   (prints the parameters)
"""

import argparse
import struct
import sys

import numpy as np


def parameters(seed):
    """The face's shape parameters, drawn from the seed."""
    g = np.random.Generator(np.random.PCG64(seed))
    return {
        "chord": float(g.uniform(40.0, 80.0)),
        "span": float(g.uniform(60.0, 120.0)),
        "camber": float(g.uniform(0.08, 0.22)),        # of the chord, at the hub
        "camber_tip": float(g.uniform(-0.6, 0.6)),     # relative change toward the tip
        "skew": float(g.uniform(-0.9, 0.9)),           # the camber's peak fore or aft
        "taper": float(g.uniform(0.0, 0.35)),          # the chord at the tip, less
        "twist": float(np.radians(g.uniform(20.0, 60.0))),
        "twist_bend": float(np.radians(g.uniform(-15.0, 15.0))),  # quadratic part
        "lean": float(g.uniform(-0.15, 0.15)),         # of the span, at the tip
        "sweep": float(g.uniform(-0.15, 0.15)),
    }


def blade(seed, rows=161, cols=121):
    """(V, F): the face of `seed` as rows × cols vertices (rows along the span) and their
    triangles, two a cell, consistently oriented."""
    p = parameters(seed)
    v = np.linspace(0.0, 1.0, rows)[:, None]    # span fraction
    u = np.linspace(0.0, 1.0, cols)[None, :]    # chord fraction
    chord = p["chord"] * (1.0 - p["taper"] * v)
    x = (u - 0.5) * chord
    camber = p["camber"] * (1.0 + p["camber_tip"] * v)
    y = 4.0 * camber * chord * u * (1.0 - u) * (1.0 + p["skew"] * (u - 0.5))
    angle = p["twist"] * v + p["twist_bend"] * v * v
    c, s = np.cos(angle), np.sin(angle)
    X = c * x - s * y + p["lean"] * p["span"] * v * v
    Y = s * x + c * y + p["sweep"] * p["span"] * v * v
    Z = p["span"] * v * np.ones_like(u)
    V = np.stack([X, Y, Z], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    a = (i * cols + j).ravel()
    b, d, e = a + 1, a + cols, a + cols + 1
    F = np.concatenate([np.stack([a, b, e], 1), np.stack([a, e, d], 1)])
    return V, F


def write_stl(path, V, F):
    """Binary STL (facet normals from the corners)."""
    tri = V[F]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    rec = np.zeros(len(F), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["n"], rec["v"] = n, tri
    with open(path, "wb") as f:
        f.write(b"flank freeform_parts".ljust(80, b" "))
        f.write(struct.pack("<I", len(F)))
        f.write(rec.tobytes())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seed", type=int)
    ap.add_argument("out")
    ap.add_argument("--rows", type=int, default=161)
    ap.add_argument("--cols", type=int, default=121)
    a = ap.parse_args(argv)
    if a.rows < 2 or a.cols < 2:
        ap.error("--rows and --cols need at least 2")
    write_stl(a.out, *blade(a.seed, a.rows, a.cols))
    print(" ".join(f"{k} {v:.4g}" for k, v in parameters(a.seed).items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
