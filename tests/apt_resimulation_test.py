#!/usr/bin/env python3
"""toolpath.apt machines what flank says it machines, judged by tests/apt_resimulate.py.

Makes the exact envelope of a cone (`flank synth`, the guiding curves of Li, Mann & Bedi),
decomposes it with cone cutters, requires a cone patch, then re-simulates toolpath.apt: the
tool rebuilt from CUTTER/ alone, swept linearly through the GOTO points, must leave every
vertex of Omega (envelopes.ply) on its surface within the run's tolerance and gouge none of
them by more than that.

The cone is steep enough that the end face's offset along the axis matters: it lies
r_tip k / (1 + k^2) = 0.36 mm below the axis end point (k = 0.12 mm/mm), which moves the side
by 0.36 sin(atan k) = 0.04 mm, four times the tolerance (1e-4 of the part's diagonal, about
0.01 mm). A negative control proves it: the same toolpath with every GOTO moved back to the
tip-end axis point (where flank wrote it before the CL point was the end face's centre) must
fail the re-simulation.

--apt-steps 200 (the default): the linear moves between GOTOs then stay within 5e-4 mm of the
cubic motion flank fitted (0.04 of the tolerance; 2e-3 with 100 steps, 2e-2 with 25, which
fails), so what the check measures is the CL point and CUTTER/, not the chords.

Usage: apt_resimulation_test.py --flank BIN [--work DIR]
Exit 0 when the toolpath holds and the control fails, 1 otherwise.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
RESIMULATE = os.path.join(HERE, "apt_resimulate.py")
CONE = "cone:3,9"  # radius 3 mm at the tip, 9 mm at the spindle end, 50 mm long
APT_STEPS = "200"


def run(cmd, expect=(0,)):
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode not in expect:
        raise SystemExit(f"FAIL: {' '.join(cmd)} exited {p.returncode}: "
                         f"{(p.stdout + p.stderr).strip()[-800:]}")
    return p


def without_end_face_offset(apt, patches, path):
    """The toolpath with each GOTO moved back along its axis to the tip-end axis point."""
    faces = []
    for p in patches:
        profile, length = p["tool"]["profile"], p["tool"]["length"]
        faces.append(profile[0][0] if p["tip"] == "a" else length - profile[-1][0])
    out, block = [], -1
    with open(apt) as f:
        for line in f:
            if line.startswith("CUTTER/"):
                block += 1
            elif line.startswith("GOTO/"):
                x, y, z, i, j, k = (float(v) for v in line[5:].split(","))
                w = faces[block]
                line = f"GOTO/{x - w * i:.6f},{y - w * j:.6f},{z - w * k:.6f},{i:.6f},{j:.6f},{k:.6f}\n"
            out.append(line)
    with open(path, "w") as f:
        f.writelines(out)
    return max(abs(w) for w in faces)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flank", required=True)
    ap.add_argument("--work", help="keep the outputs here (default: a temporary folder)")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        work = a.work or tmp
        os.makedirs(work, exist_ok=True)
        mesh, out = os.path.join(work, "cone.stl"), os.path.join(work, "out")
        run([a.flank, "synth", "--guides", "seed003", "--tool", CONE, "--resolution", "121x31", "-o", mesh])
        run([a.flank, "decompose", mesh, "-o", out, "--tool", "cone", "--tolerance-rel", "1e-4",
             "--apt-steps", APT_STEPS, "--threads", "2", "-q"])
        with open(os.path.join(out, "patches.json")) as f:
            data = json.load(f)
        kinds = [p["tool"]["kind"] for p in data["patches"]]
        if not kinds or any(k != "cone" for k in kinds):
            print(f"FAIL: expected cone patches, got {kinds}")
            return 1
        tol = data["coverage"]["tolerance"]
        apt, ply = os.path.join(out, "toolpath.apt"), os.path.join(out, "envelopes.ply")
        check = [sys.executable, RESIMULATE, apt, ply, "--tolerance", repr(tol)]
        good = run(check, expect=(0, 1))
        print(good.stdout, end="")
        fails = []
        if good.returncode != 0:
            fails.append("toolpath.apt does not machine Omega within the tolerance")
        control = os.path.join(work, "no_offset.apt")
        shift = without_end_face_offset(apt, data["patches"], control)
        bad = run(check[:2] + [control] + check[3:] + ["--max-points", "5000"], expect=(0, 1))
        print("control, GOTO at the axis end point (shifted %.4f mm): " % shift + bad.stdout, end="")
        if bad.returncode == 0:
            fails.append("the control without the end face's offset passes: the check cannot see it")
    print(f"[ apt_resimulation ] {len(kinds)} cone patch(es), tolerance {tol:.4g} mm: "
          + ("ok" if not fails else "FAIL"))
    for f in fails:
        print(f"FAIL: {f}")
    return 1 if fails else 0


if __name__ == "__main__":
    sys.exit(main())
