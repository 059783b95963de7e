#!/usr/bin/env bash
# Regenerates the golden images of tests/test_regression.cpp: every algorithm on scenes
# 0, 3 and 4 at 16x16, 2 iterations, 1 thread, seed 5 (pm/pmfg with 2000 photons).
# They pin the renderer's output bit for bit, so that restructuring for speed (compact
# light vertices, per-ray intersection constants, ...) is proven not to change a result.
# Regenerate only after an intentional change of what is sampled, and say so in the commit.
# First made with commit 0dd80a4, before the speed work, which kept them bit for bit.
# Regenerated since: (1) the glTF loader now normalises the camera's axes before building
# its basis (robust to huge transforms), which moves every ray by a rounding error;
# (2) pm and pmfg only: the kd-tree search no longer sorts the k nearest photons, so the
# density estimate sums their contributions in another order (the set of photons is the
# same; the images differ by at most 2.4e-7 relative, in 350 of 4608 values).
# (3) pt only: the MIS weight is computed as 1 / (1 + (q/p)^b) instead of p^b / (p^b + q^b),
# so that the power heuristic cannot overflow on tiny lights (scenes 3 and 4 differ by at
# most 2.3e-7 relative, in 359 of 4608 values; scene 0 is unchanged).
# (Regenerating everything must leave the other algorithms' files unchanged.)
# Run from the repository root.
set -euo pipefail
for scene in 0 3 4; do
  for algorithm in el pt lt ppm bpm bpt vcm pm pmfg; do
    build/smallvcm -q -s "$scene" -a "$algorithm" -r 16x16 -i 2 -j 1 --seed 5 --photons 2000 \
      -o "tests/data/golden/${algorithm}_s${scene}.pfm"
  done
done
