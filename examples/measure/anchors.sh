#!/usr/bin/env bash
# Embree 3 and Prism on the ray-tracing anchors workload, alternating:
#   examples/measure/anchors.sh PRISM_BINARY OUT_DIR [SHARED_DIR]
# SHARED_DIR defaults to ../shared (beside the repository). ROUNDS
# (default 2) rounds each run Embree's harness, then `prism bench rays` on
# the 100k and 1M workloads (1 and 2 threads, 3 passes, 3 builds), so that
# a VM whose speed drifts over minutes weighs on both alike. Writes
# OUT_DIR/embree.R.txt (the harness's table and DETAIL lines),
# OUT_DIR/prism-100k.R.txt and prism-1m.R.txt for each round R,
# OUT_DIR/uptime.txt (load before and after), and prints the ratios of
# issue 12's bars from the best figure of each side over the rounds, then
# round by round with their median and range (anchors_ratio.py). About a
# minute a round on 2 cores once the workload and harness exist.
set -euo pipefail
if [ $# -lt 2 ]; then
  echo "usage: $0 PRISM_BINARY OUT_DIR [SHARED_DIR]" >&2
  exit 2
fi
PRISM=$(realpath "$1"); OUT=$2
SHARED=${3:-$(dirname "$0")/../../../shared}
ROUNDS=${ROUNDS:-2}
mkdir -p "$OUT"
uptime > "$OUT/uptime.txt"
for r in $(seq "$ROUNDS"); do
  (cd "$SHARED/traversal-anchors" && SIZES="100k 1m" THREADS=1,2 REPS=3 ./run.sh) > "$OUT/embree.$r.txt" 2>&1
  for s in 100k 1m; do
    "$PRISM" bench rays "$HOME/.cache/traversal-anchors/data/$s" --threads 1,2 --reps 3 --build-reps 3 > "$OUT/prism-$s.$r.txt" 2>&1
  done
done
uptime >> "$OUT/uptime.txt"
python3 "$(dirname "$0")/anchors_ratio.py" "$OUT"
