#!/usr/bin/env python3
"""Independent check of flank's patches.step against Ω rebuilt from patches.json.

Reads the STEP file's text (no OCCT, no flank code): every face's B-spline surface (poles,
knots with multiplicities) and the name of the product it belongs to (P<id>). Each face is
evaluated with SciPy on a grid of its own (t, s) domain (patches.json's nurbs.t_range and
s_range) that is not the grid it was fitted on, and measured against the exact envelope of its
patch rebuilt by tests/check_patches.py (the nearer of the two envelope points; a spline
cutter's profile from its coefficients). Reports the
largest distance per face, in mm and as a fraction of the tolerance.

Usage: check_step.py PATCHES_JSON [--step FILE] [--limit FRACTION] [--rows N] [--cols N]
Prints one line per face and a summary; exit 0 when every face is within LIMIT × tolerance
(default 0.01: the 1% patches.step promises), 1 when one is not, 2 on unreadable input.
"""

import argparse
import os
import re
import sys

import numpy as np
from scipy.interpolate import BSpline

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import check_patches  # noqa: E402  (the independent rebuild of Ω)

_ENTITY = re.compile(r"#(\d+)\s*=\s*([A-Z0-9_]+)\s*\((.*)\)\s*$", re.S)
_TOKEN = re.compile(r"\s*('(?:[^']|'')*'|#\d+|\.[A-Z0-9_]+\.|[A-Z_][A-Z0-9_]*|[-+0-9.Ee]+|\$|\*|[(),])")


def _parse_args(text):
    """A STEP parameter list as nested Python lists: '#n' refs stay strings, numbers float."""
    stack = [[]]
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m:
            if text[pos:].strip() == "":
                break
            raise ValueError(f"cannot read STEP parameters at {text[pos:pos + 30]!r}")
        tok = m.group(1)
        pos = m.end()
        if tok == "(":
            stack.append([])
        elif tok == ")":
            inner = stack.pop()
            stack[-1].append(inner)
        elif tok == ",":
            continue
        elif tok[0] == "'":
            stack[-1].append(tok[1:-1].replace("''", "'"))
        elif tok[0] in "#.$*" or tok[0].isalpha() or tok[0] == "_":  # refs, enums, typed values' keywords
            stack[-1].append(tok)
        else:
            stack[-1].append(float(tok))
    if len(stack) != 1:
        raise ValueError("unbalanced parentheses in STEP parameters")
    return stack[0]


def read_step_entities(path):
    with open(path, "r", encoding="latin-1") as f:
        text = f.read()
    at = text.find("DATA;")
    if at < 0:
        raise check_patches.InputError(path, "no DATA section")
    entities = {}
    for chunk in re.split(r";\s*\n", text[at + 5:]):
        m = _ENTITY.match(chunk.strip())
        if m:
            entities["#" + m.group(1)] = (m.group(2), _parse_args(m.group(3)))
    return entities


def _refs(value):
    if isinstance(value, list):
        for v in value:
            yield from _refs(v)
    elif isinstance(value, str) and value.startswith("#"):
        yield value


def named_surfaces(path):
    """{product name: scipy-evaluable surface (knots_u, knots_v, poles[nu, nv, 3])}."""
    ents = read_step_entities(path)
    referrers = {}
    for eid, (_, args) in ents.items():
        for r in _refs(args):
            referrers.setdefault(r, []).append(eid)

    def below(eid, kind):
        seen, todo, found = set(), [eid], []
        while todo:
            e = todo.pop()
            if e in seen or e not in ents:
                continue
            seen.add(e)
            if ents[e][0] == kind:
                found.append(e)
            todo.extend(_refs(ents[e][1]))
        return found

    out = {}
    for eid, (kind, args) in ents.items():
        if kind != "PRODUCT":
            continue
        name = args[0]
        # PRODUCT ← formation ← definition ← definition shape ← shape definition representation.
        layer = [eid]
        sdr = []
        for _ in range(6):
            layer = [r for e in layer for r in referrers.get(e, [])]
            sdr = [e for e in layer if ents[e][0] == "SHAPE_DEFINITION_REPRESENTATION"]
            if sdr:
                break
        if len(sdr) != 1:
            continue
        rep = ents[sdr[0]][1][1]
        surfaces = below(rep, "B_SPLINE_SURFACE_WITH_KNOTS")
        if len(surfaces) != 1:
            raise check_patches.InputError(path, f"product {name!r} has {len(surfaces)} B-spline surfaces")
        a = ents[surfaces[0]][1]
        du, dv, rows = int(a[1]), int(a[2]), a[3]
        poles = np.array([[ents[r][1][1] for r in row] for row in rows], dtype=float)
        ku = np.repeat(np.array(a[10], dtype=float), np.array(a[8], dtype=int))
        kv = np.repeat(np.array(a[11], dtype=float), np.array(a[9], dtype=int))
        if len(ku) != poles.shape[0] + du + 1 or len(kv) != poles.shape[1] + dv + 1:
            raise check_patches.InputError(path, f"face {name!r}: knots do not match its poles")
        out[name] = (ku, kv, du, dv, poles)
    return out


def evaluate(surface, u, v):
    ku, kv, du, dv, poles = surface
    Bu = BSpline.design_matrix(u, ku, du).toarray()
    Bv = BSpline.design_matrix(v, kv, dv).toarray()
    return np.einsum("ia,abc,jb->ijc", Bu, poles, Bv)


def faces_of(patches_json, step_path=None):
    """The named surfaces of patches.step (beside PATCHES_JSON unless STEP_PATH is given)."""
    return named_surfaces(step_path or os.path.join(os.path.dirname(patches_json), "patches.step"))


def face_name(pj, pid):
    """The name of patch `pid`'s face in patches.step: patches.json's nurbs.face, else P<id>."""
    return (pj.get("nurbs") or {}).get("face") or f"P{pid}"


def check(patches_json, step_path=None, rows=401, cols=81, faces=None):
    """Per patch id: the largest distance (mm) of its face from Ω at rows × cols parameters.
    `faces`: faces_of(...) already read, else the file is read here."""
    data, patches, tol = check_patches.load_patches(patches_json)
    faces = faces if faces is not None else faces_of(patches_json, step_path)
    result = {}
    for p, pj in zip(patches, data["patches"]):
        nurbs = pj.get("nurbs") or {}
        name = face_name(pj, p.id)
        if name not in faces:
            result[p.id] = None
            continue
        t0, t1 = nurbs.get("t_range", [0.0, 1.0])
        s0, s1 = nurbs.get("s_range", [0.0, 1.0])
        # Off the fit's own samples: offsets of a third of a step from the domain's ends.
        t = t0 + (t1 - t0) * np.clip((np.arange(rows) + 1.0 / 3.0) / rows, 0.0, 1.0)
        s = s0 + (s1 - s0) * np.clip((np.arange(cols) + 1.0 / 3.0) / cols, 0.0, 1.0)
        t = np.concatenate(([t0], t, [t1]))
        s = np.concatenate(([s0], s, [s1]))
        S = evaluate(faces[name], t, s)
        _, Pp, Pm, valid = check_patches.envelope(p, t, s)
        d = np.minimum(np.linalg.norm(S - Pp, axis=2), np.linalg.norm(S - Pm, axis=2))
        result[p.id] = float(np.max(np.where(valid, d, 0.0))) if valid.any() else None
    return result, tol


def pole_counts(patches_json, step_path=None, faces=None):
    """Per patch id: the poles (nu × nv) of its face in patches.step, or None without one.
    `faces` as for check."""
    data = check_patches.load_patches(patches_json)[0]
    faces = faces if faces is not None else faces_of(patches_json, step_path)
    counts = {}
    for index, pj in enumerate(data["patches"]):
        pid = pj.get("id", index)
        name = face_name(pj, pid)
        counts[pid] = faces[name][4].shape[0] * faces[name][4].shape[1] if name in faces else None
    return counts


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("patches_json")
    ap.add_argument("--step", help="the STEP file (default: patches.step beside PATCHES_JSON)")
    ap.add_argument("--limit", type=float, default=0.01, help="largest distance allowed, × tolerance")
    ap.add_argument("--rows", type=int, default=401)
    ap.add_argument("--cols", type=int, default=81)
    a = ap.parse_args(argv)
    try:
        check_patches.load_patches(a.patches_json)  # its errors first, as the file named
        faces = faces_of(a.patches_json, a.step)
        result, tol = check(a.patches_json, a.step, a.rows, a.cols, faces)
        poles = pole_counts(a.patches_json, a.step, faces)
    except (check_patches.InputError, OSError, ValueError) as exc:
        print(f"check_step: {exc}", file=sys.stderr)
        return 2
    bad = 0
    for pid, dev in result.items():
        ok = dev is not None and dev <= a.limit * tol
        bad += not ok
        print(f"P{pid}: " + ("no face" if dev is None else f"{dev:.3g} mm = {dev / tol:.4f} tol, "
                             f"{poles.get(pid)} poles")
              + ("" if ok else "  FAILS"))
    worst = max((d for d in result.values() if d is not None), default=0.0)
    print(f"{len(result)} faces, worst {worst / tol:.4f} tol (limit {a.limit})")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
