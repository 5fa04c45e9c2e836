#!/bin/bash
# Submits a Prism render as a Slurm job array of N shards, at most P
# running at once, and a merge job that runs only if every shard succeeded.
#
#   examples/farm/slurm/submit.sh SCENE N P OUT_DIR OUTPUT [render options...]
#
# e.g. examples/farm/slurm/submit.sh /shared/cornell.toml 64 16 /shared/shards \
#        /shared/cornell.exr --spp 4096
# PRISM names the binary (default: prism on PATH); extra sbatch options
# (partition, account, time) go in SBATCH_ARGS. Prints the two job ids.
set -euo pipefail
if [ $# -lt 5 ]; then
  sed -n '2,10p' "$0" >&2
  exit 2
fi
here=$(cd "$(dirname "$0")" && pwd)
scene=$1 shards=$2 parallel=$3 out_dir=$4 output=$5
shift 5
export SCENE=$scene SHARDS=$shards OUT_DIR=$out_dir OUTPUT=$output
export PRISM=${PRISM:-prism} PRISM_ARGS="$*"
mkdir -p "$out_dir"
# shellcheck disable=SC2086
array=$(sbatch --parsable ${SBATCH_ARGS:-} --chdir "$out_dir" \
  --array="0-$((shards - 1))%$parallel" --export=ALL "$here/render-shards.sbatch")
array=${array%%;*}
# shellcheck disable=SC2086
merge=$(sbatch --parsable ${SBATCH_ARGS:-} --chdir "$out_dir" \
  --dependency="afterok:$array" --kill-on-invalid-dep=yes --export=ALL "$here/merge.sbatch")
merge=${merge%%;*}
echo "$array $merge"
