#!/usr/bin/env bash
# Times SmallVCM (Davidovic & Georgiev) and smallvcm side by side on this machine, and
# checks that equal iterations give equal error. SmallVCM is not part of this project:
# build it yourself from its public repository (its Makefile: g++ -O3 -std=c++0x
# -fopenmp) and, as it has no resolution option, a second build with the resolution in
# config.hxx set to 256x256. Then, from the repository root:
#
#   SMALLVCM=/path/to/smallvcm SMALLVCM_256=/path/to/smallvcm_256 benchmarks/compare_smallvcm.sh OUTDIR
#
# Speed: for each configuration the two programs run interleaved, R times (default 2),
# and the faster run counts: wall seconds of the whole command / iterations (start-up and
# scene set-up included for both; a few milliseconds). One thread: both pinned to core 0
# with taskset (SmallVCM always starts a thread per core). Writes OUTDIR/times.csv.
# Equal error: on scenes 0 and 1, 16 iterations of pt and of vcm by each program, each
# compared with one 256-iteration smallvcm VCM reference of another seed
# (benchmarks/smallvcm_equal_error.py). Writes OUTDIR/equal_error.txt. About 15 minutes;
# EQUAL_ERROR=0 skips the equal-error part (about 5 minutes then), for a header whose
# renders are bit-identical to those of the last equal-error run.
set -euo pipefail
OUT=${1:?usage: SMALLVCM=... SMALLVCM_256=... benchmarks/compare_smallvcm.sh OUTDIR}
: "${SMALLVCM:?set SMALLVCM to a SmallVCM binary (512x512)}"
: "${SMALLVCM_256:?set SMALLVCM_256 to a SmallVCM binary built for 256x256}"
R=${R:-2}
OURS=$(pwd)/build/smallvcm
SAMPLER=${SAMPLER:-independent}  # SmallVCM draws independent numbers: ours too, unless SAMPLER=sobol
[ -x "$OURS" ] || { echo "compare_smallvcm: $OURS is missing (make build/smallvcm)" >&2; exit 1; }
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
SCRIPT_DIR=$(cd "$(dirname "$0")" && pwd)
cd "$OUT"   # SmallVCM writes its image into the working folder

seconds() { /usr/bin/time -f "%e" -o "$OUT/time.txt" "$@" > /dev/null 2>&1; cat "$OUT/time.txt"; }
measure() {  # resolution scene algorithm threads iterations
  local res=$1 scene=$2 alg=$3 threads=$4 iterations=$5 pin="" theirs=$SMALLVCM
  [ "$threads" = 1 ] && pin="taskset -c 0"
  [ "$res" = 256 ] && theirs=$SMALLVCM_256
  for _ in $(seq "$R"); do
    echo "smallvcm_original,$res,$scene,$alg,$threads,$iterations,$(seconds $pin "$theirs" -s "$scene" -a "$alg" -i "$iterations" -o theirs.bmp)" >> times.csv
    echo "smallvcm,$res,$scene,$alg,$threads,$iterations,$(seconds $pin "$OURS" -q --sampler "$SAMPLER" -s "$scene" -a "$alg" -i "$iterations" -j "$threads" -r "${res}x${res}" -o ours.pfm)" >> times.csv
  done
}
echo "program,resolution,scene,algorithm,threads,iterations,wall_seconds" > times.csv
echo "start $(date -u) load $(cut -d' ' -f1-3 /proc/loadavg)" > log.txt
for alg in pt bpt vcm; do measure 256 0 "$alg" 1 16; measure 256 0 "$alg" 2 32; done
for scene in 0 1 2 3; do
  measure 512 "$scene" pt 1 6; measure 512 "$scene" lt 1 10; measure 512 "$scene" ppm 1 6
  measure 512 "$scene" bpm 1 3; measure 512 "$scene" bpt 1 3; measure 512 "$scene" vcm 1 2
  measure 512 "$scene" pt 2 12; measure 512 "$scene" bpt 2 6; measure 512 "$scene" vcm 2 4
done
echo "end $(date -u) load $(cut -d' ' -f1-3 /proc/loadavg)" >> log.txt

[ "${EQUAL_ERROR:-1}" = 0 ] && exit 0
: > equal_error.txt
for scene in 0 1; do
  "$OURS" -q --sampler "$SAMPLER" -s "$scene" -a vcm -i 256 -j 2 -r 512x512 --seed 777 -o "reference_s$scene.pfm"
  for alg in pt vcm; do
    "$SMALLVCM" -s "$scene" -a "$alg" -i 16 -o "theirs_${alg}_s$scene.hdr" > /dev/null
    "$OURS" -q --sampler "$SAMPLER" -s "$scene" -a "$alg" -i 16 -j 2 -r 512x512 -o "ours_${alg}_s$scene.pfm"
    echo "scene $scene, $alg, 16 iterations: $(/usr/bin/python3 "$SCRIPT_DIR/smallvcm_equal_error.py" \
      "reference_s$scene.pfm" "ours_${alg}_s$scene.pfm" "theirs_${alg}_s$scene.hdr")" >> equal_error.txt
  done
done
cat equal_error.txt
