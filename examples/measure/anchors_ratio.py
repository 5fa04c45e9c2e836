"""Issue 12's anchors bars from an `anchors.sh` output folder.

    python3 examples/measure/anchors_ratio.py OUT_DIR

Reads OUT_DIR/embree*.txt (the Embree harness's DETAIL lines) and
OUT_DIR/prism-{100k,1m}*.txt (`prism bench rays` tables), takes the best
figure of each side over all the files (rounds), and prints per workload
and thread count: camera rays, Prism's best mode against Embree's best
mode; bounce rays, Prism's best mode against Embree's `rtcIntersect1` on
its medium build; build time against Embree's medium build.

Then the same ratios round by round (`embree.R.txt` against
`prism-SIZE.R.txt` of the same round R, run minutes apart) with their
median and range: on a VM whose speed drifts, a ratio of two bests can
pair one side's fast minute with the other's slow one, and the paired
rounds show how far a cell moves from round to round.
"""
import glob
import re
import statistics
import sys


def ratios(emb_paths, prism_paths):
    """The bars' ratios from the best figures in the given files: for
    each (size, threads), (camera ratio, bounce ratio, build ratio, the
    line that prints them with their figures)."""
    emb = {}
    for path in emb_paths:
        for line in open(path):
            if not line.startswith("DETAIL"):
                continue
            f = line.strip().split("|")
            if f[3] == "build":
                key = (f[1], f[2], "build", int(f[4].split("=")[1]))
                ms = float(f[5].split("=")[1])
                emb[key] = min(emb.get(key, ms), ms)
                continue
            key = (f[1], f[2], f[3], f[4], int(f[5].split("=")[1]))
            rate = float(f[6].split("=")[1])
            emb[key] = max(emb.get(key, rate), rate)
    out = {}
    for size in ["100k", "1m"]:
        rates, builds = {}, {}
        for path in prism_paths(size):
            for line in open(path):
                m = re.match(r"\s+(primary|incoherent)\s+(\w+)\s+(\d+)\s+([\d.]+)", line)
                if m:
                    key = (m.group(1), m.group(2), int(m.group(3)))
                    rates[key] = max(rates.get(key, 0.0), float(m.group(4)))
                m = re.match(r"\s+build .*, (\d+) threads: ([\d.]+) ms", line)
                if m:
                    t, ms = int(m.group(1)), float(m.group(2))
                    builds[t] = min(builds.get(t, ms), ms)
        for t in (1, 2):
            camera = {k: v for k, v in emb.items()
                      if len(k) == 5 and k[0] == size and k[3] == "primary" and k[4] == t}
            best_key = max(camera, key=camera.get)
            e_cam = camera[best_key]
            e_one = emb[(size, "embree3-medium", "rtcIntersect1", "incoherent", t)]
            e_build = emb[(size, "embree3-medium", "build", t)]
            p_cam = max(v for k, v in rates.items() if k[0] == "primary" and k[2] == t)
            p_inc = max(v for k, v in rates.items() if k[0] == "incoherent" and k[2] == t)
            line = (
                f"{size} {t} thread(s): camera {p_cam:.2f} / {e_cam:.2f} "
                f"({best_key[1]} {best_key[2]}) = {p_cam / e_cam:.2f}x (0.5x needed); "
                f"bounces {p_inc:.2f} / {e_one:.2f} = {p_inc / e_one:.2f}x (0.8x needed); "
                f"build {builds[t]:.1f} / {e_build:.1f} ms = {builds[t] / e_build:.2f}x (2x allowed)"
            )
            out[(size, t)] = (p_cam / e_cam, p_inc / e_one, builds[t] / e_build, line)
    return out


def main(out):
    best = ratios(
        sorted(glob.glob(out + "/embree*.txt")),
        lambda size: sorted(glob.glob(f"{out}/prism-{size}*.txt")),
    )
    for key in sorted(best):
        print(best[key][3])
    rounds = sorted(
        int(m.group(1))
        for p in glob.glob(out + "/embree.*.txt")
        if (m := re.search(r"embree\.(\d+)\.txt$", p))
    )
    if len(rounds) < 2:
        return
    per = [
        ratios([f"{out}/embree.{r}.txt"], lambda size, r=r: [f"{out}/prism-{size}.{r}.txt"])
        for r in rounds
    ]
    print(f"paired rounds ({len(rounds)}): median [min, max] of each round's ratio")
    for key in sorted(best):
        cells = []
        for i, (name, bar) in enumerate([("camera", "0.5x"), ("bounces", "0.8x"), ("build", "2x")]):
            v = sorted(p[key][i] for p in per)
            cells.append(f"{name} {statistics.median(v):.2f}x [{v[0]:.2f}, {v[-1]:.2f}] ({bar})")
        print(f"{key[0]} {key[1]} thread(s): " + "; ".join(cells))


if __name__ == "__main__":
    main(sys.argv[1])
