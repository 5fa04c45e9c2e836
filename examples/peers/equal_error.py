#!/usr/bin/env python3
"""Prism against Mitsuba 3 at equal error: path tracing a glTF scene at 320x240
and 16 bounces, both measured against a high-spp reference.

  ~/.cache/peers-venv/bin/python examples/peers/equal_error.py assets/gltf/cornell.gltf \
      --reference REF.exr --prism target/release/prism --spp 16,64,256 --rounds 3

For each spp, the two renderers are run alternately (`--rounds` times; the
median time is kept): Prism with `prism render --transport path --max-depth 16`
(each integrator given by `--integrators`; `recursive+caustics` adds
`--caustics`, `recursive+split=2` adds `--split 2`), Mitsuba with
../shared/peers/mitsuba_render.py (`llvm_ad_rgb`, `--max-depth 18`, which is
16 bounces in Mitsuba's counting). Times are each renderer's own render time
(Prism's "in X s" line, Mitsuba's mi.render plus readback after a compiling
warm-up), not loading. The error is the mean relative error against the
reference, mean over pixels and channels of |x - ref| / (ref + 0.01).

Monte Carlo error falls as time^-1/2, so each point gives a constant
c = error * sqrt(time) (printed for every point; the highest-spp point,
least affected by fixed start-up costs, is used): the time Prism needs to
reach Mitsuba's error is (c_prism / c_mitsuba)^2 times Mitsuba's. Prints a
Markdown table. With several spp, it also gives, for each of Mitsuba's
points, the time Prism needs for that error read off its own points
(log-log interpolation), which does not assume the time^-1/2 law: Prism's
Sobol sampler converges faster than that, so its c falls with spp.

`--prism-spp 2,4,8,16,32` with `--spp 4,8,16,32` gives Prism points below
Mitsuba's lowest, so that Mitsuba's noisiest error is read between two of
Prism's points rather than extrapolated.

Make the reference with Mitsuba at 4096 spp and another seed:
  ~/.cache/peers-venv/bin/python ../shared/peers/mitsuba_render.py SCENE.gltf -o REF.exr \
      --width 320 --height 240 --spp 4096 --max-depth 18 --seed 1
"""
import argparse
import math
import os
import re
import statistics
import subprocess
import sys
import tempfile

import numpy as np
import OpenEXR

HERE = os.path.dirname(os.path.abspath(__file__))
PEER = os.path.normpath(os.path.join(HERE, "..", "..", "..", "shared", "peers", "mitsuba_render.py"))


def load(path):
    with OpenEXR.File(path) as f:
        ch = f.channels()
        if "RGB" in ch:
            return np.array(ch["RGB"].pixels, dtype=np.float64)
        return np.stack([ch[c].pixels for c in "RGB"], -1).astype(np.float64)


def mre(img, ref):
    return float(np.mean(np.abs(img - ref) / (ref + 0.01)))


def run_prism(prism, scene, out, spp, integrator, threads):
    # "recursive+caustics": the recursive integrator with `--caustics`;
    # "recursive+split=2" with `--split 2`.
    integrator, *flags = integrator.split("+")
    cmd = [prism, "render", scene, "-o", out, "--transport", "path", "--max-depth", "16",
           "--width", "320", "--height", "240", "--spp", str(spp), "--integrator", integrator,
           "--threads", str(threads)]
    for f in flags:
        cmd += ["--" + f] if "=" not in f else ["--" + f.split("=")[0], f.split("=", 1)[1]]
    p = subprocess.run(cmd, capture_output=True, text=True, check=True)
    m = re.search(r"at %d spp in ([0-9.]+) s" % spp, p.stdout + p.stderr)
    if not m:
        sys.exit("could not read Prism's time from: " + p.stdout + p.stderr)
    return float(m.group(1))


def run_mitsuba(python, scene, out, spp, threads, seed):
    cmd = [python, PEER, scene, "-o", out, "--width", "320", "--height", "240", "--spp", str(spp),
           "--max-depth", "18", "--threads", str(threads), "--seed", str(seed)]
    p = subprocess.run(cmd, capture_output=True, text=True, check=True)
    m = re.search(r"%d spp in ([0-9.]+) s" % spp, p.stdout)
    if not m:
        sys.exit("could not read Mitsuba's time from: " + p.stdout + p.stderr)
    return float(m.group(1))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene")
    ap.add_argument("--reference", required=True)
    ap.add_argument("--prism", default="target/release/prism")
    ap.add_argument("--spp", default="16,64,256")
    ap.add_argument("--prism-spp", default=None,
                    help="Prism's spp values (default: --spp); give lower ones too so that "
                         "Mitsuba's noisiest error is read between two of Prism's points "
                         "instead of extrapolated")
    ap.add_argument("--integrators", default="recursive,wavefront")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    a = ap.parse_args()
    ref = load(a.reference)
    tmp = tempfile.mkdtemp(prefix="equal_error_")
    rows = {}
    mitsuba_spp = [int(s) for s in a.spp.split(",")]
    prism_spp = [int(s) for s in (a.prism_spp or a.spp).split(",")]
    for spp in sorted(set(mitsuba_spp) | set(prism_spp)):
        times = {}
        errs = {}
        for r in range(a.rounds):
            if spp in prism_spp:
                for integ in a.integrators.split(","):
                    out = os.path.join(tmp, "prism_%s.exr" % integ)
                    times.setdefault("prism " + integ, []).append(run_prism(a.prism, a.scene, out, spp, integ, a.threads))
                    errs["prism " + integ] = mre(load(out), ref)
            if spp in mitsuba_spp:
                out = os.path.join(tmp, "mitsuba.exr")
                times.setdefault("mitsuba", []).append(run_mitsuba(sys.executable, a.scene, out, spp, a.threads, 0))
                errs["mitsuba"] = mre(load(out), ref)
        for k in times:
            t = statistics.median(times[k])
            rows.setdefault(k, []).append((spp, t, errs[k]))
            print("%-18s %5d spp  %8.3f s  error %.5f  c = %.5f" % (k, spp, t, errs[k], errs[k] * t ** 0.5),
                  file=sys.stderr, flush=True)
    print("| renderer | spp | seconds (median of %d) | mean relative error | error x sqrt(seconds) |" % a.rounds)
    print("|---|---:|---:|---:|---:|")
    for k, pts in rows.items():
        for spp, t, e in pts:
            print("| %s | %d | %.3f | %.5f | %.5f |" % (k, spp, t, e, e * t ** 0.5))
    cm = rows["mitsuba"][-1][2] * rows["mitsuba"][-1][1] ** 0.5
    for k, pts in rows.items():
        if k == "mitsuba":
            continue
        c = pts[-1][2] * pts[-1][1] ** 0.5
        print("\n%s needs %.2fx Mitsuba's time for Mitsuba's error (at the highest spp)." % (k, (c / cm) ** 2))
    # The same question at each of Mitsuba's error levels, without assuming
    # that error falls as time^-1/2 (a low-discrepancy sampler's falls
    # faster): Prism's time for that error, read off the straight line
    # through its two neighbouring points in log(error)-log(time).
    if len(rows["mitsuba"]) > 1 and all(len(v) > 1 for v in rows.values()):
        print("\n| Mitsuba spp | its error | its seconds | " +
              " | ".join("%s: seconds for that error (ratio)" % k for k in rows if k != "mitsuba") + " |")
        print("|---:|---:|---:|" + "---:|" * (len(rows) - 1))
        for spp, t_m, e_m in rows["mitsuba"]:
            cells = []
            for k, pts in rows.items():
                if k == "mitsuba":
                    continue
                t, outside = time_for_error(pts, e_m)
                cells.append("%.3f (%.2fx)%s" % (t, t / t_m, " extrapolated" if outside else ""))
            print("| %d | %.5f | %.3f | %s |" % (spp, e_m, t_m, " | ".join(cells)))


def time_for_error(pts, e):
    """Time at which the renderer whose (spp, seconds, error) points are
    `pts` (by increasing spp) reaches error `e`: linear in log-log between
    the two points around `e` (or along the nearest end segment, then
    flagged as extrapolated)."""
    outside = not (pts[-1][2] <= e <= pts[0][2])
    # The first segment whose far end is at or below `e`, else the last.
    i = next((i for i in range(len(pts) - 2) if pts[i + 1][2] <= e), len(pts) - 2)
    (_, t0, e0), (_, t1, e1) = pts[i], pts[i + 1]
    slope = math.log(t1 / t0) / math.log(e1 / e0)
    return t0 * math.exp(slope * math.log(e / e0)), outside


if __name__ == "__main__":
    main()
