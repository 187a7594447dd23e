#!/usr/bin/env python3
"""Self-tests of tests/check_patches.py against analytic ground truth.

Every case is built here (a mesh file and a patches.json in a temporary folder) with a
known answer: a cylinder or cone rolling over a plane machines exactly that plane, so the
envelope, the signed error, its sign and the coverage are known in closed form.

Run: /usr/bin/python3 tests/check_patches_test.py      (exit status non-zero on failure)
"""

import io
import json
import os
import struct
import subprocess
import sys
import tempfile
import unittest
from contextlib import redirect_stdout

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SCRIPT = os.path.join(HERE, "check_patches.py")
sys.path.insert(0, HERE)
import check_patches as cp  # noqa: E402

# A small grid keeps the suite fast; 121 rows put an Omega row exactly on x = 0 and x = X
# for the standard sweep below (x from -2 to X + 2 in 120 steps of 0.2).
ROWS, COLS = 121, 41
TOL = 0.01


# ---------------------------------------------------------------------------------------
# Builders
# ---------------------------------------------------------------------------------------

def plane(x0, x1, y0, y1, nx, ny, z=0.0):
    """Regular grid of the rectangle at height z, triangles counter-clockwise seen from +z
    (normals +z, so tools live above)."""
    xs, ys = np.linspace(x0, x1, nx), np.linspace(y0, y1, ny)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    V = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], axis=1)
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="ij")
    v00 = (i * ny + j).ravel()
    v10, v01, v11 = v00 + ny, v00 + 1, v00 + ny + 1
    F = np.concatenate([np.stack([v00, v10, v11], 1), np.stack([v00, v11, v01], 1)])
    return V, F


def clamped_knots(K):
    inner = np.linspace(0.0, 1.0, K - 2)
    return np.concatenate([[0.0] * 3, inner, [1.0] * 3])


def linear_controls(p0, p1, knots):
    """Control points at the Greville abscissae: the cubic B-spline is then exactly
    p0 + t (p1 - p0), linear in t."""
    K = len(knots) - 4
    xi = np.array([knots[i + 1:i + 4].mean() for i in range(K)])
    return np.asarray(p0, float)[None, :] + xi[:, None] * (np.asarray(p1, float) - p0)[None, :]


def patch_json(pid, ca, cb, knots, radius, kind="cylinder", claimed_max=0.0,
               claimed_gouge=0.0, claimed_cov=0.0):
    s = [i / 100.0 for i in range(101)]
    return {"id": pid,
            "tool": {"kind": kind, "length": float(np.linalg.norm(cb[0] - ca[0])),
                     "radii": {"s": s, "d": [float(radius(x)) for x in s]}, "profile": []},
            "motion": {"degree": 3, "knots": [float(k) for k in knots],
                       "a": np.asarray(ca).tolist(), "b": np.asarray(cb).tolist()},
            "tip": "a",
            "error": {"max": claimed_max, "rms": 0.0, "max_gouge": claimed_gouge,
                      "max_relative": 0.0},
            "coverage": {"area": 0.0, "fraction": claimed_cov}}


def strip_patch(pid, y0, y1, r=2.0, x0=-2.0, x1=22.0, K=8, **kw):
    """Cylinder of radius r, axis along y from y0 to y1 at height r, swept along x."""
    kn = clamped_knots(K)
    ca = linear_controls([x0, y0, r], [x1, y0, r], kn)
    cb = linear_controls([x0, y1, r], [x1, y1, r], kn)
    return patch_json(pid, ca, cb, kn, lambda s: r, **kw)


def write_stl_binary(path, V, F):
    with open(path, "wb") as f:
        f.write(b"binary stl written by check_patches_test".ljust(80, b" "))
        f.write(struct.pack("<I", len(F)))
        for tri in F:
            f.write(struct.pack("<3f", 0, 0, 0))
            for k in tri:
                f.write(struct.pack("<3f", *V[k]))
            f.write(b"\0\0")


def write_stl_ascii(path, V, F):
    with open(path, "w") as f:
        f.write("solid t\n")
        for tri in F:
            f.write(" facet normal 0 0 0\n  outer loop\n")
            for k in tri:
                f.write("   vertex %.17g %.17g %.17g\n" % tuple(V[k]))
            f.write("  endloop\n endfacet\n")
        f.write("endsolid t\n")


def write_obj(path, V, F):
    # Quads where two triangles form one (exercises fan triangulation and a/b/c forms).
    with open(path, "w") as f:
        for v in V:
            f.write("v %.17g %.17g %.17g\n" % tuple(v))
        f.write("vt 0 0\nvn 0 0 1\n")
        half = len(F) // 2
        for t1, t2 in zip(F[:half], F[half:]):
            # t1 = (v00, v10, v11), t2 = (v00, v11, v01): the quad v00 v10 v11 v01.
            q = [t1[0], t1[1], t1[2], t2[2]]
            f.write("f " + " ".join(f"{k + 1}/1/1" for k in q) + "\n")


def write_ply(path, V, F, binary):
    head = ("ply\nformat %s 1.0\ncomment test\nelement vertex %d\nproperty double x\n"
            "property double y\nproperty double z\nproperty uchar red\nelement face %d\n"
            "property list uchar int vertex_indices\nend_header\n"
            % ("binary_little_endian" if binary else "ascii", len(V), len(F)))
    with open(path, "wb") as f:
        f.write(head.encode())
        if binary:
            for v in V:
                f.write(struct.pack("<3dB", *v, 7))
            for t in F:
                f.write(struct.pack("<B3i", 3, *t))
        else:
            for v in V:
                f.write(("%.17g %.17g %.17g 7\n" % tuple(v)).encode())
            for t in F:
                f.write(("3 %d %d %d\n" % tuple(t)).encode())


def write_ply_binary(path, V, F):
    write_ply(path, V, F, True)


def write_case(folder, V, F, patches, tol=TOL, mesh_name="phi.ply", writer=write_ply_binary,
               input_path=None):
    # Doubles by default: binary STL's float32 would blur the 1e-9 comparisons.
    mesh_path = os.path.join(folder, mesh_name)
    writer(mesh_path, V, F)
    doc = {"format": "flank-patches/1", "units": "mm",
           "input": {"path": input_path or mesh_path, "vertices": len(V), "triangles": len(F),
                     "bbox_diagonal": 0.0},
           "settings": {"tolerance": tol},
           "coverage": {"fraction": 0.0, "tolerance": tol, "uncovered_area": 0.0},
           "timing_s": {}, "patches": patches}
    path = os.path.join(folder, "patches.json")
    with open(path, "w") as f:
        json.dump(doc, f)
    return path


# The standard flat case: Phi = [0,20] x [0,16] at z, spacing 0.5; the strip y in
# [3.25, 13.25] (between vertex rows) spans Phi completely in x.
X, Y, NX, NY = 20.0, 16.0, 41, 33
H = 0.5
Y0, Y1 = 3.25, 13.25


def run_check(path, **kw):
    kw.setdefault("rows", ROWS)
    kw.setdefault("cols", COLS)
    return cp.check(path, **kw)


# ---------------------------------------------------------------------------------------
# Independent references
# ---------------------------------------------------------------------------------------

def reference_point_triangle(p, a, b, c):
    """Distance by a different route than Ericson's: inside test on the plane projection,
    else the nearest of the three segments."""
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n)
    q = p - np.dot(p - a, n) * n
    inside = all(np.dot(np.cross(v1 - v0, q - v0), n) >= 0
                 for v0, v1 in ((a, b), (b, c), (c, a)))
    if inside:
        return abs(np.dot(p - a, n))
    best = np.inf
    for v0, v1 in ((a, b), (b, c), (c, a)):
        t = np.clip(np.dot(p - v0, v1 - v0) / np.dot(v1 - v0, v1 - v0), 0, 1)
        best = min(best, np.linalg.norm(p - (v0 + t * (v1 - v0))))
    return best


# ---------------------------------------------------------------------------------------
# Tests
# ---------------------------------------------------------------------------------------

class Geometry(unittest.TestCase):

    def test_bspline_collinear_control_points_give_a_straight_line(self):
        p0, p1 = np.array([1.0, -2.0, 3.0]), np.array([7.0, 5.0, -1.0])
        kn = clamped_knots(9)
        K = len(kn) - 4
        even = p0 + np.linspace(0, 1, K)[:, None] * (p1 - p0)
        pj = cp.Patch(patch_json(0, even, even + [0, 0, 1], kn, lambda s: 1.0), 0, "x")
        t = np.linspace(0, 1, 257)
        pts = pj.A(t)
        # On the line, from p0 to p1, in order.
        u = (p1 - p0) / np.linalg.norm(p1 - p0)
        rel = pts - p0
        off = rel - (rel @ u)[:, None] * u
        self.assertLess(np.abs(off).max(), 1e-12)
        np.testing.assert_allclose(pts[0], p0, atol=1e-12)
        np.testing.assert_allclose(pts[-1], p1, atol=1e-12)
        self.assertTrue(np.all(np.diff(rel @ u) > 0))
        # At the Greville abscissae the parametrisation is exactly linear, derivative too.
        greville = linear_controls(p0, p1, kn)
        pg = cp.Patch(patch_json(0, greville, greville + [0, 0, 1], kn, lambda s: 1.0), 0, "x")
        np.testing.assert_allclose(pg.A(t), p0 + t[:, None] * (p1 - p0), atol=1e-12)
        np.testing.assert_allclose(pg.dA(t), np.broadcast_to(p1 - p0, (len(t), 3)), atol=1e-11)

    def test_point_triangle_distance_matches_reference(self):
        rng = np.random.default_rng(1)
        n = 3000
        a, b, c = (rng.normal(size=(n, 3)) for _ in range(3))
        # Points near and far, including many in the edge and vertex regions.
        p = rng.normal(size=(n, 3)) * rng.choice([0.3, 1.0, 5.0], size=(n, 1))
        foot, d2, region = cp.closest_on_triangles(p.T, a.T, b.T, c.T)
        ref = np.array([reference_point_triangle(p[i], a[i], b[i], c[i]) for i in range(n)])
        np.testing.assert_allclose(np.sqrt(d2), ref, rtol=1e-9, atol=1e-12)
        # The foot is on the triangle and the reported distance is to the foot.
        np.testing.assert_allclose(np.linalg.norm(p.T - foot, axis=0), np.sqrt(d2), atol=1e-12)
        self.assertEqual(set(np.unique(region)), set(range(7)))

    def test_mesh_query_is_exact_against_brute_force(self):
        # A bumpy open surface with uneven triangles (one band 10x coarser), points near
        # and far, with and without a limit.
        V, F = plane(0, 10, 0, 10, 31, 31)
        V[:, 2] = 0.4 * np.sin(V[:, 0]) * np.cos(0.7 * V[:, 1])
        V[V[:, 0] > 8, 0] = 8 + (V[V[:, 0] > 8, 0] - 8) * 6   # stretched band
        mesh = cp.TriMesh(V, F)
        rng = np.random.default_rng(2)
        P = np.column_stack([rng.uniform(-3, 25, 400), rng.uniform(-3, 13, 400),
                             rng.normal(scale=3, size=400)])
        q = mesh.query(P)
        A, B, C = (V[F[:, k]] for k in range(3))
        brute = np.empty(len(P))
        for i, p in enumerate(P):
            _, d2, _ = cp.closest_on_triangles(np.repeat(p[:, None], len(F), 1), A.T, B.T, C.T)
            brute[i] = np.sqrt(d2.min())
        self.assertTrue(np.all(q["exact"]))
        np.testing.assert_allclose(q["dist"], brute, rtol=1e-12, atol=1e-12)
        lim = 1.0
        ql = mesh.query(P, limit=lim)
        near = brute <= lim
        np.testing.assert_allclose(ql["dist"][near], brute[near], rtol=1e-12, atol=1e-12)
        self.assertTrue(np.all(ql["exact"][near]))
        self.assertTrue(np.all(ql["lb"][~near] <= brute[~near] + 1e-12))
        self.assertTrue(np.all((ql["lb"] > lim)[~near & ~ql["exact"]]))

    def test_mesh_query_survives_nearer_centroids_of_farther_triangles(self):
        # Adversarial: 20 stacked triangles 2 below the query point have their centroids
        # right under it, nearer than the centroid of the triangle it nearly touches (a
        # big one whose corner is under the point). A search that trusted the k nearest
        # centroids without the r_max margin would answer 2 instead of 0.1.
        tris = [[(-0.5, -0.5, 0), (8, 0, 0), (0, 8, 0)]]
        for i in range(20):
            z = -2 - 0.01 * i
            tris.append([(-5, -3, z), (5, -3, z), (0, 6, z)])
        V = np.array(tris, dtype=float).reshape(-1, 3)
        F = np.arange(len(V)).reshape(-1, 3)
        mesh = cp.TriMesh(V, F)
        q = mesh.query(np.array([[0.0, 0.0, 0.1]]))
        self.assertTrue(q["exact"][0])
        self.assertAlmostEqual(q["dist"][0], 0.1, places=12)
        self.assertEqual(q["face"][0], 0)

    def test_radius_spline_reproduces_barrels_exactly(self):
        # Not-a-knot cubic interpolation of the 101 samples is exact for polynomials up to
        # degree 3: a barrel's quadratic radius and its slope come back everywhere.
        d = lambda s: 3.0 + 0.7 * s - 1.9 * s * s
        dd = lambda s: 0.7 - 3.8 * s
        kn = clamped_knots(4)
        ca = linear_controls([0, 0, 0], [0, 5, 0], kn)
        p = cp.Patch(patch_json(0, ca, ca + [0, 0, 10], kn, d, kind="barrel"), 0, "x")
        s = np.linspace(0, 1, 997)
        np.testing.assert_allclose(p.radius(s), d(s), atol=1e-12)
        np.testing.assert_allclose(p.dradius(s), dd(s), atol=1e-10)

    def test_spline_cutter_profile_comes_from_its_coefficients(self):
        # A spline cutter's d(s) is a cubic B-spline of 10 coefficients on clamped uniform
        # knots (interior knots at k/7): between the 101 samples, near those knots, the
        # not-a-knot interpolation of the samples is off; the coefficients are exact.
        from scipy.interpolate import BSpline, CubicSpline
        c = np.array([3.0, 3.4, 2.6, 3.9, 2.8, 3.6, 3.1, 4.0, 3.2, 3.5])
        knots = np.concatenate(([0.0] * 4, np.arange(1, 7) / 7.0, [1.0] * 4))
        d = BSpline(knots, c, 3)
        kn = clamped_knots(4)
        ca = linear_controls([0, 0, 0], [0, 5, 0], kn)
        pj = patch_json(0, ca, ca + [0, 0, 10], kn, d, kind="spline")
        pj["tool"]["coefficients"] = c.tolist()
        s = np.linspace(0, 1, 997)
        interpolated = CubicSpline(np.arange(101) / 100.0, d(np.arange(101) / 100.0))
        self.assertGreater(np.max(np.abs(interpolated(s) - d(s))), 1e-6)  # what was rebuilt
        p = cp.Patch(pj, 0, "x")
        np.testing.assert_allclose(p.radius(s), d(s), atol=1e-12)
        np.testing.assert_allclose(p.dradius(s), d.derivative()(s), atol=1e-9)
        # Coefficients that disagree with the samples (the contract) are not used.
        pj["tool"]["coefficients"] = (c + 0.01).tolist()
        p = cp.Patch(pj, 0, "x")
        np.testing.assert_allclose(p.radius(s), interpolated(s), atol=1e-12)
        # Nor are they for another kind, or when they are not numbers.
        pj["tool"]["coefficients"] = c.tolist()
        pj["tool"]["kind"] = "barrel"
        np.testing.assert_allclose(cp.Patch(pj, 0, "x").radius(s), interpolated(s), atol=1e-12)
        pj["tool"]["kind"] = "spline"
        pj["tool"]["coefficients"] = ["a"] * 10
        np.testing.assert_allclose(cp.Patch(pj, 0, "x").radius(s), interpolated(s), atol=1e-12)

    def test_envelope_conditions_hold_for_a_general_motion(self):
        # Curved motion with a non-uniform knot vector and a spline-like radius: at each
        # envelope point f(t,s) = |P - R(t,s)| - d(s) vanishes with zero gradient
        # (checked by central differences, independent of the closed form).
        rng = np.random.default_rng(3)
        K = 7
        kn = np.concatenate([[0] * 4, np.sort(rng.uniform(0.1, 0.9, K - 4)), [1] * 4])
        base = np.cumsum(rng.normal(scale=[3, 1, 0.5], size=(K, 3)), axis=0)
        ca = base
        cb = base + np.array([0.5, 0.3, 10.0]) + rng.normal(scale=0.3, size=(K, 3))
        p = cp.Patch(patch_json(0, ca, cb, kn, lambda s: 2 + 0.8 * s - 0.5 * s * s
                                + 0.3 * np.sin(3 * s), kind="spline"), 0, "x")
        t = np.linspace(0.05, 0.95, 23)
        s = np.linspace(0.05, 0.95, 19)
        R, Pp, Pm, valid = cp.envelope(p, t, s)
        self.assertGreater(valid.mean(), 0.5)
        h = 1e-6
        checked = 0
        for P in (Pp, Pm):
            for i, j in np.argwhere(valid):
                x = P[i, j]

                def f(tt, ss):
                    r = (1 - ss) * p.A(tt) + ss * p.B(tt)
                    return np.linalg.norm(x - r) - p.radius(ss)
                self.assertAlmostEqual(float(f(t[i], s[j])), 0.0, delta=1e-12)
                ft = (f(t[i] + h, s[j]) - f(t[i] - h, s[j])) / (2 * h)
                fs = (f(t[i], s[j] + h) - f(t[i], s[j] - h)) / (2 * h)
                self.assertLess(abs(ft), 1e-6)
                self.assertLess(abs(fs), 1e-6)
                checked += 1
        self.assertGreater(checked, 300)

    def test_cone_translating_over_a_plane_envelope_is_the_plane(self):
        # Case 3: a cone (linear d, d' != 0) whose spheres all touch z = 0 (centre height
        # d(s)) touches the plane along a generator; translated perpendicular to its
        # axis and parallel to the plane, its envelope is that plane, point by point
        # P(t,s) = (s Lx, y(t), 0).
        d0, d1, Lx, Yt = 1.5, 4.0, 12.0, 9.0
        kn = clamped_knots(6)
        ca = linear_controls([0, 0, d0], [0, Yt, d0], kn)
        cb = linear_controls([Lx, 0, d1], [Lx, Yt, d1], kn)
        pj = patch_json(0, ca, cb, kn, lambda s: d0 + (d1 - d0) * s, kind="cone")
        p = cp.Patch(pj, 0, "x")
        t, s = np.linspace(0, 1, 31), np.linspace(0, 1, 21)
        R, Pp, Pm, valid = cp.envelope(p, t, s)
        self.assertTrue(valid.all())
        low = np.where((Pp[..., 2] < Pm[..., 2])[..., None], Pp, Pm)
        expect = np.stack(np.broadcast_arrays(s[None, :] * Lx, t[:, None] * Yt,
                                              np.zeros((1, 1))), axis=-1)
        np.testing.assert_allclose(low, expect, atol=1e-12)
        with tempfile.TemporaryDirectory() as tmp:
            V, F = plane(-2, Lx + 2, -2, Yt + 2, 33, 27)
            res = run_check(write_case(tmp, V, F, [pj]))
        r = res["patches"][0]
        self.assertEqual(r["counted"], ROWS * COLS)
        self.assertLess(r["max_abs"], 1e-9 * d1)
        self.assertLess(r["max_gouge"], 1e-9 * d1)

    def test_no_envelope_where_the_taper_exceeds_the_axis_length(self):
        kn = clamped_knots(4)
        ca = linear_controls([0, 0, 1], [0, 5, 1], kn)
        cb = linear_controls([1, 0, 1], [1, 5, 1], kn)   # |b - a| = 1
        p = cp.Patch(patch_json(0, ca, cb, kn, lambda s: 1 + 1.5 * s, kind="cone"), 0, "x")
        _, _, _, valid = cp.envelope(p, np.linspace(0, 1, 5), np.linspace(0, 1, 5))
        self.assertFalse(valid.any())
        # Sliding along its own axis is no sweep: no envelope either.
        ca = linear_controls([0, 0, 1], [3, 0, 1], kn)
        cb = linear_controls([1, 0, 1], [4, 0, 1], kn)
        p = cp.Patch(patch_json(0, ca, cb, kn, lambda s: 1.0), 0, "x")
        _, _, _, valid = cp.envelope(p, np.linspace(0, 1, 5), np.linspace(0, 1, 5))
        self.assertFalse(valid.any())


class FlatStrips(unittest.TestCase):

    def test_cylinder_strip_on_plane(self):
        # Case 1: exact envelope. Omega = the strip y in [Y0, Y1] on z = 0.
        with tempfile.TemporaryDirectory() as tmp:
            V, F = plane(0, X, 0, Y, NX, NY)
            res = run_check(write_case(tmp, V, F, [strip_patch(0, Y0, Y1)]))
        r = res["patches"][0]
        self.assertLess(r["max_abs"], 1e-9 * 2.0)
        self.assertLess(r["max_gouge"], 1e-9 * 2.0)
        self.assertGreater(r["counted"], 0.75 * ROWS * COLS)
        self.assertAlmostEqual(res["area"], X * Y, places=9)
        exact = (Y1 - Y0) / Y
        self.assertEqual(len(res["coverage_curve"]), 1)
        self.assertAlmostEqual(res["coverage_curve"][0], res["coverage"], places=15)
        # Within a vertex spacing by construction; in fact exact here, because the strip's
        # edges lie half-way between vertex rows and Omega has rows exactly on x = 0, X.
        self.assertLessEqual(abs(res["coverage"] - exact), H / Y)
        self.assertAlmostEqual(res["coverage"], exact, places=12)
        self.assertAlmostEqual(res["coverage_ab"], exact, places=12)

    def test_vertex_exactly_over_the_last_row_is_covered(self):
        # Strip edges on vertex rows y = 3 and 13: those rows lie exactly under Omega's
        # boundary (not beyond it), so they count: 21 rows of 0.5 = 10.5 of 16.
        with tempfile.TemporaryDirectory() as tmp:
            V, F = plane(0, X, 0, Y, NX, NY)
            res = run_check(write_case(tmp, V, F, [strip_patch(0, 3.0, 13.0)]))
        self.assertAlmostEqual(res["coverage"], 10.5 / Y, places=12)

    def test_rule_c_needs_the_omega_triangle_within_twice_the_tolerance(self):
        # A ridge: the vertex row y = 8 raised by 6 tol. Omega's columns (y = 3.3 + 0.25 j)
        # at 7.8, 8.05, 8.3 are then more than 2 tol from Phi (3.6, 5.4, 2.4 tol). The row
        # y = 8 is too far (rule b); the row y = 8.5 lies on Omega (distance 0) but inside
        # cells with a corner at 8.3, so only rule (c) rejects it; the row y = 7.5 lies in
        # the cell [7.3, 7.55], both corners within 2 tol, and stays covered.
        V, F = plane(0, X, 0, Y, NX, NY)
        y = V[:, 1]
        V[np.isclose(y, 8.0), 2] = 6 * TOL
        area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]),
                                    axis=1)
        varea = np.zeros(len(V))
        np.add.at(varea, F.ravel(), np.repeat(area / 3, 3))
        in_strip = (y > 3.3) & (y < 13.3)
        expect_ab = varea[in_strip & ~np.isclose(y, 8.0)].sum() / area.sum()
        expect = expect_ab - varea[np.isclose(y, 8.5)].sum() / area.sum()
        with tempfile.TemporaryDirectory() as tmp:
            res = run_check(write_case(tmp, V, F, [strip_patch(0, 3.3, 13.3)]))
        self.assertAlmostEqual(res["coverage_ab"], expect_ab, places=12)
        self.assertAlmostEqual(res["coverage"], expect, places=12)
        # The ridge's peak is 6 tol above Omega: a gouge of nearly that.
        self.assertGreater(res["patches"][0]["max_gouge"], 5 * TOL)

    def test_curved_planar_motion_still_machines_the_plane(self):
        # Any motion keeping a cylinder's axis horizontal at height r has n = -z at every
        # envelope point (n is orthogonal to both horizontal R_t and R_s): Omega lies on
        # z = 0 even for a wiggly, non-uniformly knotted motion.
        rng = np.random.default_rng(4)
        K, r = 9, 1.5
        kn = np.concatenate([[0] * 4, np.sort(rng.uniform(0.05, 0.95, K - 4)), [1] * 4])
        xs = np.linspace(2, 18, K)
        ca = np.column_stack([xs, 4 + rng.uniform(-1, 1, K), np.full(K, r)])
        cb = np.column_stack([xs + rng.uniform(-1, 1, K), 11 + rng.uniform(-1, 1, K),
                              np.full(K, r)])
        with tempfile.TemporaryDirectory() as tmp:
            V, F = plane(0, X, 0, Y, NX, NY)
            res = run_check(write_case(tmp, V, F, [patch_json(0, ca, cb, kn, lambda s: r)]))
        p = res["patches"][0]
        self.assertGreater(p["counted"], 0.9 * ROWS * COLS)
        self.assertLess(p["max_abs"], 1e-9 * r)
        self.assertGreater(res["coverage"], 0.2)

    def test_plane_raised_or_lowered_by_delta(self):
        # Case 2: Phi moved by delta along its normal. Raised toward the tool: Omega is
        # behind Phi, e = -delta (gouge). Lowered away: e = +delta (material left).
        delta = 0.3 * TOL
        for shift, gouge in ((+delta, True), (-delta, False)):
            with self.subTest(shift=shift), tempfile.TemporaryDirectory() as tmp:
                V, F = plane(0, X, 0, Y, NX, NY, z=shift)
                res = run_check(write_case(tmp, V, F, [strip_patch(0, Y0, Y1)]))
                r = res["patches"][0]
                self.assertAlmostEqual(r["max_abs"], delta, delta=1e-9 * delta + 1e-12)
                self.assertAlmostEqual(r["rms"], delta, delta=1e-9 * delta + 1e-12)
                # Every point has the same sign: the mean is the signed error.
                self.assertAlmostEqual(r["mean"], -shift, delta=1e-9 * delta + 1e-12)
                if gouge:
                    self.assertAlmostEqual(r["max_gouge"], delta, delta=1e-9 * delta + 1e-12)
                else:
                    self.assertEqual(r["max_gouge"], 0.0)
                # Still within tolerance: coverage as on the exact plane.
                self.assertAlmostEqual(res["coverage"], (Y1 - Y0) / Y, places=12)

    def test_a_peak_between_samples_is_seen_from_the_vertex(self):
        # One vertex under the strip raised by 1.5 tol toward the tool, at a point no row or
        # column of Omega passes over: the grid sees less than the peak, the vertex sees it
        # all, and as a gouge. The result must not depend on the grid.
        V, F = plane(0, X, 0, Y, NX, NY)
        k = int(np.argmin(np.linalg.norm(V[:, :2] - [X / 2 + 0.1, (Y0 + Y1) / 2 + 0.1], axis=1)))
        V[k, 2] = 1.5 * TOL
        for rows, cols in ((ROWS, COLS), (ROWS + 37, COLS + 11)):
            with self.subTest(rows=rows), tempfile.TemporaryDirectory() as tmp:
                res = run_check(write_case(tmp, V, F, [strip_patch(0, Y0, Y1)]), rows=rows, cols=cols)
                r = res["patches"][0]
                self.assertAlmostEqual(r["max_abs"], 1.5 * TOL, delta=1e-9)
                self.assertAlmostEqual(r["max_gouge"], 1.5 * TOL, delta=1e-9)
                self.assertAlmostEqual(r["max_abs_vertices"], 1.5 * TOL, delta=1e-9)

    def test_beyond_tolerance_covers_nothing(self):
        with tempfile.TemporaryDirectory() as tmp:
            V, F = plane(0, X, 0, Y, NX, NY, z=-3 * TOL)
            res = run_check(write_case(tmp, V, F, [strip_patch(0, Y0, Y1)]))
        self.assertAlmostEqual(res["patches"][0]["max_abs"], 3 * TOL, delta=1e-12)
        self.assertFalse(res["patches"][0]["within_tolerance"])
        self.assertEqual(res["coverage"], 0.0)

    def test_coverage_curve_of_two_disjoint_strips(self):
        # Case 4: the curve is [f1, f1 + f2], f_i each strip's own coverage.
        a = strip_patch(0, 2.25, 6.25)
        b = strip_patch(1, 9.25, 13.25)
        V, F = plane(0, X, 0, Y, NX, NY)
        with tempfile.TemporaryDirectory() as tmp:
            both = run_check(write_case(tmp, V, F, [a, b]))
            f1 = run_check(write_case(tmp, V, F, [a]))["coverage"]
            f2 = run_check(write_case(tmp, V, F, [b]))["coverage"]
        self.assertEqual(len(both["coverage_curve"]), 2)
        self.assertAlmostEqual(both["coverage_curve"][0], f1, places=12)
        self.assertAlmostEqual(both["coverage_curve"][1], f1 + f2, places=12)
        self.assertAlmostEqual(f1, 4.0 / Y, places=12)
        self.assertAlmostEqual(f2, 4.0 / Y, places=12)
        self.assertAlmostEqual(both["patches"][1]["coverage_alone"], f2, places=12)

    def test_wrong_claim_is_reported(self):
        # Case 5: the file claims 1e-9 where the truth is 0.3 tol; a truthful claim agrees.
        delta = 0.3 * TOL
        V, F = plane(0, X, 0, Y, NX, NY, z=delta)
        lie = strip_patch(0, Y0, Y1, claimed_max=1e-9, claimed_gouge=1e-9, claimed_cov=0.99)
        truth = strip_patch(1, 2.25, 3.25, x0=-2.0, claimed_max=delta, claimed_gouge=delta)
        with tempfile.TemporaryDirectory() as tmp:
            path = write_case(tmp, V, F, [lie, truth])
            res = run_check(path)
            out = io.StringIO()
            with redirect_stdout(out):
                code = cp.main([path, "--rows", str(ROWS), "--cols", str(COLS)])
        r0, r1 = res["patches"]
        self.assertEqual(r0["claimed_max"], 1e-9)
        self.assertEqual(r0["claimed_coverage"], 0.99)
        self.assertAlmostEqual(r0["max_abs"], delta, delta=1e-9)
        self.assertFalse(r0["claim_agrees"])
        self.assertTrue(r1["claim_agrees"])
        self.assertEqual(code, 0)
        lines = out.getvalue().splitlines()
        self.assertTrue(any("CLAIM-DIFFERS" in l and l.split()[0] == "0" for l in lines))
        self.assertFalse(any("CLAIM-DIFFERS" in l and l.split()[0] == "1" for l in lines))


class MeshHandling(unittest.TestCase):

    def reference(self):
        V, F = plane(0, X, 0, Y, NX, NY, z=0.3 * TOL)
        return V, F, [strip_patch(0, Y0, Y1)]

    def test_all_formats_give_the_same_answer(self):
        V, F, patches = self.reference()
        writers = [("phi.stl", write_stl_binary), ("phi_ascii.stl", write_stl_ascii),
                   ("phi.obj", write_obj), ("phi.ply", lambda p, v, f: write_ply(p, v, f, False)),
                   ("phi_bin.ply", lambda p, v, f: write_ply(p, v, f, True))]
        results = []
        with tempfile.TemporaryDirectory() as tmp:
            for name, writer in writers:
                path = write_case(tmp, V, F, patches, mesh_name=name, writer=writer)
                Vr, Fr = cp.read_mesh(os.path.join(tmp, name))
                self.assertEqual(len(Vr), len(V), name)
                self.assertEqual(len(Fr), len(F), name)
                results.append(run_check(path))
        for name_res, res in zip(writers, results):
            # Binary STL stores float32, so allow its rounding.
            self.assertAlmostEqual(res["patches"][0]["max_gouge"], 0.3 * TOL, delta=1e-7,
                                   msg=name_res[0])
            self.assertAlmostEqual(res["coverage"], results[0]["coverage"], delta=1e-6,
                                   msg=name_res[0])

    def test_orientation_is_repaired_and_chosen_by_the_tools(self):
        # All faces reversed (normals -z): the tools' side still wins, signs unchanged.
        # Half the faces reversed (inconsistent): the walk over shared edges repairs it.
        V, F, patches = self.reference()
        rng = np.random.default_rng(5)
        mixed = F.copy()
        pick = rng.random(len(F)) < 0.5
        mixed[pick] = mixed[pick][:, ::-1]
        for name, FF in (("reversed", F[:, ::-1]), ("mixed", mixed)):
            with self.subTest(name), tempfile.TemporaryDirectory() as tmp:
                res = run_check(write_case(tmp, V, FF, patches))
                r = res["patches"][0]
                self.assertAlmostEqual(r["max_gouge"], 0.3 * TOL, delta=1e-7)
                self.assertAlmostEqual(r["mean"], -0.3 * TOL, delta=1e-7)
                self.assertLessEqual(abs(res["coverage"] - (Y1 - Y0) / Y), H / Y)

    def test_relative_input_path_resolves_next_to_patches_json(self):
        V, F, patches = self.reference()
        with tempfile.TemporaryDirectory() as tmp, tempfile.TemporaryDirectory() as other:
            path = write_case(tmp, V, F, patches, input_path="phi.ply")
            proc = subprocess.run([sys.executable, SCRIPT, path, "--rows", "21", "--cols", "11",
                                   "--json"], cwd=other, capture_output=True, text=True)
        self.assertEqual(proc.returncode, 0, proc.stderr)
        res = json.loads(proc.stdout)
        self.assertEqual(len(res["coverage_curve"]), 1)
        self.assertEqual(set(res["patches"][0]) >= {"id", "kind", "max_abs", "rms", "max_gouge",
                                                    "counted", "claimed_max", "claimed_gouge",
                                                    "claimed_coverage"}, True)


class BadInput(unittest.TestCase):

    def run_cli(self, *args):
        return subprocess.run([sys.executable, SCRIPT, *args], capture_output=True, text=True)

    def assert_one_line_error(self, proc, name):
        self.assertEqual(proc.returncode, 2, proc.stderr)
        lines = proc.stderr.strip().splitlines()
        self.assertEqual(len(lines), 1, proc.stderr)
        self.assertIn(name, lines[0])
        self.assertEqual(proc.stdout, "")

    def test_missing_file(self):
        with tempfile.TemporaryDirectory() as tmp:
            missing = os.path.join(tmp, "nope", "patches.json")
            self.assert_one_line_error(self.run_cli(missing), missing)

    def test_truncated_json(self):
        V, F = plane(0, 4, 0, 4, 5, 5)
        with tempfile.TemporaryDirectory() as tmp:
            path = write_case(tmp, V, F, [strip_patch(0, 1, 3)])
            with open(path) as f:
                text = f.read()
            with open(path, "w") as f:
                f.write(text[: len(text) // 2])
            self.assert_one_line_error(self.run_cli(path), path)

    def test_unreadable_mesh(self):
        V, F = plane(0, 4, 0, 4, 5, 5)
        with tempfile.TemporaryDirectory() as tmp:
            path = write_case(tmp, V, F, [strip_patch(0, 1, 3)], mesh_name="phi.stl",
                              writer=write_stl_binary)
            mesh = os.path.join(tmp, "phi.stl")
            with open(mesh, "rb") as f:
                raw = f.read()
            with open(mesh, "wb") as f:
                f.write(raw[:-30])             # truncated binary STL
            self.assert_one_line_error(self.run_cli(path), mesh)
            missing = os.path.join(tmp, "gone.obj")
            self.assert_one_line_error(self.run_cli(path, "--mesh", missing), missing)

    def test_bad_patch_content(self):
        V, F = plane(0, 4, 0, 4, 5, 5)
        with tempfile.TemporaryDirectory() as tmp:
            p = strip_patch(0, 1, 3)
            p["motion"]["a"][2][1] = None      # a non-finite value written as null
            path = write_case(tmp, V, F, [p])
            proc = self.run_cli(path)
            self.assert_one_line_error(proc, path)
            self.assertIn("motion.a", proc.stderr)


if __name__ == "__main__":
    unittest.main()
