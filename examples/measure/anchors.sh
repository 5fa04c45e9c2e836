#!/usr/bin/env bash
# Embree 3 and Prism on the ray-tracing anchors workload in one run:
#   examples/measure/anchors.sh PRISM_BINARY OUT_DIR [SHARED_DIR]
# SHARED_DIR defaults to ../shared (beside the repository). Writes
# OUT_DIR/embree.txt (the harness's table and DETAIL lines),
# OUT_DIR/prism-100k.txt and prism-1m.txt (`prism bench rays`, 1 and 2
# threads, 3 passes, 3 builds) and OUT_DIR/uptime.txt (load before and
# after). About a minute on 2 cores once the workload and harness exist.
set -euo pipefail
if [ $# -lt 2 ]; then
  echo "usage: $0 PRISM_BINARY OUT_DIR [SHARED_DIR]" >&2
  exit 2
fi
PRISM=$(realpath "$1"); OUT=$2
SHARED=${3:-$(dirname "$0")/../../../shared}
mkdir -p "$OUT"
uptime > "$OUT/uptime.txt"
(cd "$SHARED/traversal-anchors" && SIZES="100k 1m" THREADS=1,2 REPS=3 ./run.sh) > "$OUT/embree.txt" 2>&1
for s in 100k 1m; do
  "$PRISM" bench rays "$HOME/.cache/traversal-anchors/data/$s" --threads 1,2 --reps 3 --build-reps 3 > "$OUT/prism-$s.txt" 2>&1
done
uptime >> "$OUT/uptime.txt"
