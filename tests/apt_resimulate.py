#!/usr/bin/env python3
"""Re-simulate toolpath.apt and check it machines the surface Omega (independent of flank).

The tool is rebuilt from the CUTTER/ statement alone, as a post-processor or a CAM verifier
would: APT's CUTTER/d,r,e,f,alpha,beta,h with r = e = f = alpha = 0 is a flat-ended cone whose
end face (diameter d) is centred on the CL point, whose side widens by tan(beta) per mm toward
the spindle and whose flutes are h long. Each GOTO/x,y,z,i,j,k puts the end face's centre at
x,y,z with the unit axis i,j,k toward the spindle; between consecutive GOTOs the CL point and
the axis move linearly (the axis renormalised), as a 5-axis machine does, sub-sampled finely
enough that the sampling error is at most 1/50 of the tolerance (below).

Omega is read from envelopes.ply (binary little-endian PLY; vertex x, y, z as float or double,
optional int `patch`): the k-th CUTTER/ block machines the vertices of the k-th patch id in the
order the file first lists them (all vertices when there is no `patch` property). Every point
must lie on the swept tool's surface:
  - on the surface: |min over tool positions of the signed distance from the point to the
    cone's side| <= tolerance (negative inside the tool);
  - no gouge: the point lies at most `tolerance` inside any one tool position (depth below the
    side, the end face or the flutes' far end, whichever is nearest).

Sampling: the distance from a point to the moving tool is a smooth function of the motion
parameter whose curvature is at most v^2 / rho, v the speed of the tool's surface and rho its
smallest radius of curvature (at least the cone's smallest radius). Samples no more than delta
of surface displacement apart therefore find its minimum within delta^2 / (8 rho); delta is
chosen so that this is tolerance / 50, with the displacement bounded by |dCL| + |dAxis| (h + R).

Usage: apt_resimulate.py TOOLPATH.apt ENVELOPES.ply --tolerance MM [--max-points N]
Prints a summary line per block; exit 0 when every point holds, 1 when one does not, 2 on bad
input.
"""

import argparse
import math
import sys

import numpy as np

PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "<i2",
             "int16": "<i2", "ushort": "<u2", "uint16": "<u2", "int": "<i4", "int32": "<i4",
             "uint": "<u4", "uint32": "<u4", "float": "<f4", "float32": "<f4",
             "double": "<f8", "float64": "<f8"}


class BadInput(Exception):
    pass


def numbers(text, what):
    try:
        return [float(v) for v in text.split(",")]
    except ValueError:
        raise BadInput(f"{what}: not a list of numbers")


def read_apt(path):
    """The blocks of an APT CL file: [{'cutter': [7 numbers], 'cl': (n,3), 'axis': (n,3)}]."""
    blocks, units = [], None
    with open(path, encoding="ascii", errors="replace") as f:
        for number, raw in enumerate(f, 1):
            line = raw.strip()
            where = f"{path}:{number}"
            if not line or line.startswith("$$"):
                continue
            word, _, rest = line.partition("/")
            word = word.strip().upper()
            if word == "UNITS":
                units = rest.strip().upper()
            elif word == "CUTTER":
                params = numbers(rest, where)
                if len(params) != 7:
                    raise BadInput(f"{where}: CUTTER/ needs 7 parameters d,r,e,f,alpha,beta,h")
                blocks.append({"cutter": params, "goto": []})
            elif word == "GOTO":
                if not blocks:
                    raise BadInput(f"{where}: GOTO/ before any CUTTER/")
                v = numbers(rest, where)
                if len(v) != 6:
                    raise BadInput(f"{where}: GOTO/ needs x,y,z,i,j,k (5-axis CL data)")
                blocks[-1]["goto"].append(v)
            elif word in ("PARTNO", "MULTAX", "FINI"):
                continue
            else:
                raise BadInput(f"{where}: statement {word} is not handled")
    if units != "MM":
        raise BadInput(f"{path}: no UNITS/MM")
    for b in blocks:
        g = np.array(b.pop("goto"), dtype=float).reshape(-1, 6)
        if len(g) < 2:
            raise BadInput(f"{path}: a CUTTER/ block with {len(g)} GOTO/")
        norm = np.linalg.norm(g[:, 3:], axis=1)
        if np.any(np.abs(norm - 1.0) > 1e-5):
            raise BadInput(f"{path}: a tool axis i,j,k is not a unit vector (|ijk| = {norm.min()}..{norm.max()})")
        b["cl"], b["axis"] = g[:, :3], g[:, 3:] / norm[:, None]
    if not blocks:
        raise BadInput(f"{path}: no CUTTER/ block")
    return blocks


def read_ply_vertices(path):
    """x, y, z (n,3) and the `patch` ids (n,) or None of a binary little-endian PLY."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise BadInput(f"{path}: not a PLY file")
    header = data[:end].decode("ascii", "replace").splitlines()
    if "format binary_little_endian 1.0" not in header:
        raise BadInput(f"{path}: only binary little-endian PLY is read")
    count, fields, element = None, [], None
    for line in header:
        parts = line.split()
        if parts[:1] == ["element"]:
            element = parts[1]
            if element == "vertex":
                count = int(parts[2])
        elif parts[:1] == ["property"] and element == "vertex":
            if parts[1] == "list" or parts[1] not in PLY_TYPES:
                raise BadInput(f"{path}: vertex property '{line}' is not handled")
            fields.append((parts[2], PLY_TYPES[parts[1]]))
        elif element is None and parts[:1] == ["property"]:
            raise BadInput(f"{path}: property before any element")
    if count is None:
        raise BadInput(f"{path}: no vertex element")
    names = [n for n, _ in fields]
    if not all(k in names for k in ("x", "y", "z")):
        raise BadInput(f"{path}: vertices have no x, y, z")
    dtype = np.dtype(fields)
    body = end + len(b"end_header\n")
    if len(data) < body + count * dtype.itemsize:
        raise BadInput(f"{path}: truncated vertex data")
    v = np.frombuffer(data, dtype=dtype, count=count, offset=body)
    xyz = np.stack([v["x"], v["y"], v["z"]], axis=1).astype(float)
    patch = v["patch"].astype(int) if "patch" in names else None
    return xyz, patch


def cone(cutter, where):
    d, r, e, f, alpha, beta, h = cutter
    if r != 0 or e != 0 or f != 0 or alpha != 0:
        raise BadInput(f"{where}: only flat-ended cones (r = e = f = alpha = 0) are simulated")
    if not (d > 0 and h > 0 and abs(beta) < 90):
        raise BadInput(f"{where}: CUTTER/ with d = {d}, beta = {beta}, h = {h}")
    r0 = d / 2
    r1 = r0 + h * math.tan(math.radians(beta))
    if not r1 > 0:
        raise BadInput(f"{where}: the cone closes before its flutes end (radius {r1} at h)")
    return r0, r1, h


def positions(cl, axis, r0, r1, h, tolerance):
    """Tool positions sampled along the linear moves between GOTOs, and the sampling bound."""
    rho = min(r0, r1)
    delta = math.sqrt(8.0 * rho * tolerance / 50.0)
    reach = h + max(r0, r1)
    move = np.linalg.norm(np.diff(cl, axis=0), axis=1) + np.linalg.norm(np.diff(axis, axis=0), axis=1) * reach
    steps = np.maximum(1, np.ceil(move / delta).astype(int))
    P, U = [cl[:1]], [axis[:1]]
    for k, m in enumerate(steps):
        w = (np.arange(1, m + 1) / m)[:, None]
        P.append((1 - w) * cl[k] + w * cl[k + 1])
        u = (1 - w) * axis[k] + w * axis[k + 1]
        U.append(u / np.linalg.norm(u, axis=1, keepdims=True))
    return np.concatenate(P), np.concatenate(U), delta * delta / (8.0 * rho)


def check_block(points, P, U, r0, r1, h, chunk_entries=500_000):
    """Per point: min over positions of the signed distance to the side, max depth inside."""
    length = math.hypot(h, r1 - r0)
    tz, tr = h / length, (r1 - r0) / length  # unit side direction in the (w, rho) plane
    origin = points.mean(axis=0)  # small coordinates keep |v|^2 - w^2 accurate
    points, P = points - origin, P - origin
    PU, PP = np.einsum("mk,mk->m", P, U), np.einsum("mk,mk->m", P, P)
    min_side = np.empty(len(points))
    max_depth = np.empty(len(points))
    step = max(1, chunk_entries // max(1, len(P)))
    for start in range(0, len(points), step):
        p = points[start:start + step]
        w = p @ U.T - PU                                   # along the axis from the end face
        vv = np.einsum("nk,nk->n", p, p)[:, None] - 2.0 * (p @ P.T) + PP
        rho = np.sqrt(np.maximum(0.0, vv - w * w))         # from the axis
        lam = np.clip(w * tz + (rho - r0) * tr, 0.0, length)
        dist = np.hypot(w - lam * tz, rho - (r0 + lam * tr))
        inside = (w >= 0) & (w <= h) & (rho < r0 + (r1 - r0) * w / h)
        min_side[start:start + step] = np.where(inside, -dist, dist).min(axis=1)
        depth = np.where(inside, np.minimum(np.minimum(dist, w), h - w), 0.0)
        max_depth[start:start + step] = depth.max(axis=1)
    return min_side, max_depth


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("apt")
    ap.add_argument("ply")
    ap.add_argument("--tolerance", type=float, required=True, help="mm")
    ap.add_argument("--max-points", type=int, default=0,
                    help="check at most this many points per block, evenly spread (0: all)")
    a = ap.parse_args(argv)
    try:
        if not (a.tolerance > 0 and math.isfinite(a.tolerance)):
            raise BadInput(f"--tolerance {a.tolerance}: must be positive")
        blocks = read_apt(a.apt)
        xyz, patch = read_ply_vertices(a.ply)
        if patch is None:
            groups = [np.arange(len(xyz))] * len(blocks)
        else:
            ids = list(dict.fromkeys(patch.tolist()))
            if len(ids) != len(blocks):
                raise BadInput(f"{a.ply} has {len(ids)} patches, {a.apt} {len(blocks)} CUTTER/ blocks")
            groups = [np.flatnonzero(patch == i) for i in ids]
        ok = True
        for k, (block, group) in enumerate(zip(blocks, groups)):
            r0, r1, h = cone(block["cutter"], f"{a.apt} block {k}")
            pts = xyz[group]
            pts = pts[np.all(np.isfinite(pts), axis=1)]
            if a.max_points and len(pts) > a.max_points:
                pts = pts[np.linspace(0, len(pts) - 1, a.max_points).astype(int)]
            if len(pts) == 0:
                raise BadInput(f"block {k}: no finite points of Omega")
            P, U, sampling = positions(block["cl"], block["axis"], r0, r1, h, a.tolerance)
            min_side, max_depth = check_block(pts, P, U, r0, r1, h)
            off = np.abs(min_side)
            worst = int(np.argmax(off))
            fails = int(np.count_nonzero(off > a.tolerance)) + int(np.count_nonzero(max_depth > a.tolerance))
            ok &= fails == 0
            print(f"[ apt_resimulate ] block {k}: cone d {2 * r0:.6f} -> {2 * r1:.6f} over h {h:.6f}, "
                  f"{len(block['cl'])} GOTOs, {len(P)} positions (sampling error <= {sampling:.2e}), "
                  f"{len(pts)} points: max |distance to the swept side| {off.max():.3e} "
                  f"(at {np.array2string(pts[worst], precision=4)}), max depth inside a tool "
                  f"{max_depth.max():.3e}, tolerance {a.tolerance:.3e}: "
                  + ("ok" if fails == 0 else f"FAIL ({fails} violations)"))
        return 0 if ok else 1
    except (BadInput, OSError) as e:
        print(f"apt_resimulate: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
