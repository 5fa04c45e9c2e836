"""Issue 12's anchors bars from an `anchors.sh` output folder.

    python3 examples/measure/anchors_ratio.py OUT_DIR

Reads OUT_DIR/embree*.txt (the Embree harness's DETAIL lines) and
OUT_DIR/prism-{100k,1m}*.txt (`prism bench rays` tables), takes the best
figure of each side over all the files (rounds), and prints per workload
and thread count: camera rays, Prism's best mode against Embree's best
mode; bounce rays, Prism's best mode against Embree's `rtcIntersect1` on
its medium build; build time against Embree's medium build.
"""
import glob
import re
import sys


def main(out):
    emb = {}
    for path in sorted(glob.glob(out + "/embree*.txt")):
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
    for size in ["100k", "1m"]:
        rates, builds = {}, {}
        for path in sorted(glob.glob(f"{out}/prism-{size}*.txt")):
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
            print(
                f"{size} {t} thread(s): camera {p_cam:.2f} / {e_cam:.2f} "
                f"({best_key[1]} {best_key[2]}) = {p_cam / e_cam:.2f}x (0.5x needed); "
                f"bounces {p_inc:.2f} / {e_one:.2f} = {p_inc / e_one:.2f}x (0.8x needed); "
                f"build {builds[t]:.1f} / {e_build:.1f} ms = {builds[t] / e_build:.2f}x (2x allowed)"
            )


if __name__ == "__main__":
    main(sys.argv[1])
