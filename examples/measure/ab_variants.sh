#!/usr/bin/env bash
# Alternating wall-clock medians of several variants of `prism render`:
#   examples/measure/ab_variants.sh RUNS SCENE "BIN::ARGS|BIN::ARGS|..." [render args...]
# Each variant is a binary (with optional `env VAR=...` before it) and
# arguments after `::` appended to the render arguments; the variants run
# one after the other, RUNS rounds, and the median of each variant's
# "in X s" render time is printed. Example (merged meshes off and on):
#   examples/measure/ab_variants.sh 5 assets/gltf/cornell.gltf \
#     "target/release/prism::--merge-meshes off|target/release/prism::--merge-meshes on" \
#     --transport path --max-depth 16 --width 320 --height 240 --spp 16 --threads 1
set -euo pipefail
if [ $# -lt 3 ]; then
  echo "usage: $0 RUNS SCENE \"BIN::ARGS|BIN::ARGS|...\" [render args...]" >&2
  exit 2
fi
R=$1; S=$2
IFS='|' read -ra VARIANTS <<< "$3"
shift 3
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
declare -A T
for _ in $(seq "$R"); do
  for k in "${!VARIANTS[@]}"; do
    pre=${VARIANTS[$k]%%::*}; post=${VARIANTS[$k]#*::}
    [ "$post" = "${VARIANTS[$k]}" ] && post=""
    t=$(eval "$pre render \"$S\" -o \"$tmp/$k.exr\" $* $post" 2>&1 | grep -oE 'in [0-9.]+ s' | awk '{print $2}')
    T[$k]="${T[$k]:-} $t"
  done
done
for k in "${!VARIANTS[@]}"; do
  med=$(echo ${T[$k]} | tr ' ' '\n' | sort -n | awk '{a[NR]=$1} END{print a[int((NR+1)/2)]}')
  echo "${VARIANTS[$k]}: median $med s of${T[$k]}"
done
