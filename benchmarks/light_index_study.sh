#!/bin/sh
# Convergence of the Sobol sampler over several seeds, for comparing two versions of the
# code (docs/performance.md, "Light sub-paths across iterations"):
#
#   benchmarks/light_index_study.sh CONVERGENCE OUTDIR LABEL [SCENES] [ALGORITHMS] [SEEDS] [MAX_ITERATIONS]
#
# runs CONVERGENCE (a build/convergence binary, e.g. one copied aside from each version)
# once per seed, --sampler sobol, 64x64, one thread, checkpoints at 1, 2, 4, ... up to
# MAX_ITERATIONS, against docs/performance/references_sobol, writing
# OUTDIR/LABEL_seed<S>.csv; then prints benchmarks/sampler_seeds.py's table of slopes
# (mean +- standard error over the seeds) and own MSE at the last checkpoint.
# Defaults: scene 4, pt,lt,bpt,vcm, seeds 1-8, 1024 iterations (about 3 CPU-minutes per
# seed). Iterations, not time: the machine may be shared.
set -e
[ $# -ge 3 ] || { sed -n 2,14p "$0"; exit 2; }
CONVERGENCE=$1 OUTDIR=$2 LABEL=$3
SCENES=${4:-4} ALGORITHMS=${5:-pt,lt,bpt,vcm} SEEDS=${6:-"1 2 3 4 5 6 7 8"} MAX_ITERATIONS=${7:-1024}
cd "$(dirname "$0")/.."
mkdir -p "$OUTDIR"
files=""
for seed in $SEEDS; do
    out="$OUTDIR/${LABEL}_seed$seed.csv"
    "$CONVERGENCE" --references docs/performance/references_sobol --resolution 64x64 --scenes "$SCENES" \
        --algorithms "$ALGORITHMS" --max-iterations "$MAX_ITERATIONS" --sampler sobol --seed "$seed" --threads 1 -q \
        --out "$out"
    files="${files:+$files,}$out"
done
python3 benchmarks/sampler_seeds.py "$LABEL=$files"
