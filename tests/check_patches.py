#!/usr/bin/env python3
"""Independent checker of flank's `patches.json` (format flank-patches/1).

It rebuilds every patch's machined surface Omega from the file alone (cutter radii and
the B-spline motion), measures it against the input mesh Phi with exact point-triangle
distances, and recomputes the coverage. The solver's own numbers (error.max,
error.max_gouge, coverage.fraction) are only reported beside ours, never used.

Usage:
    /usr/bin/python3 tests/check_patches.py DIR/patches.json [--mesh PATH]
                     [--rows N] [--cols N] [--json]
    import check_patches; check_patches.check("DIR/patches.json")  -> dict

Exit codes: 0 checked (whatever the verdict), 2 bad input (one line on stderr).

Definitions (the contract; derived here from first principles, not from the C++):

* Axis surface R(t,s) = (1-s) a(t) + s b(t), a and b clamped cubic B-splines
  (scipy BSpline) over [knots[3], knots[K]] (= [0,1] in valid files).
* Sphere radius d(s): scipy CubicSpline through the (s, d) samples with the default
  *not-a-knot* end condition, because it reproduces polynomials up to degree 3 exactly
  (cylinder, cone, barrel cutters are exact; a natural spline would bend the ends of a
  barrel's parabola). A spline cutter's d(s) is its coefficients' cubic B-spline on clamped
  uniform knots instead, when that reproduces the samples to 1e-9 (spline_profile).
  d'(s) = dd/ds with s in [0,1] (so |R_s| = |b-a| ~ L).
* Envelope of the two-parameter sphere family |x - R(t,s)| = d(s): differentiating in t
  and s gives, with x = R + d n and |n| = 1,
      n . R_t = 0,    n . R_s = -d'(s).
  Closed form: e1 = w/|w| (w = R_s = b - a), v = R_t, v_perp = v - (v.e1) e1,
  e2 = v_perp/|v_perp|, e3 = e1 x e2, and n = x e1 + y e2 +- z e3 with
      x = -d'/|w|,   y = -x (v.e1)/|v_perp|,   z = sqrt(1 - x^2 - y^2).
  No envelope point exists when 1 - x^2 - y^2 <= 0 (this includes |d'| >= |b-a|), when
  the axis does not move across itself (|v_perp| ~ 0), or when d < 0.  Of the two sides
  the one whose point is closer to Phi is taken, point by point.
* Signed deviation e = +-dist(P, Phi): + on the tool side of Phi (material left), - behind
  it (gouge).  The side at edge/vertex footpoints is decided with angle-weighted
  pseudo-normals (Baerentzen-Aanaes), so the sign is exact for a closed or open mesh.
  A point counts only if its footpoint is interior to Phi, or lies on Phi's boundary
  with P not beyond it (P in the normal slab of the boundary edge, within 1e-9 x the
  bounding-box diagonal).
* max_abs and max_gouge are the sup over Omega, not over the grid: around the 8 counted
  samples of largest |e| a 9 x 9 sub-grid (eighth steps, one sample each way) is searched too.
* The reported deviations also count Phi's vertices seen from Omega: every vertex of Phi
  within 10 x tolerance of a patch's Omega mesh, taken over the cells whose four corners
  have a counted footpoint (as the grid's errors), whose closest point on it is not beyond
  that mesh's boundary (nor on it: at the ends of the sweep and of the cutter a vertex is
  not under Omega), and whose segment to that point lies within 30 degrees of Phi's vertex
  normal (a vertex beyond the end of a sweep sees Omega's last rows off to the side),
  contributes its signed distance (+ where Omega lies on the tool side of
  the vertex, by the area-weighted vertex normal: material left) to max_abs and max_gouge
  (not to rms).  On a scanned (noisy) Phi the largest deviation sits at the vertices, between
  any samples of Omega, so the grid alone would make max_abs depend on the sampling.
* Coverage: a vertex of Phi is covered when its closest point on the union of the Omega
  meshes (a) is not beyond the boundary of that Omega mesh (same "beyond" rule as above;
  the Omega mesh boundary includes holes left by cells with an invalid corner),
  (b) is within the tolerance, and (c) lies on an Omega triangle whose three vertices each
  either lie beyond Phi's boundary (the cutter overhangs the part there: nothing to
  compare) or have |e| <= 2 x tolerance (when the closest point is on an edge or a vertex
  of Omega, any triangle containing it may qualify).  Rule (c) keeps Omega's false parts
  out: folds where the motion reverses, or a surface crossing Phi at an angle, pass near
  some vertices of Phi without cutting them.  It allows twice the tolerance because on a
  scanned (noisy) Phi the distance from Omega to the nearest vertex of Phi carries that
  vertex's noise: at once a vertex within tolerance of Omega would count as uncovered
  because its noisy neighbour is not.  Ties between patches
  (equal distance within 1e-12 x diagonal) count as covered if any tied patch qualifies.
  Fraction = sum of covered vertex areas / sum of vertex areas, vertex area = 1/3 of each
  incident triangle.  The coverage curve uses patches 0..k-1, in file order.

Orientation of Phi: the faces are first made consistent by a breadth-first walk over
shared (2-manifold) edges, agreeing with the lowest-numbered face of each edge-connected
component.  Then each component is flipped if the majority of the patches' axis sample
points R(t,s) (21 x 11 per patch) whose footpoint lies on it are on its negative side:
tools live on the positive side, and the file may have been oriented either way (flank
re-orients on load).  Components no axis point is closest to keep the walk's orientation.

Meshes: binary / ASCII STL, OBJ (v and f lines, polygons fan-triangulated, a/b/c forms,
negative indices), PLY (ascii, binary little/big endian).  Identical vertex coordinates
are welded exactly for every format (area-weighted coverage is unaffected by welding);
faces that repeat a vertex after welding are dropped; zero-area faces stay in the
topology but are never closest.

Diagnostics beyond the contract (reported, never replacing it):
* max_abs_exposed: max |e| without the envelope points that lie strictly inside the
  sampled swept volume (another sphere of the sweep contains them, e.g. where the motion
  stalls and reverses). Such points are cut away, so they are not machined surface; a
  large max_abs with a small max_abs_exposed means "envelope artefact", not material
  left.  Gouge points (e < 0) are never excluded: the sweep does reach behind Phi there.
* worst: where max |e| occurs (t, s, e) and how deep that point is inside the swept volume.
* claim_agrees: |max_abs_exposed - error.max| <= 0.1 tol + 0.1 max(both) (sampling
  differs, so exact equality is not expected).
* coverage_ab / coverage_curve_ab: coverage with rules (a) and (b) only, which is how
  flank counts; compare claimed_coverage with this one.
* coverage_alone per patch, mean (signed), length_drift = max | |b(t)-a(t)| - tool.length |.
* Feet within 1e-9 x diagonal of an edge or vertex of their Omega triangle are snapped
  onto it before rule (c), so exact ties (a Phi vertex on a shared Omega edge) do not
  depend on round-off.

Closest points: per size class of triangles (powers of two of the median
centroid-to-vertex radius), a cKDTree on centroids gives the k nearest candidates; the
exact distance to them (vectorised Ericson region test) is accepted only when it is
provably the minimum, i.e. D <= (k-th centroid distance) - r_max, r_max being the largest
centroid-to-vertex distance in the class (every triangle lies in the ball of that radius
around its centroid).  Otherwise k grows (16, 64, 256), then a ball query of radius
D + r_max settles the rest.  Queries with a limit (the tolerance, for coverage) stop as
soon as the lower bound exceeds it.  The side of the envelope closer to Phi is found
without exact distances for the far side: the two candidates are |P+ - P-| apart, so a
side within half of that of Phi is the closer one (triangle inequality).

Measured (one core, Debian python3 / NumPy 1.24 / SciPy 1.10): rotor67 upper blade
(19 481 vertices, 38 400 triangles) with 12 patches at 400 x 101: about 21 s.
"""

import argparse
import json
import math
import os
import struct
import sys
import time

import numpy as np
from scipy.interpolate import BSpline, CubicSpline
from scipy.spatial import cKDTree


class InputError(Exception):
    """Bad input: reported as one line naming the file, exit code 2."""

    def __init__(self, path, message):
        super().__init__(f"{path}: {message}")
        self.path = path
        self.message = message


# --------------------------------------------------------------------------------------
# Mesh reading
# --------------------------------------------------------------------------------------

def read_mesh(path):
    """Returns (V float64 (n,3), F int64 (m,3)), welded and cleaned. Raises InputError."""
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except OSError as exc:
        raise InputError(path, f"cannot read mesh ({exc.strerror or exc})")
    ext = os.path.splitext(path)[1].lower()
    try:
        if ext == ".stl":
            V, F = _read_stl(raw)
        elif ext == ".obj":
            V, F = _read_obj(raw)
        elif ext == ".ply":
            V, F = _read_ply(raw)
        else:
            raise ValueError(f"unsupported mesh extension '{ext}' (expected .stl, .obj or .ply)")
    except (ValueError, IndexError, struct.error, UnicodeDecodeError) as exc:
        raise InputError(path, str(exc) or type(exc).__name__)
    if len(F) == 0:
        raise InputError(path, "mesh has no triangles")
    if not np.all(np.isfinite(V)):
        raise InputError(path, "mesh has non-finite vertex coordinates")
    if F.min() < 0 or F.max() >= len(V):
        raise InputError(path, "face index out of range")
    V, F = _weld(V, F)
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 2] != F[:, 0])]
    if len(F) == 0:
        raise InputError(path, "mesh has only degenerate triangles")
    return V, F


def _weld(V, F):
    # +0.0 turns -0.0 into 0.0, so that np.unique's bytewise row comparison sees them equal.
    V = np.ascontiguousarray(V, dtype=np.float64) + 0.0
    used = np.unique(F)
    U, inverse = np.unique(V[used], axis=0, return_inverse=True)
    remap = np.full(len(V), -1, dtype=np.int64)
    remap[used] = inverse.reshape(-1)
    return U, remap[F]


def _read_stl(raw):
    if len(raw) >= 84:
        n = struct.unpack_from("<I", raw, 80)[0]
        # The size test comes first: many binary STLs also start with "solid".
        if len(raw) == 84 + 50 * n:
            rec = np.dtype([("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
            tri = np.frombuffer(raw, dtype=rec, count=n, offset=84)["v"].astype(np.float64)
            V = tri.reshape(-1, 3)
            return V, np.arange(len(V), dtype=np.int64).reshape(-1, 3)
    if not raw.lstrip().lower().startswith(b"solid"):
        if len(raw) >= 84:
            n = struct.unpack_from("<I", raw, 80)[0]
            raise ValueError(f"binary STL of {n} triangles needs {84 + 50 * n} bytes, "
                             f"file has {len(raw)}")
        raise ValueError("neither binary nor ASCII STL (too short, no 'solid')")
    tokens = raw.decode("ascii", errors="replace").split()
    coords = []
    for i, tok in enumerate(tokens):
        if tok.lower() == "vertex":
            if i + 3 >= len(tokens):
                raise ValueError("truncated ASCII STL vertex")
            coords.append(tokens[i + 1:i + 4])
    if not coords or len(coords) % 3:
        raise ValueError(f"ASCII STL has {len(coords)} vertices (need a positive multiple of 3)")
    try:
        V = np.array(coords, dtype=np.float64)
    except ValueError:
        raise ValueError("ASCII STL has a malformed vertex line")
    if V.shape[1] != 3:
        raise ValueError("truncated ASCII STL vertex")
    return V, np.arange(len(V), dtype=np.int64).reshape(-1, 3)


def _read_obj(raw):
    V, F = [], []
    for lineno, line in enumerate(raw.decode("utf-8", errors="replace").splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            if len(parts) < 4:
                raise ValueError(f"line {lineno}: vertex needs 3 coordinates")
            try:
                V.append([float(x) for x in parts[1:4]])
            except ValueError:
                raise ValueError(f"line {lineno}: malformed vertex")
        elif parts[0] == "f":
            idx = []
            for p in parts[1:]:
                try:
                    k = int(p.split("/")[0])
                except ValueError:
                    raise ValueError(f"line {lineno}: malformed face index '{p}'")
                # OBJ indices are 1-based; negative ones count back from the last vertex.
                idx.append(k - 1 if k > 0 else len(V) + k)
            if len(idx) < 3:
                raise ValueError(f"line {lineno}: face with fewer than 3 vertices")
            for j in range(1, len(idx) - 1):
                F.append([idx[0], idx[j], idx[j + 1]])
    if not V:
        raise ValueError("OBJ has no vertices")
    return np.array(V, dtype=np.float64), np.array(F, dtype=np.int64).reshape(-1, 3)


_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
              "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
              "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def _read_ply(raw):
    end = raw.find(b"end_header")
    if not raw.startswith(b"ply") or end < 0:
        raise ValueError("not a PLY file (no 'ply' magic or no end_header)")
    nl = raw.find(b"\n", end)
    body_start = len(raw) if nl < 0 else nl + 1
    header = raw[:end].decode("ascii", errors="replace").splitlines()
    fmt, elements = None, []
    for line in header[1:]:
        w = line.split()
        if not w or w[0] in ("comment", "obj_info"):
            continue
        if w[0] == "format":
            fmt = w[1]
        elif w[0] == "element":
            elements.append({"name": w[1], "count": int(w[2]), "props": []})
        elif w[0] == "property":
            if not elements:
                raise ValueError("property before any element")
            if w[1] == "list":
                if w[2] not in _PLY_TYPES or w[3] not in _PLY_TYPES:
                    raise ValueError(f"unknown PLY type in '{line}'")
                elements[-1]["props"].append((w[4], "list", _PLY_TYPES[w[2]], _PLY_TYPES[w[3]]))
            else:
                if w[1] not in _PLY_TYPES:
                    raise ValueError(f"unknown PLY type '{w[1]}'")
                elements[-1]["props"].append((w[2], "scalar", _PLY_TYPES[w[1]], None))
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise ValueError(f"unsupported PLY format '{fmt}'")
    if fmt == "ascii":
        try:
            V, lists = _ply_ascii_body(raw[body_start:].split(), elements)
        except IndexError:
            raise ValueError("truncated PLY body")
    else:
        bo = "<" if fmt == "binary_little_endian" else ">"
        pos = body_start
        V, lists = None, []
        for el in elements:
            has_list = any(k == "list" for _, k, _, _ in el["props"])
            if not has_list:
                dt = np.dtype([(n, bo + t1) for n, _, t1, _ in el["props"]])
                if pos + dt.itemsize * el["count"] > len(raw):
                    raise ValueError(f"truncated PLY body in element '{el['name']}'")
                arr = np.frombuffer(raw, dtype=dt, count=el["count"], offset=pos)
                pos += dt.itemsize * el["count"]
                if el["name"] == "vertex":
                    V = np.stack([arr["x"], arr["y"], arr["z"]], axis=1).astype(np.float64)
            else:
                rows, pos = _ply_binary_lists(raw, pos, el, bo)
                if el["name"] == "face":
                    lists = rows
        if V is None:
            raise ValueError("PLY has no vertex element with x, y, z")
    F = []
    for idx in lists:
        if idx is None or len(idx) < 3:
            continue
        for j in range(1, len(idx) - 1):
            F.append([idx[0], idx[j], idx[j + 1]])
    return V, np.array(F, dtype=np.int64).reshape(-1, 3)


def _ply_ascii_body(tokens, elements):
    """Elements of an ASCII PLY body, in header order. Returns (V, face index lists)."""
    data, pos = {}, 0
    for el in elements:
        rows = []
        for _ in range(el["count"]):
            row = {}
            for name, kind, t1, t2 in el["props"]:
                if kind == "scalar":
                    row[name] = float(tokens[pos]); pos += 1
                else:
                    n = int(tokens[pos]); pos += 1
                    row[name] = [int(x) for x in tokens[pos:pos + n]]
                    if len(row[name]) != n:
                        raise ValueError("truncated PLY body")
                    pos += n
            rows.append(row)
        data[el["name"]] = rows
    vrows = data.get("vertex")
    if vrows is None:
        raise ValueError("PLY has no vertex element")
    V = np.array([[r["x"], r["y"], r["z"]] for r in vrows], dtype=np.float64).reshape(-1, 3)
    return V, [_first_list(r) for r in data.get("face", [])]


def _first_list(row):
    for v in row.values():
        if isinstance(v, list):
            return v
    return None


def _ply_binary_lists(raw, pos, el, bo):
    """Binary element with list properties. Fast path: every list has 3 entries."""
    props, count = el["props"], el["count"]
    fields = []
    for name, kind, t1, t2 in props:
        if kind == "scalar":
            fields.append((name, bo + t1))
        else:
            fields.append((name + "__n", bo + t1))
            fields.append((name, bo + t2, (3,)))
    dt = np.dtype(fields)
    first_list = next(n for n, k, _, _ in props if k == "list")
    if pos + dt.itemsize * count <= len(raw):
        arr = np.frombuffer(raw, dtype=dt, count=count, offset=pos)
        ok = all(np.all(arr[n + "__n"] == 3) for n, k, _, _ in props if k == "list")
        if ok:
            return [list(map(int, r)) for r in arr[first_list]], pos + dt.itemsize * count
    rows = []
    for _ in range(count):
        found = None
        for name, kind, t1, t2 in props:
            if kind == "scalar":
                pos += np.dtype(t1).itemsize
                continue
            n = int(np.frombuffer(raw, dtype=bo + t1, count=1, offset=pos)[0])
            pos += np.dtype(t1).itemsize
            size = np.dtype(t2).itemsize * n
            if pos + size > len(raw):
                raise ValueError(f"truncated PLY body in element '{el['name']}'")
            vals = np.frombuffer(raw, dtype=bo + t2, count=n, offset=pos)
            pos += size
            if found is None and name == first_list:
                found = [int(x) for x in vals]
        rows.append(found)
    return rows, pos


# --------------------------------------------------------------------------------------
# Exact point-triangle distance (Ericson, "Real-Time Collision Detection" 5.1.5),
# vectorised over columns of (3, N) arrays.
# Region codes: 0 face, 1 edge AB, 2 edge BC, 3 edge CA, 4 vertex A, 5 vertex B, 6 vertex C.
# --------------------------------------------------------------------------------------

def _dot(u, v):
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def closest_on_triangles(p, a, b, c):
    """p, a, b, c: (3, N). Returns (foot (3,N), squared distance (N,), region (N,) int8).

    Triangles must have positive area (callers exclude degenerate ones)."""
    ab, ac = b - a, c - a
    ap, bp, cp = p - a, p - b, p - c
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    # np.select takes the first true condition: this is Ericson's early-return order.
    conds = [(d1 <= 0) & (d2 <= 0),
             (d3 >= 0) & (d4 <= d3),
             (vc <= 0) & (d1 >= 0) & (d3 <= 0),
             (d6 >= 0) & (d5 <= d6),
             (vb <= 0) & (d2 >= 0) & (d6 <= 0),
             (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)]
    region = np.select(conds, [4, 5, 1, 6, 3, 2], default=0).astype(np.int8)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        inv = 1.0 / (va + vb + vc)
        v_face, w_face = vb * inv, vc * inv
    zero, one = 0.0, 1.0
    # Barycentric weights (u, v, w) of the foot for each region.
    v = np.select([region == 0, region == 1, region == 2, region == 5],
                  [v_face, t_ab, 1.0 - t_bc, one], default=zero)
    w = np.select([region == 0, region == 3, region == 2, region == 6],
                  [w_face, t_ac, t_bc, one], default=zero)
    foot = a + v * ab + w * ac
    diff = p - foot
    return foot, _dot(diff, diff), region


# --------------------------------------------------------------------------------------
# Triangle mesh with closest-point queries, boundary and sign information
# --------------------------------------------------------------------------------------

def edge_ids(fe):
    """Per face-edge slot (rows of fe: the two vertex indices), the id of its undirected edge,
    edges numbered in (lower vertex, higher vertex) order, and each edge's slot count. The
    same as np.unique of the sorted rows with axis=0, on one int64 key per slot: a row-wise
    unique sorts a structured array field by field, and cost the checker a fifth of its time."""
    lo, hi = np.minimum(fe[:, 0], fe[:, 1]), np.maximum(fe[:, 0], fe[:, 1])
    n = int(hi.max()) + 1 if len(fe) else 1
    _, eid, count = np.unique(lo.astype(np.int64) * n + hi, return_inverse=True, return_counts=True)
    return eid.reshape(-1), count


_CHUNK_PAIRS = 1 << 18  # point-triangle pairs per vectorised batch (memory ~ 100 MB)


class TriMesh:
    """A triangle mesh answering exact closest-point queries."""

    def __init__(self, V, F, pseudo_normals=False):
        self.V = np.ascontiguousarray(V, dtype=np.float64)
        self.F = np.ascontiguousarray(F, dtype=np.int64)
        nv, nf = len(self.V), len(self.F)
        A, B, C = (self.V[self.F[:, k]] for k in range(3))
        cr = np.cross(B - A, C - A)
        dbl = np.linalg.norm(cr, axis=1)
        self.area = 0.5 * dbl
        edge_len = np.stack([np.linalg.norm(B - A, axis=1), np.linalg.norm(C - B, axis=1),
                             np.linalg.norm(A - C, axis=1)], axis=1)
        lmax = edge_len.max(axis=1)
        # Slivers whose area is at round-off level cannot be handled by the region test;
        # they stay in the topology (edges, boundary) but are never returned as closest.
        good = dbl > 1e-12 * lmax * lmax
        with np.errstate(divide="ignore", invalid="ignore"):
            self.normal = np.where(good[:, None], cr / dbl[:, None], 0.0)

        # Edge topology: face-edge slot k runs from corner k to corner k+1.
        fe = self.F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
        eid, ecount = edge_ids(fe)
        self.edge_id = eid.reshape(nf, 3)
        self.n_edges = len(ecount)
        self.boundary_edge = (ecount[eid] == 1).reshape(nf, 3)
        self.boundary_vertex = np.zeros(nv, dtype=bool)
        bslots = np.nonzero(self.boundary_edge.reshape(-1))[0]
        self.boundary_vertex[fe[bslots].reshape(-1)] = True

        # Outward in-plane unit normal of each face edge (away from the opposite corner):
        # independent of the face's orientation, so it works for Omega meshes too.
        P0 = np.stack([A, B, C], axis=1)            # (nf, 3 corners, 3)
        P1 = np.roll(P0, -1, axis=1)                # edge end
        P2 = np.roll(P0, -2, axis=1)                # opposite corner
        ed = P1 - P0
        with np.errstate(divide="ignore", invalid="ignore"):
            ed_u = ed / np.linalg.norm(ed, axis=2, keepdims=True)
            toward = P2 - P0
            perp = toward - np.sum(toward * ed_u, axis=2, keepdims=True) * ed_u
            out = -perp / np.linalg.norm(perp, axis=2, keepdims=True)
        self.edge_out = np.nan_to_num(out)
        # Per boundary vertex, the outward normals of its boundary edges (CSR).
        bv = fe[bslots].reshape(-1)
        bm = np.repeat(self.edge_out.reshape(-1, 3)[bslots], 2, axis=0)
        order = np.argsort(bv, kind="stable")
        self._bv_m = bm[order]
        self._bv_start = np.searchsorted(bv[order], np.arange(nv + 1))

        if pseudo_normals:
            self._build_pseudo_normals(A, B, C, good)

        # Query structure over the non-degenerate faces, in size classes: the safety bound
        # uses the largest triangle of a class, so a few huge triangles (an envelope that
        # jumps at a stall, a sliver in a CAD mesh) must not weaken it for all the others.
        self.qfaces = np.nonzero(good)[0]
        if len(self.qfaces) == 0:
            raise ValueError("mesh has no triangle of positive area")
        qa, qb, qc = A[self.qfaces], B[self.qfaces], C[self.qfaces]
        cen = (qa + qb + qc) / 3.0
        r = np.max(np.stack([np.linalg.norm(q - cen, axis=1) for q in (qa, qb, qc)]), axis=0)
        self.r_max = float(r.max())
        med = float(np.median(r))
        level = np.floor(np.log2(np.maximum(r / med, 1.0))).astype(np.int64)
        self.classes = []
        for lv in np.unique(level):
            members = np.nonzero(level == lv)[0]
            self.classes.append({
                "faces": self.qfaces[members],
                "tree": cKDTree(cen[members]),
                "r_max": float(r[members].max()),
                "TA": np.ascontiguousarray(qa[members].T),
                "TB": np.ascontiguousarray(qb[members].T),
                "TC": np.ascontiguousarray(qc[members].T)})
        # Largest class first: it usually holds the answer, and its upper bound then lets
        # the small classes stop after one round.
        self.classes.sort(key=lambda c: -len(c["faces"]))
        self.stats = {"queries": 0, "ball_fallbacks": 0}

    def _build_pseudo_normals(self, A, B, C, good):
        n = self.normal
        # Edge pseudo-normal: sum of the unit normals of the faces sharing the edge.
        esum = np.zeros((self.n_edges, 3))
        np.add.at(esum, self.edge_id.reshape(-1), np.repeat(n, 3, axis=0))
        self.edge_pn = esum[self.edge_id]            # (nf, 3, 3)
        # Vertex pseudo-normal: angle-weighted sum of incident face normals.
        P = np.stack([A, B, C], axis=1)
        u = np.roll(P, -1, axis=1) - P
        w = np.roll(P, -2, axis=1) - P
        with np.errstate(divide="ignore", invalid="ignore"):
            cosang = np.sum(u * w, axis=2) / (np.linalg.norm(u, axis=2) * np.linalg.norm(w, axis=2))
        ang = np.arccos(np.clip(np.nan_to_num(cosang), -1.0, 1.0))
        ang[~good] = 0.0
        vsum = np.zeros((len(self.V), 3))
        np.add.at(vsum, self.F.reshape(-1), (ang[:, :, None] * n[:, None, :]).reshape(-1, 3))
        self.vertex_pn = vsum

    # ---- closest points ----

    @staticmethod
    def _exact(cls, P, cand, missing=None):
        """Exact distance from each row of P to its candidate faces (rows of cand, indices
        into the class). Returns the best per row: dist, foot (m,3), face (into F), region."""
        m, k = cand.shape
        dist = np.empty(m)
        foot = np.empty((m, 3))
        face = np.empty(m, dtype=np.int64)
        reg = np.empty(m, dtype=np.int8)
        step = max(1, _CHUNK_PAIRS // k)
        for lo in range(0, m, step):
            hi = min(m, lo + step)
            idx = cand[lo:hi].reshape(-1)
            p = np.repeat(P[lo:hi].T, k, axis=1)
            f, d2, r = closest_on_triangles(p, cls["TA"][:, idx], cls["TB"][:, idx],
                                            cls["TC"][:, idx])
            d2 = d2.reshape(hi - lo, k)
            if missing is not None:
                d2[missing[lo:hi]] = np.inf
            j = np.argmin(d2, axis=1)
            flat = np.arange(hi - lo) * k + j
            dist[lo:hi] = np.sqrt(d2[np.arange(hi - lo), j])
            foot[lo:hi] = f[:, flat].T
            face[lo:hi] = cls["faces"][idx[flat]]
            reg[lo:hi] = r[flat]
        return dist, foot, face, reg

    def query(self, P, limit=np.inf, k0=16):
        """Closest points of P (n,3) on the mesh.

        Returns a dict: dist (exact where `exact`, else an upper bound), lb (a lower bound,
        equal to dist where exact), foot, face (into F), region, exact.  Points proven
        farther than `limit` (scalar or per point) stop early (then dist and lb only
        bound the distance)."""
        P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3)
        n = len(P)
        limit = np.broadcast_to(np.asarray(limit, dtype=np.float64), (n,))
        self.stats["queries"] += n
        res = None
        for cls in self.classes:
            # A class need not be searched beyond what is already known to be closer.
            lim = limit if res is None else np.minimum(limit, res["dist"])
            r = self._query_class(cls, P, lim, k0)
            if res is None:
                res = r
                continue
            better = r["dist"] < res["dist"]
            lb = np.minimum(res["lb"], r["lb"])
            for key in ("dist", "foot", "face", "region"):
                res[key][better] = r[key][better]
            res["lb"] = lb
        # Exact when no class can hold anything closer than the best found.
        res["exact"] = res["lb"] >= res["dist"]
        res["lb"] = np.minimum(res["lb"], res["dist"])
        return res

    def _query_class(self, cls, P, limit, k0):
        n, nq = len(P), len(cls["faces"])
        res = {"dist": np.full(n, np.inf), "lb": np.zeros(n), "foot": np.zeros((n, 3)),
               "face": np.zeros(n, dtype=np.int64), "region": np.zeros(n, dtype=np.int8)}
        # Blocks of similar limit: a kd-tree search from far above a surface visits many
        # cells, so it is cut off at limit + r_max (nothing beyond can be within limit).
        order = np.argsort(limit, kind="stable")
        for lo in range(0, n, 8192):
            todo = order[lo:lo + 8192]
            k = min(k0, nq)
            while todo.size:
                lim = limit[todo]
                U = np.inf
                if np.all(np.isfinite(lim)):
                    top = float(lim.max())
                    U = top + abs(top) * 1e-9 + cls["r_max"] * (1 + 1e-9) + 1e-300
                dd, ii = cls["tree"].query(P[todo], k, distance_upper_bound=U)
                dd, ii = dd.reshape(len(todo), k), ii.reshape(len(todo), k)
                missing = ii >= nq
                ii = np.where(missing, 0, ii)
                D, foot, face, reg = self._exact(cls, P[todo], ii, missing)
                kth = dd[:, -1]
                # Every face outside the returned candidates is at least this far away.
                if k >= nq:
                    bound = np.where(np.isinf(kth), U - cls["r_max"], np.inf)
                else:
                    bound = np.minimum(kth, U) - cls["r_max"]
                safe = D <= bound
                lb = np.where(safe, D, np.minimum(D, bound))
                done = safe | (lb > lim)
                sel = todo[done]
                res["dist"][sel] = D[done]
                res["lb"][sel] = lb[done]
                res["foot"][sel] = foot[done]
                res["face"][sel] = face[done]
                res["region"][sel] = reg[done]
                todo = todo[~done]
                if todo.size and k < nq:
                    if 4 * k > 256:
                        self._ball(cls, P, todo, D[~done], res)
                        todo = todo[:0]
                    k = min(4 * k, nq)
        return res

    def _ball(self, cls, P, todo, upper, res):
        # Rare: far points or a very uneven class. A ball of radius D + r_max around the
        # point holds the centroid of every face that can be closer than the current D.
        self.stats["ball_fallbacks"] += len(todo)
        lists = cls["tree"].query_ball_point(P[todo], upper + cls["r_max"] * (1 + 1e-12))
        for i, cand in zip(todo, lists):
            cand = np.asarray(cand, dtype=np.int64)
            D, foot, face, reg = self._exact(cls, P[i:i + 1], cand.reshape(1, -1))
            res["dist"][i] = res["lb"][i] = D[0]
            res["foot"][i] = foot[0]
            res["face"][i] = face[0]
            res["region"][i] = reg[0]

    def query_closer(self, PA, PB):
        """For point pairs (PA[i], PB[i]), the one closer to the mesh and its exact query.

        The far side of an envelope lies about two radii away, where exact answers are
        expensive; the triangle inequality avoids them: if dist(PA) <= |PA - PB| / 2 then
        dist(PB) >= |PA - PB| - dist(PA) >= dist(PA), so each side is only searched within
        half the separation. Returns (use_b bool array, chosen points, query of them)."""
        half = 0.5 * np.linalg.norm(PA - PB, axis=1)
        qa = self.query(PA, limit=half)
        a_ok = qa["exact"] & (qa["dist"] <= half)
        # Where A lies within half the separation with room to spare (far beyond rounding),
        # B is farther than half and than A: B is neither ok nor chosen, so its side (the far
        # side of the envelope, half of the checker's time) is only searched elsewhere.
        need = np.nonzero(~(a_ok & (qa["dist"] < half * (1.0 - 1e-9))))[0]
        qb = {key: np.zeros_like(value) for key, value in qa.items()}
        b_ok = np.zeros(len(PA), dtype=bool)
        if need.size:
            sub = self.query(PB[need], limit=half[need])
            for key in qb:
                qb[key][need] = sub[key]
            b_ok[need] = sub["exact"] & (sub["dist"] <= half[need])
        use_b = b_ok & ~(a_ok & (qa["dist"] <= qb["dist"]))
        # Both sides farther than half the separation (an error about as large as the
        # radius, or a grazing contact where the sides meet): search both in full.
        und = np.nonzero(~a_ok & ~b_ok)[0]
        if und.size:
            ra = self.query(PA[und])
            rb = self.query(PB[und], limit=ra["dist"])
            pick_b = rb["exact"] & (rb["dist"] < ra["dist"])
            use_b[und] = pick_b
            for q, r in ((qa, ra), (qb, rb)):
                for key in q:
                    q[key][und] = r[key]
        Pc = np.where(use_b[:, None], PB, PA)
        q = {key: np.where(use_b if qa[key].ndim == 1 else use_b[:, None], qb[key], qa[key])
             for key in qa}
        assert np.all(q["exact"])
        return use_b, Pc, q

    # ---- facts about a query's footpoints ----

    def sign(self, P, q):
        """+1 on the side the (pseudo-)normals point to, -1 behind, for exact queries."""
        f, r = q["face"], q["region"].astype(np.int64)
        pn = self.normal[f].copy()
        e = (r >= 1) & (r <= 3)
        pn[e] = self.edge_pn[f[e], r[e] - 1]
        vv = r >= 4
        pn[vv] = self.vertex_pn[self.F[f[vv], r[vv] - 4]]
        s = np.sign(np.sum((P - q["foot"]) * pn, axis=1))
        s[s == 0] = 1.0
        return s

    def snap_region(self, q, eps):
        """The query's regions, with feet within eps of an edge or vertex of their face
        moved onto it. A foot exactly on an edge shared by two triangles may come out of
        the region test as inside either one (round-off); rules that ask "which triangles
        contain the foot" must see both."""
        f, r = q["face"], q["region"].copy()
        sel = np.nonzero(r <= 3)[0]
        if sel.size == 0:
            return r
        A, B, C = (self.V[self.F[f[sel], k]] for k in range(3))
        X = q["foot"][sel]
        n = self.normal[f[sel]]
        # Distance of the foot to each edge line = signed sub-area / edge length.
        dist = []
        for P0, P1 in ((A, B), (B, C), (C, A)):
            e = P1 - P0
            dist.append(np.abs(np.sum(np.cross(e, X - P0) * n, axis=1))
                        / np.maximum(np.linalg.norm(e, axis=1), 1e-300))
        on_ab, on_bc, on_ca = (d <= eps for d in dist)
        # Vertices: A lies on AB and CA, B on AB and BC, C on BC and CA.
        new = np.select([on_ab & on_ca, on_ab & on_bc, on_bc & on_ca, on_ab, on_bc, on_ca],
                        [4, 5, 6, 1, 2, 3], default=0).astype(np.int8)
        # An edge region stays an edge (or becomes one of its end vertices).
        r[sel] = np.where((r[sel] == 0) | (new >= 4), new, r[sel])
        return r

    def on_boundary(self, q):
        """True where the footpoint lies on a boundary edge or vertex (beyond it or not)."""
        f, r = q["face"], q["region"].astype(np.int64)
        out = np.zeros(len(f), dtype=bool)
        e = (r >= 1) & (r <= 3)
        out[e] = self.boundary_edge[f[e], r[e] - 1]
        vv = r >= 4
        out[vv] = self.boundary_vertex[self.F[f[vv], r[vv] - 4]]
        return out

    def beyond_boundary(self, P, q, eps):
        """True where the footpoint is on a boundary edge/vertex and P lies beyond it."""
        f, r = q["face"], q["region"].astype(np.int64)
        off = P - q["foot"]
        out = np.zeros(len(P), dtype=bool)
        e = (r >= 1) & (r <= 3)
        e[e] = self.boundary_edge[f[e], r[e] - 1]
        ie = np.nonzero(e)[0]
        out[ie] = np.sum(off[ie] * self.edge_out[f[ie], r[ie] - 1], axis=1) > eps
        vv = r >= 4
        iv = np.nonzero(vv)[0]
        verts = self.F[f[iv], r[iv] - 4]
        keep = self.boundary_vertex[verts]
        iv, verts = iv[keep], verts[keep]
        if iv.size:
            st, en = self._bv_start[verts], self._bv_start[verts + 1]
            cnt = en - st
            owner = np.repeat(np.arange(len(iv)), cnt)
            pos = np.repeat(st - np.cumsum(cnt) + cnt, cnt) + np.arange(cnt.sum())
            vals = np.sum(off[iv][owner] * self._bv_m[pos], axis=1)
            best = np.full(len(iv), -np.inf)
            np.maximum.at(best, owner, vals)
            out[iv] = best > eps
        return out


# --------------------------------------------------------------------------------------
# Orientation
# --------------------------------------------------------------------------------------

def orient_consistently(F):
    """Flips faces so that neighbours across every 2-manifold edge agree, starting from the
    lowest-numbered face of each edge-connected component. Returns (F, component id)."""
    F = F.copy()
    nf = len(F)
    fe = F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    eid, cnt = edge_ids(fe)
    forward = fe[:, 0] < fe[:, 1]
    slots = np.nonzero(cnt[eid] == 2)[0]
    slots = slots[np.argsort(eid[slots], kind="stable")]
    s1, s2 = slots[0::2], slots[1::2]
    f1, f2 = s1 // 3, s2 // 3
    same = forward[s1] == forward[s2]
    # Adjacency lists (CSR) of (neighbour, must-differ flag).
    a = np.concatenate([f1, f2])
    b = np.concatenate([f2, f1])
    x = np.concatenate([same, same])
    order = np.argsort(a, kind="stable")
    a, b, x = a[order], b[order], x[order]
    start = np.searchsorted(a, np.arange(nf + 1))
    flip = np.zeros(nf, dtype=bool)
    seen = np.zeros(nf, dtype=bool)
    comp = np.full(nf, -1, dtype=np.int64)
    ncomp = 0
    # Level-synchronous BFS: one vectorised step per level, components in face order.
    for seed in range(nf):
        if seen[seed]:
            continue
        seen[seed] = True
        comp[seed] = ncomp
        frontier = np.array([seed])
        while frontier.size:
            st, en = start[frontier], start[frontier + 1]
            c = en - st
            src = np.repeat(frontier, c)
            pos = np.repeat(st - np.cumsum(c) + c, c) + np.arange(c.sum())
            nb, differ = b[pos], x[pos]
            new = ~seen[nb]
            nb, src, differ = nb[new], src[new], differ[new]
            nb, first = np.unique(nb, return_index=True)
            flip[nb] = flip[src[first]] ^ differ[first]
            seen[nb] = True
            comp[nb] = ncomp
            frontier = nb
        ncomp += 1
    F[flip] = F[flip][:, ::-1]
    return F, comp


# --------------------------------------------------------------------------------------
# Patches
# --------------------------------------------------------------------------------------

def _finite_array(value, shape_tail, what, where):
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(where, f"{what} is not a numeric array (null or non-finite values?)")
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != tuple(shape_tail):
        raise InputError(where, f"{what} has shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(where, f"{what} has non-finite values")
    return arr


def spline_profile(tool, s, d):
    """A spline cutter's d(s) from its coefficients (DESIGN.md: a cubic B-spline of 10
    coefficients on clamped uniform knots) when it reproduces the sampled radii d at s to
    1e-9 of their size; else None (another kind, or coefficients that disagree)."""
    if not isinstance(tool, dict) or tool.get("kind") != "spline":
        return None
    c = tool.get("coefficients")
    if not isinstance(c, list) or len(c) < 4:
        return None
    try:
        c = np.asarray(c, dtype=float)
    except (TypeError, ValueError):
        return None
    if c.ndim != 1 or not np.all(np.isfinite(c)):
        return None
    n = len(c)
    knots = np.concatenate(([0.0] * 4, np.arange(1, n - 3) / (n - 3), [1.0] * 4))
    spline = BSpline(knots, c, 3)
    if np.max(np.abs(spline(s) - d)) <= 1e-9 * max(1.0, float(np.max(np.abs(d)))):
        return spline
    return None


class Patch:
    """One patch rebuilt from its JSON: the motion a(t), b(t) and the radii d(s)."""

    def __init__(self, p, index, where):
        if not isinstance(p, dict):
            raise InputError(where, f"patches[{index}] is not an object")
        try:
            tool, motion = p["tool"], p["motion"]
            radii = tool["radii"]
            s, d = radii["s"], radii["d"]
            knots, ca, cb = motion["knots"], motion["a"], motion["b"]
        except (KeyError, TypeError) as exc:
            raise InputError(where, f"patches[{index}] lacks {exc}")
        tag = f"patches[{index}]"
        self.id = p.get("id", index)
        self.kind = tool.get("kind")
        self.length = tool.get("length")
        self.s = _finite_array(s, (), f"{tag}.tool.radii.s", where)
        self.d = _finite_array(d, (), f"{tag}.tool.radii.d", where)
        if len(self.s) != len(self.d) or len(self.s) < 4:
            raise InputError(where, f"{tag}.tool.radii: s and d need the same length >= 4")
        if np.any(np.diff(self.s) <= 0) or abs(self.s[0]) > 1e-12 or abs(self.s[-1] - 1) > 1e-12:
            raise InputError(where, f"{tag}.tool.radii.s must increase from 0 to 1")
        self.knots = _finite_array(knots, (), f"{tag}.motion.knots", where)
        self.ca = _finite_array(ca, (3,), f"{tag}.motion.a", where)
        self.cb = _finite_array(cb, (3,), f"{tag}.motion.b", where)
        K = len(self.ca)
        if K < 4 or len(self.cb) != K or len(self.knots) != K + 4:
            raise InputError(where, f"{tag}.motion: need K >= 4 control points in a and b and "
                                    f"K+4 knots (a {len(self.ca)}, b {len(self.cb)}, "
                                    f"knots {len(self.knots)})")
        if np.any(np.diff(self.knots) < 0) or not self.knots[K] > self.knots[3]:
            raise InputError(where, f"{tag}.motion.knots must be non-decreasing with a "
                                    "non-empty parameter range")
        self.t0, self.t1 = float(self.knots[3]), float(self.knots[K])
        self.A = BSpline(self.knots, self.ca, 3)
        self.B = BSpline(self.knots, self.cb, 3)
        self.dA, self.dB = self.A.derivative(), self.B.derivative()
        self.radius = CubicSpline(self.s, self.d)  # not-a-knot: exact for cubics
        # A spline cutter's d(s) is a cubic B-spline with knots inside (0, 1): the not-a-knot
        # interpolation of its 101 samples is off near those knots by up to half a percent of
        # the tolerance in Ω's position. Its coefficients give it exactly, when they agree
        # with the samples (which stay the contract).
        exact = spline_profile(tool, self.s, self.d)
        if exact is not None:
            self.radius = exact
        self.dradius = self.radius.derivative()
        err = p.get("error") or {}
        cov = p.get("coverage") or {}
        self.claimed_max = err.get("max")
        self.claimed_gouge = err.get("max_gouge")
        self.claimed_coverage = cov.get("fraction")

    def params(self, rows):
        return np.linspace(self.t0, self.t1, rows)

    def axis(self, t, s):
        """R(t,s), shape (len t, len s, 3)."""
        S = np.asarray(s)[None, :, None]
        return (1 - S) * self.A(t)[:, None, :] + S * self.B(t)[:, None, :]


def envelope(patch, t, s):
    """Both envelope points of the sphere family at the grid (t x s).

    Returns R, P_plus, P_minus (each (nt, ns, 3)) and valid (nt, ns)."""
    t, s = np.asarray(t, float), np.asarray(s, float)
    a, b = patch.A(t), patch.B(t)
    da, db = patch.dA(t), patch.dB(t)
    d, dd = patch.radius(s), patch.dradius(s)
    S = s[None, :, None]
    R = (1 - S) * a[:, None, :] + S * b[:, None, :]
    Rt = (1 - S) * da[:, None, :] + S * db[:, None, :]
    w = (b - a)[:, None, :]
    Lw = np.linalg.norm(w, axis=2)                               # (nt, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        e1 = w / Lw[..., None]
        vpar = np.sum(Rt * e1, axis=2)                           # (nt, ns)
        vt = Rt - vpar[..., None] * e1
        m = np.linalg.norm(vt, axis=2)
        x = -dd[None, :] / Lw
        y = -x * vpar / m
        z2 = 1.0 - x * x - y * y
        # "Does not move across itself": the cross-axis speed is round-off of the scale.
        moving = m > 1e-10 * (Lw + np.linalg.norm(Rt, axis=2))
        valid = (Lw > 0) & moving & (z2 > 0) & (d[None, :] >= 0)
        e2 = vt / m[..., None]
        e3 = np.cross(np.broadcast_to(e1, e2.shape), e2)
        z = np.sqrt(np.where(valid, z2, 0.0))
        base = x[..., None] * e1 + y[..., None] * e2
        Pp = R + d[None, :, None] * (base + z[..., None] * e3)
        Pm = R + d[None, :, None] * (base - z[..., None] * e3)
    valid &= np.all(np.isfinite(Pp), axis=2) & np.all(np.isfinite(Pm), axis=2)
    return R, Pp, Pm, valid


def local_extremes(phi, p, t, s, E, eps, top=8):
    """max |e| and max gouge on 9 x 9 sub-grids spanning one sample each way around the `top`
    counted samples of largest |e| (E: rows x cols, NaN where not counted)."""
    flat = np.where(np.isnan(E), -1.0, np.abs(E)).reshape(-1)
    order = np.argsort(-flat, kind="stable")[:top]
    rows, cols = E.shape
    best_abs, best_gouge = None, None
    for k in order:
        if flat[k] < 0:
            break
        i, j = divmod(int(k), cols)
        tl = np.linspace(t[max(i - 1, 0)], t[min(i + 1, rows - 1)], 9)
        sl = np.linspace(s[max(j - 1, 0)], s[min(j + 1, cols - 1)], 9)
        _, Pp, Pm, valid = envelope(p, tl, sl)
        v = valid.reshape(-1)
        if not v.any():
            continue
        _, Pc, q = phi.query_closer(Pp.reshape(-1, 3)[v], Pm.reshape(-1, 3)[v])
        ok = ~phi.beyond_boundary(Pc, q, eps)
        if not ok.any():
            continue
        e = (phi.sign(Pc, q) * q["dist"])[ok]
        a, g = float(np.max(np.abs(e))), float(max(0.0, np.max(-e)))
        best_abs = a if best_abs is None else max(best_abs, a)
        best_gouge = g if best_gouge is None else max(best_gouge, g)
    return best_abs, best_gouge


def grid_triangles(rows, cols, valid):
    """Two triangles per grid cell whose four corners are valid (vertex id i*cols+j)."""
    i, j = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    v00 = (i * cols + j).reshape(-1)
    v10, v01, v11 = v00 + cols, v00 + 1, v00 + cols + 1
    vf = valid.reshape(-1)
    ok = vf[v00] & vf[v10] & vf[v01] & vf[v11]
    v00, v10, v01, v11 = v00[ok], v10[ok], v01[ok], v11[ok]
    return np.concatenate([np.stack([v00, v10, v11], 1), np.stack([v00, v11, v01], 1)])


def swept_depth(P, R, d, block=64):
    """How deep each point of P (m,3) lies inside the union of the sampled spheres
    (centres R (N,3), radii d (N,)): max(0, -min_k (|P - R_k| - d_k)).

    Sound but not complete: a positive depth proves the point is inside the swept volume
    (so it is not on the machined surface); sampling can only miss some depth."""
    out = np.empty(len(P))
    for lo in range(0, len(P), block):
        diff = P[lo:lo + block, None, :] - R[None, :, :]
        f = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff)) - d[None, :]
        out[lo:lo + block] = np.maximum(0.0, -f.min(axis=1))
    return out


def max_abs_exposed(e, P, R, d, tol, cap=2048):
    """Largest |e| over envelope points that are not inside the swept volume.

    An envelope point with e > 0 that another sphere of the sweep contains (for example
    where the motion stalls and reverses) is cut away: it is not part of the machined
    surface, so it is skipped. e < 0 always stays: the sweep does reach behind Phi there.
    Points are examined in order of decreasing e, at most `cap` of them; the result is
    then an upper bound (second value False)."""
    gouge = float(max(0.0, np.max(-e))) if e.size else 0.0
    pos = np.nonzero(e > gouge)[0]
    pos = pos[np.argsort(-e[pos], kind="stable")][:cap]
    eps = 1e-3 * tol
    for lo in range(0, len(pos), 64):
        idx = pos[lo:lo + 64]
        exposed = swept_depth(P[idx], R, d) <= eps
        if np.any(exposed):
            return float(e[idx[np.argmax(exposed)]]), True
    if len(pos) == 0:
        return gouge, True
    if np.count_nonzero(e > gouge) > cap:
        return float(e[pos[-1]]), False
    return gouge, True


# --------------------------------------------------------------------------------------
# The check
# --------------------------------------------------------------------------------------

def load_patches(path):
    try:
        with open(path, "rb") as f:
            text = f.read()
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc.strerror or exc})")
    try:
        data = json.loads(text.decode("utf-8"))
    except (ValueError, UnicodeDecodeError) as exc:
        raise InputError(path, f"bad JSON ({exc})")
    if not isinstance(data, dict):
        raise InputError(path, "top level is not a JSON object")
    if data.get("format") != "flank-patches/1":
        raise InputError(path, f"format is {data.get('format')!r}, expected 'flank-patches/1'")
    cov = data.get("coverage")
    tol = cov.get("tolerance") if isinstance(cov, dict) else None
    if not isinstance(tol, (int, float)) or isinstance(tol, bool) or not math.isfinite(tol) \
            or tol <= 0:
        raise InputError(path, f"coverage.tolerance is {json.dumps(tol)}, expected a positive "
                               "number")
    plist = data.get("patches")
    if not isinstance(plist, list):
        raise InputError(path, "patches is not a list")
    patches = [Patch(p, i, path) for i, p in enumerate(plist)]
    return data, patches, float(tol)


def resolve_mesh_path(data, json_path, mesh_path):
    """--mesh wins; else input.path as written (relative to our cwd), else relative to the
    folder of patches.json (flank may have run elsewhere)."""
    if mesh_path:
        return mesh_path
    inp = data.get("input")
    p = inp.get("path") if isinstance(inp, dict) else None
    if not isinstance(p, str) or not p:
        raise InputError(json_path, "input.path is missing (pass --mesh)")
    if os.path.isabs(p) or os.path.exists(p):
        return p
    alt = os.path.join(os.path.dirname(os.path.abspath(json_path)), p)
    return alt if os.path.exists(alt) else p


def _num(x):
    """JSON-safe float (None for missing or non-finite)."""
    if x is None or isinstance(x, bool):
        return None
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def claim_agrees(r, tol):
    """Whether the solver's claimed max error matches ours (the exposed one: the solver
    measures the machined surface). Sampling differs (our grid vs the solver's), so
    agreement means within 10% of the tolerance plus 10% of the larger value."""
    ours, claim = r["max_abs_exposed"], r["claimed_max"]
    if ours is None or claim is None:
        return None
    return abs(ours - claim) <= 0.1 * tol + 0.1 * max(ours, claim)


def check(patches_json_path, mesh_path=None, rows=400, cols=101):
    """Judges patches.json against its mesh. See the module docstring for definitions."""
    if rows < 2 or cols < 2:
        raise ValueError("rows and cols must be at least 2")
    clock = time.perf_counter()
    timing = {}
    data, patches, tol = load_patches(patches_json_path)
    mpath = resolve_mesh_path(data, patches_json_path, mesh_path)
    V, F = read_mesh(mpath)
    F, comp = orient_consistently(F)
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    eps = 1e-9 * diag
    try:
        phi = TriMesh(V, F, pseudo_normals=True)
    except ValueError as exc:  # no triangle of positive area
        raise InputError(mpath, str(exc))
    timing["mesh"] = time.perf_counter() - clock

    # Global orientation, per edge-connected component: tools live on the positive side.
    flipped = 0
    if patches:
        Rs = np.concatenate([p.axis(p.params(21), np.linspace(0, 1, 11)).reshape(-1, 3)
                             for p in patches])
        q = phi.query(Rs)
        sgn = phi.sign(Rs, q)
        counted = ~phi.beyond_boundary(Rs, q, eps)
        if not np.any(counted):
            counted[:] = True
        fc = comp[q["face"][counted]]
        votes = np.bincount(fc, weights=sgn[counted], minlength=comp.max() + 1)
        flip_comp = votes < 0
        if np.any(flip_comp):
            flipped = int(flip_comp.sum())
            fl = flip_comp[comp]
            F = F.copy()
            F[fl] = F[fl][:, ::-1]
            phi = TriMesh(V, F, pseudo_normals=True)
    timing["orient"] = time.perf_counter() - clock - sum(timing.values())

    # Vertex areas (1/3 of each incident triangle).
    varea = np.zeros(len(V))
    np.add.at(varea, F.reshape(-1), np.repeat(phi.area / 3.0, 3))
    total_area = float(phi.area.sum())
    qverts = np.nonzero(varea > 0)[0]
    # Area-weighted vertex normals of the oriented Phi (for the sign seen from a vertex).
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    vnormal = np.zeros((len(V), 3))
    for k in range(3):
        np.add.at(vnormal, F[:, k], fn)
    vnormal /= np.maximum(np.linalg.norm(vnormal, axis=1, keepdims=True), 1e-300)

    s = np.linspace(0.0, 1.0, cols)
    results, omegas, counted_mask = [], [], []
    for p in patches:
        t = p.params(rows)
        R, Pp, Pm, valid = envelope(p, t, s)
        flat_valid = valid.reshape(-1)
        iv = np.nonzero(flat_valid)[0]
        P = np.zeros((rows * cols, 3))
        e = np.full(rows * cols, np.nan)
        good = np.zeros(rows * cols, dtype=bool)
        cnt = 0
        stats = {"max_abs": None, "rms": None, "max_gouge": None}
        if iv.size:
            PA, PB = Pp.reshape(-1, 3)[iv], Pm.reshape(-1, 3)[iv]
            # The side closer to Phi, point by point.
            _, Pc, q = phi.query_closer(PA, PB)
            ec = phi.sign(Pc, q) * q["dist"]
            cnt_mask = ~phi.beyond_boundary(Pc, q, eps)
            P[iv] = Pc
            e[iv] = np.where(cnt_mask, ec, np.nan)
            good[iv] = ~cnt_mask | (np.abs(ec) <= 2.0 * tol)
            cnt = int(cnt_mask.sum())
            if cnt:
                ecnt = ec[cnt_mask]
                stats = {"max_abs": float(np.max(np.abs(ecnt))),
                         "rms": float(np.sqrt(np.mean(ecnt * ecnt))),
                         "mean": float(np.mean(ecnt)),
                         "max_gouge": float(max(0.0, np.max(-ecnt)))}
                # Diagnostics: the worst point, and the worst that is really machined.
                Rall = R.reshape(-1, 3)[iv]
                dall = np.broadcast_to(p.radius(s)[None, :], (rows, cols)).reshape(-1)[iv]
                ci = np.nonzero(cnt_mask)[0]
                w = ci[np.argmax(np.abs(ecnt))]
                stats["worst"] = {"t": float(t[iv[w] // cols]), "s": float(s[iv[w] % cols]),
                                  "e": float(ec[w]),
                                  "swept_depth": float(swept_depth(Pc[w:w + 1], Rall, dall)[0])}
                stats["max_abs_exposed"], stats["exposed_exact"] = max_abs_exposed(
                    ecnt, Pc[ci], Rall, dall, tol)
                # The sup over Omega, not over this grid: search 9 x 9 sub-grids (eighth steps)
                # around the largest samples, so the figure does not depend on the sampling.
                lmax, lgouge = local_extremes(phi, p, t, s, e.reshape(rows, cols), eps, top=8)
                for key, val in (("max_abs", lmax), ("max_abs_exposed", lmax), ("max_gouge", lgouge)):
                    if val is not None and stats.get(key) is not None:
                        stats[key] = max(stats[key], val)
        # The cutter must be rigid: |b(t) - a(t)| should stay the tool length.
        L = _num(p.length)
        ab = np.linalg.norm(p.B(t) - p.A(t), axis=1)
        drift = float(np.max(np.abs(ab - L))) if L is not None else None
        results.append({
            "id": p.id, "kind": p.kind,
            "max_abs": stats["max_abs"], "rms": stats["rms"], "max_gouge": stats["max_gouge"],
            "mean": stats.get("mean"),
            "counted": cnt, "valid": int(iv.size), "samples": rows * cols,
            "max_abs_exposed": stats.get("max_abs_exposed"),
            "exposed_exact": stats.get("exposed_exact"),
            "worst": stats.get("worst"),
            "within_tolerance": (stats["max_abs"] is not None and stats["max_abs"] <= tol),
            "claimed_max": _num(p.claimed_max), "claimed_gouge": _num(p.claimed_gouge),
            "claimed_coverage": _num(p.claimed_coverage),
            "length_drift": drift,
        })
        results[-1]["claim_agrees"] = claim_agrees(results[-1], tol)
        omegas.append((P, flat_valid, good, e))
        counted_mask.append(~np.isnan(e))
    timing["envelopes"] = time.perf_counter() - clock - sum(timing.values())

    # Coverage: per patch, each Phi vertex's closest point on that patch's Omega.
    nP = len(patches)
    dist = np.full((nP, len(qverts)), np.inf)
    ok = np.zeros((nP, len(qverts)), dtype=bool)
    ok_ab = np.zeros((nP, len(qverts)), dtype=bool)  # rules (a) and (b) only
    X = V[qverts]
    for i, (P, fvalid, good, e) in enumerate(omegas):
        T = grid_triangles(rows, cols, fvalid)
        if len(T) == 0:
            continue
        try:
            om = TriMesh(P, T)
        except ValueError:  # Omega collapsed to zero area
            continue
        # Phi's vertices as seen from Omega (see the module docstring): within 10 tol, over
        # the cells of Omega that lie over Phi.
        band = 10.0 * tol
        Tc = grid_triangles(rows, cols, fvalid & counted_mask[i])
        try:
            omc = TriMesh(P, Tc) if len(Tc) else None
        except ValueError:
            omc = None
        qv_c = omc.query(X, limit=band) if omc is not None else None
        sel = (np.nonzero(qv_c["exact"] & (qv_c["dist"] <= band))[0] if qv_c is not None
               else np.zeros(0, dtype=np.int64))
        if sel.size:
            qs = {key: v[sel] for key, v in qv_c.items()}
            along = np.sum((qs["foot"] - X[sel]) * vnormal[qverts[sel]], axis=1)
            inside_v = ~omc.on_boundary(qs) & (np.abs(along) >= math.cos(math.radians(30.0)) * qs["dist"])
            ev = np.sign(along) * qs["dist"]
            ev = np.where(ev == 0.0, qs["dist"], ev)[inside_v]
            if ev.size:
                r_ = results[i]
                vmax, vgouge = float(np.max(np.abs(ev))), float(max(0.0, np.max(-ev)))
                r_["max_abs_vertices"] = vmax
                for key, val in (("max_abs", vmax), ("max_abs_exposed", vmax), ("max_gouge", vgouge)):
                    r_[key] = val if r_[key] is None else max(r_[key], val)
                r_["within_tolerance"] = r_["max_abs"] <= tol
                r_["claim_agrees"] = claim_agrees(r_, tol)
        # Cheap pre-filter: only vertices that may be within tolerance are queried.
        q = om.query(X, limit=tol)
        near = np.nonzero(q["lb"] <= tol)[0]
        q = {key: v[near] for key, v in q.items()}
        face_good = good[T].all(axis=1)
        edge_good = np.bincount(om.edge_id.reshape(-1), weights=np.repeat(face_good, 3),
                                minlength=om.n_edges) > 0
        vert_good = np.bincount(T.reshape(-1), weights=np.repeat(face_good, 3),
                                minlength=len(P)) > 0
        f, r = q["face"], om.snap_region(q, eps).astype(np.int64)
        feat_good = face_good[f].copy()
        sel = (r >= 1) & (r <= 3)
        feat_good[sel] = edge_good[om.edge_id[f[sel], r[sel] - 1]]
        sel = r >= 4
        feat_good[sel] = vert_good[T[f[sel], r[sel] - 4]]
        inside = ~om.beyond_boundary(X[near], q, eps)
        dist[i, near] = np.where(q["exact"], q["dist"], np.maximum(q["lb"], np.nextafter(tol, 1)))
        ok_ab[i, near] = q["exact"] & (q["dist"] <= tol) & inside
        ok[i, near] = ok_ab[i, near] & feat_good
        results[i]["coverage_alone"] = float(np.sum(varea[qverts][ok[i]]) / total_area)
    for r_ in results:
        r_.setdefault("coverage_alone", 0.0)
    tie = 1e-12 * max(diag, 1e-300)
    qarea = varea[qverts]

    def covered_fraction(okk, k):
        best = dist[:k].min(axis=0)
        covered = (best <= tol) & np.any(okk[:k] & (dist[:k] <= best + tie), axis=0)
        return float(np.sum(qarea[covered]) / total_area)

    curve = [covered_fraction(ok, k) for k in range(1, nP + 1)]
    curve_ab = [covered_fraction(ok_ab, k) for k in range(1, nP + 1)]
    timing["coverage"] = time.perf_counter() - clock - sum(timing.values())
    timing["total"] = time.perf_counter() - clock

    cov = data.get("coverage") or {}
    return {
        "patches_json": patches_json_path,
        "mesh": {"path": mpath, "vertices": int(len(V)), "triangles": int(len(F)),
                 "bbox_diagonal": diag, "components": int(comp.max() + 1),
                 "components_flipped": flipped},
        "tolerance": tol,
        "area": total_area,
        "coverage": curve[-1] if curve else 0.0,
        "coverage_curve": curve,
        # Without rule (c) (the triangle's vertices within twice the tolerance).
        "coverage_ab": curve_ab[-1] if curve_ab else 0.0,
        "coverage_curve_ab": curve_ab,
        "claimed_coverage": _num(cov.get("fraction")),
        "rows": rows, "cols": cols,
        "patches": results,
        "timing_s": timing,
    }


# --------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------

def _fmt(x, spec=".3g"):
    return "-" if x is None else format(x, spec)


def summary(res):
    tol = res["tolerance"]
    m = res["mesh"]
    lines = [f"{res['patches_json']}: mesh {m['path']} ({m['vertices']} vertices, "
             f"{m['triangles']} triangles, area {res['area']:.6g}"
             + (f", {m['components_flipped']} component(s) flipped" if m["components_flipped"]
                else "") + ")",
             f"tolerance {tol:.6g}, grid {res['rows']} x {res['cols']} per patch; "
             "exposed = max|e| without envelope points inside the swept volume",
             f"{'id':>4} {'kind':<8} {'max|e|':>9} {'exposed':>9} {'rms':>9} {'gouge':>9} "
             f"{'counted':>7} | {'claim max':>9} {'gouge':>9} | {'cov':>6} {'claim':>6}"]
    notes = []
    for p in res["patches"]:
        mark = ""
        if not p["within_tolerance"]:
            mark += " OUT-OF-TOL"
        if p["claim_agrees"] is False:
            mark += " CLAIM-DIFFERS"
        lines.append(f"{str(p['id']):>4} {str(p['kind']):<8} {_fmt(p['max_abs']):>9} "
                     f"{_fmt(p['max_abs_exposed']):>9} {_fmt(p['rms']):>9} "
                     f"{_fmt(p['max_gouge']):>9} {p['counted']:>7} | "
                     f"{_fmt(p['claimed_max']):>9} {_fmt(p['claimed_gouge']):>9} | "
                     f"{_fmt(p['coverage_alone'], '.4f'):>6} "
                     f"{_fmt(p['claimed_coverage'], '.4f'):>6}{mark}")
        w = p.get("worst")
        if w and p["max_abs"] is not None and p["max_abs"] > tol:
            notes.append(f"  patch {p['id']}: worst e {w['e']:.4g} at t={w['t']:.4f} "
                         f"s={w['s']:.3f}" + (f", {w['swept_depth']:.3g} inside the swept "
                                               "volume (not machined)"
                                               if w["swept_depth"] > 1e-3 * tol else ""))
    lines += notes
    lines.append(f"coverage {res['coverage']:.4f}; after 1..n patches: "
                 + " ".join(f"{c:.4f}" for c in res["coverage_curve"]))
    lines.append(f"coverage by distance alone (rules a, b) {res['coverage_ab']:.4f} "
                 f"(claimed {_fmt(res['claimed_coverage'], '.4f')})")
    lines.append(f"checked in {res['timing_s']['total']:.1f} s")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description="Independent check of flank's patches.json.")
    ap.add_argument("patches_json")
    ap.add_argument("--mesh", help="input mesh (default: input.path from the file)")
    ap.add_argument("--rows", type=int, default=400, help="samples in t per patch (400)")
    ap.add_argument("--cols", type=int, default=101, help="samples in s per patch (101)")
    ap.add_argument("--json", action="store_true", help="print the result as JSON")
    args = ap.parse_args(argv)
    if args.rows < 2 or args.cols < 2:
        print(f"{sys.argv[0]}: --rows and --cols must be at least 2", file=sys.stderr)
        return 2
    try:
        res = check(args.patches_json, args.mesh, args.rows, args.cols)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(res, indent=1))
    else:
        print(summary(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
