#!/bin/bash
# Submits a splatscene batch as a Slurm array of TASKS shards and, after it (whether or not
# every task succeeded), a job that merges the shard indexes into OUTPUT_FOLDER/index.json.
#
#   examples/slurm/submit.sh MANIFEST OUTPUT_FOLDER [TASKS]
#
# Extra sbatch options (a partition, an account, --gres=gpu:1) go in SBATCH_OPTIONS. Prints the
# two job ids.
set -euo pipefail

if [ $# -lt 2 ] || [ $# -gt 3 ]; then
  echo "usage: $0 MANIFEST OUTPUT_FOLDER [TASKS]" >&2
  exit 2
fi
manifest=$1
out=$2
tasks=${3:-4}
case $tasks in
  '' | *[!0-9]* | 0) echo "$0: TASKS must be a positive number, not '$tasks'" >&2; exit 2 ;;
esac
here=$(cd "$(dirname "$0")" && pwd)
splatscene=${SPLATSCENE:-splatscene}
mkdir -p "$out"

# shellcheck disable=SC2086  # SBATCH_OPTIONS holds several options
array=$(sbatch --parsable ${SBATCH_OPTIONS:-} --array="1-$tasks" \
  --output="$out/slurm-%A_%a.log" \
  "$here/planning-report.sbatch" "$manifest" "$out")
array=${array%%;*}
# shellcheck disable=SC2086
merge=$(sbatch --parsable ${SBATCH_OPTIONS:-} --dependency="afterany:$array" \
  --job-name=splatscene-merge --output="$out/slurm-merge-%j.log" \
  --wrap "\"$splatscene\" batch --merge \"$out\"")
merge=${merge%%;*}
echo "array job $array ($tasks tasks), merge job $merge"
