#!/usr/bin/env python3
"""Acceptance of `flank decompose`, judged independently (issue "Real parts").

Each case runs the real command line with its default options (only the tolerance is set),
then rebuilds every patch's machined surface from patches.json with tests/check_patches.py
(NumPy/SciPy, no flank code) and measures it against the input mesh. Nothing the solver says
of itself decides a case; its claims are only compared with the rebuild.

Cases:
  real FACE TOL KMAX MIN   a face of tests/data at --tolerance-rel TOL: the coverage after at
                           most KMAX patches is at least MIN
  spline                   the exact envelope of a free-form (spline) cutter, made by
                           `flank synth`: one patch covering at least 95%
  freeform SEED TOL KMAX MIN  a made-up blade face (tests/freeform_parts.py, SEED) at
                           --tolerance-rel TOL, judged as a real face
  cad FORMAT               the exact cone envelope written by synth as one STEP or IGES
                           (FORMAT step or iges) face and read back: one cone patch covering
                           at least 99%, the chord deviation within a tenth of the tolerance
  cad FORMAT GUIDES TOOL SIDE  another synth envelope through STEP or IGES, with every cutter
                           kind: at most 2 patches covering at least 95%
  noisy_barrel             a barrel envelope with Gaussian noise (sigma = 2e-4 of the
                           diagonal on every coordinate of every vertex) and two holes (radius
                           5% of the diagonal), at --tolerance-rel 3e-4: the first 2 patches
                           cover at least 85% (the noise alone leaves about 13% of the vertices
                           beyond any surface's tolerance)

Every case also requires: each patch's reported max |e| agrees with the rebuild within 10% of
the tolerance; every cutter's sphere radii (101 samples) lie within the allowed range written in
patches.json; on a clean part no patch gouges the part beyond the tolerance; every face of
patches.step, read from the file by tests/check_step.py, lies within 1% of the tolerance of Ω
and has at most 4,000 poles.

Usage: decompose_acceptance.py --flank BIN [--work DIR] CASE [ARGS...]
Prints one summary line; exit 0 when the case holds, 1 when it does not, 2 on bad usage.
"""

import argparse
import json
import os
import struct
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import check_patches  # noqa: E402  (the independent checker, beside this file)
import check_step  # noqa: E402  (patches.step's faces against the same rebuild)
import freeform_parts  # noqa: E402  (made-up blade faces)

DATA = os.path.join(HERE, "data")

# The free-form cutter of the spline case: ten B-spline sphere-radius coefficients (mm) along
# the paper's 50 mm tool, a profile no cylinder, cone or barrel follows.
SPLINE_TOOL = "spline:5,5.6,6.4,7,6.6,6,6.3,7.2,8,8.4"


def run(cmd):
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit(f"FAIL: {' '.join(cmd)} exited {p.returncode}: {p.stderr.strip()[-500:]}")
    return p.stdout


def write_stl(path, V, F):
    tri = V[F]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    rec = np.zeros(len(F), dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
    rec["n"], rec["v"] = n, tri
    with open(path, "wb") as f:
        f.write(b"flank acceptance part".ljust(80, b"\0") + struct.pack("<I", len(F)) + rec.tobytes())


def noisy_barrel(flank, work):
    """The barrel envelope of `flank synth`, every vertex coordinate moved by N(0, sigma),
    sigma = 2e-4 of the diagonal (fixed seed), and the faces within 5% of the diagonal of two
    points of the part (near 30% and 70% of its vertex order, that is of its length) removed."""
    clean = os.path.join(work, "barrel.stl")
    run([flank, "synth", "--guides", "seed003", "--tool", "barrel:418.17", "-o", clean])
    V, F = check_patches.read_mesh(clean)
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    rng = np.random.default_rng(20261123)
    Vn = V + rng.normal(0.0, 2e-4 * diag, V.shape)
    centroids = V[F].mean(axis=1)
    keep = np.ones(len(F), dtype=bool)
    for c in (V[len(V) * 3 // 10], V[len(V) * 7 // 10]):
        keep &= np.linalg.norm(centroids - c, axis=1) >= 0.05 * diag
    path = os.path.join(work, "barrel_noisy.stl")
    write_stl(path, Vn, F[keep])
    return path


def decompose(flank, mesh, out, tol, extra=()):
    run([flank, "decompose", mesh, "-o", out, "--tolerance-rel", str(tol), "--threads", "2", "-q", *extra])
    with open(os.path.join(out, "patches.json")) as f:
        return json.load(f)


MAX_FACE_POLES = 4000


def judge(data, res, out, kmax, min_cov, max_patches=None, clean=True):
    """The case's verdict: a list of failures (empty when it holds) and the summary."""
    fails = []
    step_faces = check_step.faces_of(os.path.join(out, "patches.json"))  # read once for both
    faces, _ = check_step.check(os.path.join(out, "patches.json"), faces=step_faces)
    poles = check_step.pole_counts(os.path.join(out, "patches.json"), faces=step_faces)
    tol = res["tolerance"]
    curve = res["coverage_curve"]
    n = len(curve)
    k = min(kmax, n)
    cov_k = curve[k - 1] if k > 0 else 0.0
    if cov_k < min_cov:
        fails.append(f"coverage after {k} patches {cov_k:.4f} < {min_cov}")
    if max_patches is not None and n > max_patches:
        fails.append(f"{n} patches > {max_patches}")
    lo, hi = data["settings"]["radius"]
    for p, r in zip(data["patches"], res["patches"]):
        d = np.array(p["tool"]["radii"]["d"], dtype=float)
        if d.min() < lo * (1 - 1e-9) or d.max() > hi * (1 + 1e-9):
            fails.append(f"patch {p['id']}: radii {d.min():.4f}..{d.max():.4f} outside {lo:.4f}..{hi:.4f}")
        ours, claim = r["max_abs"], r["claimed_max"]
        if ours is None or claim is None or abs(ours - claim) > 0.1 * tol:
            fails.append(f"patch {p['id']}: reported max |e| {claim} vs rebuilt {ours} (tol {tol:.4g})")
        if clean and r["max_gouge"] is not None and r["max_gouge"] > tol * (1 + 1e-6):
            fails.append(f"patch {p['id']}: gouges {r['max_gouge']:.4g} > tol {tol:.4g}")
        # patches.step (issue 11): each patch's B-spline face within 1% of the tolerance of Ω,
        # read from the file and measured off its fitted samples (tests/check_step.py).
        dev = faces.get(p["id"])
        if dev is None or not dev <= 0.01 * tol:
            fails.append(f"patch {p['id']}: patches.step face deviates {dev} > 1% of the tolerance")
        # Its knots follow Ω: a face of these parts holds within 1% of the tolerance on at most
        # 1,512 poles (the eight blade runs). Uniform knots over the fit's grid, where the
        # knots could not follow Ω on it, took 13,920 (HECC side a at 1e-4), 38,100 (the noisy
        # barrel next to its fold) and 46,080 (the made-up face 5).
        if poles.get(p["id"]) is not None and poles[p["id"]] > MAX_FACE_POLES:
            fails.append(f"patch {p['id']}: patches.step face has {poles[p['id']]} poles > {MAX_FACE_POLES}")
    summary = (f"{n} patches, coverage after 1..{n}: "
               + " ".join(f"{100 * c:.1f}%" for c in curve)
               + f"; after {k}: {100 * cov_k:.2f}% (claimed {100 * data['coverage']['fraction']:.2f}%"
               + f" after all); worst |max e claimed - rebuilt| "
               + f"{max((abs(r['max_abs'] - r['claimed_max']) for r in res['patches']), default=0.0) / tol:.3f} tol"
               + "; patches.step within "
               + f"{max((d or 0.0 for d in faces.values()), default=0.0) / tol:.4f} tol (claimed "
               + f"{max((p['nurbs']['max_deviation'] or 0.0 for p in data['patches']), default=0.0) / tol:.4f})"
               + f", at most {max((count or 0 for count in poles.values()), default=0)} poles a face")
    return fails, summary


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flank", required=True)
    ap.add_argument("--work", help="keep the outputs here (default: a temporary folder)")
    ap.add_argument("case", choices=["real", "freeform", "spline", "noisy_barrel", "cad"])
    ap.add_argument("args", nargs="*")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        work = a.work or tmp
        os.makedirs(work, exist_ok=True)
        out = os.path.join(work, "out")
        if a.case == "real":
            if len(a.args) != 4:
                ap.error("real takes FACE TOL KMAX MIN")
            face, tol, kmax, min_cov = a.args[0], float(a.args[1]), int(a.args[2]), float(a.args[3])
            mesh = os.path.join(DATA, face + ".stl")
            name = f"{face} at {tol:g}"
            data = decompose(a.flank, mesh, out, tol)
            res = check_patches.check(os.path.join(out, "patches.json"), mesh)
            fails, summary = judge(data, res, out, kmax, min_cov)
        elif a.case == "freeform":
            if len(a.args) != 4:
                ap.error("freeform takes SEED TOL KMAX MIN")
            seed, tol, kmax, min_cov = int(a.args[0]), float(a.args[1]), int(a.args[2]), float(a.args[3])
            mesh = os.path.join(work, f"freeform_{seed}.stl")
            freeform_parts.write_stl(mesh, *freeform_parts.blade(seed))
            name = f"made-up blade face {seed} at {tol:g}"
            data = decompose(a.flank, mesh, out, tol)
            res = check_patches.check(os.path.join(out, "patches.json"), mesh)
            fails, summary = judge(data, res, out, kmax, min_cov)
        elif a.case == "spline":
            mesh = os.path.join(work, "spline.stl")
            run([a.flank, "synth", "--guides", "seed003", "--tool", SPLINE_TOOL, "-o", mesh])
            name = "spline cutter envelope at 1e-4"
            data = decompose(a.flank, mesh, out, 1e-4)
            res = check_patches.check(os.path.join(out, "patches.json"), mesh)
            fails, summary = judge(data, res, out, 1, 0.95, max_patches=1)
        elif a.case == "cad":
            # The round trip of a designer's flank-millable face: an exact cone envelope written
            # by synth as one B-spline face (STEP or IGES), read back by decompose, judged
            # against the same envelope as a mesh.
            # With GUIDES TOOL SIDE, another envelope, decomposed with every cutter kind: what
            # is judged then is the decomposition of a tessellated face, whose coarse and fine
            # evaluations disagree more than on synth's regular meshes (a patch the finish cuts
            # back or drops must be replaced; the first round's best candidate may finish
            # under the target).
            if len(a.args) not in (1, 4) or a.args[0] not in ("step", "iges"):
                ap.error("cad takes FORMAT (step or iges) [GUIDES TOOL SIDE]")
            guides, tool, side = a.args[1:] if len(a.args) == 4 else ("seed003", "cone:4,7", "1")
            cad = os.path.join(work, "part." + ("step" if a.args[0] == "step" else "igs"))
            mesh = os.path.join(work, "part.stl")
            for path in (cad, mesh):
                run([a.flank, "synth", "--guides", guides, "--tool", tool, "--side", side, "-o", path])
            name = f"{tool} envelope of {guides} (side {side}) through {a.args[0].upper()} at 1e-4"
            if len(a.args) == 1:
                # The cone only: what is judged is the CAD reading, not the choice of tool kind.
                # One patch's coverage moves with the tessellation by about half a point: at
                # tolerances 0.8-1.3e-4 this face gave 98.95-100% through STEP and IGES with
                # the faces meshed whole, and the same spread cut in pieces (measured when
                # the faces were first cut, 2026-11-29). 98.5% asks for the whole face but
                # that boundary strip, whatever the tessellation.
                data = decompose(a.flank, cad, out, 1e-4, ["--tool", "cone"])
                res = check_patches.check(os.path.join(out, "patches.json"), mesh)
                fails, summary = judge(data, res, out, 1, 0.985, max_patches=1)
            else:
                data = decompose(a.flank, cad, out, 1e-4)
                res = check_patches.check(os.path.join(out, "patches.json"), mesh)
                fails, summary = judge(data, res, out, 2, 0.95, max_patches=2)
            tol = res["tolerance"]
            chord = data["settings"]["chord_deviation"]
            if not chord <= 0.1 * tol:
                fails.append(f"chord deviation {chord:.4g} > a tenth of the tolerance {tol:.4g}")
            summary += f"; chord deviation {chord / tol:.3f} tol"
        else:
            mesh = noisy_barrel(a.flank, work)
            name = "noisy barrel envelope with two holes at 3e-4"
            data = decompose(a.flank, mesh, out, 3e-4)
            res = check_patches.check(os.path.join(out, "patches.json"), mesh)
            fails, summary = judge(data, res, out, 2, 0.85, clean=False)
    print(f"[ acceptance ] {name}: {summary}")
    for f in fails:
        print(f"FAIL: {f}")
    return 1 if fails else 0


if __name__ == "__main__":
    sys.exit(main())
