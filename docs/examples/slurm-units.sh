#!/bin/sh
# Submits the work units of a spec as Slurm job arrays, one array per level of
# `amrepro plan` (each level's tasks start when the level before has succeeded), then
# one job running `amrepro collect` (docs/SCALE.md). Prints the job ids.
#
#   SPEC=specs/discrepancy_fdm.toml OUT=/shared/out sh docs/examples/slurm-units.sh
#
# Every node must see $OUT and the spec's datasets at the same paths and run the same
# amrepro build ($AMREPRO, default `amrepro` on PATH). Add your site's sbatch options
# (partition, account, time) to SBATCH_OPTS.
set -eu
: "${SPEC:?set SPEC to the spec file}"
: "${OUT:?set OUT to the shared out folder}"
AMREPRO=${AMREPRO:-amrepro}
SBATCH_OPTS=${SBATCH_OPTS:-}

deepest=$("$AMREPRO" plan "$SPEC" 2>/dev/null | sed -n 's/.*"level":\([0-9]*\).*/\1/p' | sort -n | tail -n 1)
after=""
level=0
while [ "$level" -le "$deepest" ]; do
    array=$("$AMREPRO" plan "$SPEC" --array-of-level "$level")
    # shellcheck disable=SC2086
    after=$(sbatch --parsable $SBATCH_OPTS --job-name="amrepro-units-$level" --array="$array" \
        ${after:+--dependency=afterok:$after} \
        --wrap="\"$AMREPRO\" run-unit \"$SPEC\" --index \$SLURM_ARRAY_TASK_ID --out \"$OUT\" --quiet")
    echo "level $level: units $array, job $after"
    level=$((level + 1))
done
# shellcheck disable=SC2086
collect=$(sbatch --parsable $SBATCH_OPTS --job-name=amrepro-collect --dependency="afterok:$after" \
    --wrap="\"$AMREPRO\" collect \"$SPEC\" --out \"$OUT\" --quiet")
echo "collect: job $collect"
