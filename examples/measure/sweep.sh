#!/usr/bin/env bash
# Wavefront against recursive on every scene (issue 13's third line):
#   examples/measure/sweep.sh PRISM_BINARY OUT_FILE [RUNS]
# Runs `prism bench SCENE --runs RUNS --width 320 --height 240 --spp 4
# --threads 2 --transport T` for every assets/*.toml, assets/bench/*.toml
# and assets/gltf/*.gltf under Whitted and path transport, and writes one
# line per scene and transport with the speedup of the wavefront over
# the recursive integrator (medians and fastest runs). About 12 minutes
# on 2 cores with RUNS = 7 (the default).
set -euo pipefail
if [ $# -lt 2 ]; then
  echo "usage: $0 PRISM_BINARY OUT_FILE [RUNS]" >&2
  exit 2
fi
PRISM=$(realpath "$1"); OUT=$2; RUNS=${3:-7}
cd "$(dirname "$0")/../.."
: > "$OUT"
for s in assets/*.toml assets/bench/*.toml assets/gltf/*.gltf; do
  for t in whitted path; do
    r=$("$PRISM" bench "$s" --runs "$RUNS" --width 320 --height 240 --spp 4 \
        --threads 2 --transport "$t" 2>&1 | grep "speedup" || echo "(not measured)")
    echo "$s $t $r" >> "$OUT"
  done
done
