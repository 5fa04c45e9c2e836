#!/usr/bin/env bash
# Instructions per closest-hit query of Embree's rtcIntersect1 and of
# Prism's one-ray kernel on the anchors' bounce rays, under callgrind:
#   examples/measure/instr_per_ray.sh PRISM_BINARY [SIZE] [SHARED_DIR]
# SIZE is 100k (default) or 1m. The Embree harness of SHARED_DIR (default
# ../shared beside the repository) is copied to a temporary folder, cut
# down to its medium build, rtcIntersect1 and the bounce rays, given a
# LIMIT on the number of rays, and built as run.sh builds it. Each program
# runs under callgrind on the first 50,000 and the first 100,000 rays (one
# thread, one warm-up and one timed pass); the difference of the two
# totals over the 100,000 extra queries is printed. Needs the workload and
# libembree-dev (run SHARED_DIR/traversal-anchors/run.sh once) and
# valgrind. A few minutes.
set -euo pipefail
if [ $# -lt 1 ]; then
  echo "usage: $0 PRISM_BINARY [SIZE] [SHARED_DIR]" >&2
  exit 2
fi
PRISM=$(realpath "$1"); SIZE=${2:-100k}
SHARED=${3:-$(dirname "$0")/../../../shared}
DATA="$HOME/.cache/traversal-anchors/data/$SIZE"
VALGRIND=${VALGRIND:-valgrind}
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
src="$SHARED/traversal-anchors/embree/embree_anchor.cpp"
# The harness's own lines, replaced so that it runs the medium build's
# rtcIntersect1 on the first LIMIT bounce rays only.
sed -e 's|const Quality qualities\[\] = {{"high", RTC_BUILD_QUALITY_HIGH}, {"medium", RTC_BUILD_QUALITY_MEDIUM}};|const Quality qualities[] = {{"medium", RTC_BUILD_QUALITY_MEDIUM}};|' \
    -e 's|std::vector<Mode> modes = {M1, MSTREAM};|std::vector<Mode> modes = {M1};|' \
    -e 's|for (int set = 0; set < 2; set++) {|for (int set = 1; set < 2; set++) {|' \
    -e 's|^\(\s*RaySet prim = load_rays.*\)$|\1 if (getenv("LIMIT")) incoh.n = atoi(getenv("LIMIT"));|' \
    "$src" > "$tmp/e.cpp"
for pattern in 'qualities\[\] = {{"medium"' 'modes = {M1};' 'set = 1; set < 2' 'getenv("LIMIT")'; do
  grep -q "$pattern" "$tmp/e.cpp" || { echo "the harness changed: '$pattern' not applied" >&2; exit 1; }
done
g++ -O3 -march=native -std=c++17 -pthread "$tmp/e.cpp" -lembree3 -o "$tmp/embree"
total() { callgrind_annotate "$1" 2>/dev/null | awk '/PROGRAM TOTALS/ {gsub(",", "", $1); print $1}'; }
for n in 50000 100000; do
  LIMIT=$n "$VALGRIND" --tool=callgrind --callgrind-out-file="$tmp/embree.$n" \
    "$tmp/embree" "$DATA" --reps 1 --build-reps 1 --threads 1 > /dev/null 2>&1
  PRISM_ISA=avx2 "$VALGRIND" --tool=callgrind --callgrind-out-file="$tmp/prism.$n" \
    "$PRISM" bench rays "$DATA" --sets incoherent --modes single --threads 1 --reps 1 \
    --build-reps 1 --limit "$n" > /dev/null 2>&1
done
for who in embree prism; do
  a=$(total "$tmp/$who.50000"); b=$(total "$tmp/$who.100000")
  echo "$who: $(( (b - a) / 100000 )) instructions per bounce ray ($SIZE, whole program)"
done
