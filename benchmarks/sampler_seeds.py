#!/usr/bin/env python3
"""Slopes with standard errors: one estimator's convergence over several seeds.

    python3 benchmarks/sampler_seeds.py LABEL=RUN1.csv,RUN2.csv,... [LABEL=...] > TABLE.md

Each RUN.csv is a build/convergence study (columns scene,algorithm,iterations,seconds,
rmse,relmse,rmse_diffuse; settings in RUN.txt) of the same scenes, estimators, resolution
and references, with its own --seed. Per label (a variant of the code, a sampler), scene,
estimator and region (whole image, diffuse region):
  slope     the fitted slope of log own MSE against log iterations, per seed (own MSE =
            MSE - the reference's noise^2; checkpoints from 8 iterations on whose own MSE is
            at least half the noise^2, as benchmarks/sampler_table.py and F18 fit), then
            the mean over seeds +- its standard error (sd / sqrt(seeds))
  slope of mean  the same fit to the own MSE averaged over the seeds
  own MSE   at the largest checkpoint all seeds reached: the mean over seeds +- its
            standard error
benchmarks/light_index_study.sh made the numbers of docs/performance.md's "Light
sub-paths across iterations" with it.
"""

import csv
import math
import os
import sys
from collections import defaultdict

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sampler_table import read_settings  # noqa: E402

ORDER = ["pt", "lt", "bpt", "ppm", "bpm", "vcm", "pm", "pmfg"]
REGIONS = [("whole", "rmse", "noise_rmse"), ("diffuse", "rmse_diffuse", "noise_rmse_diffuse")]


def read_run(path):
    runs = defaultdict(dict)
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            runs[(int(row["scene"]), row["algorithm"])][int(row["iterations"])] = row
    return runs, read_settings(path)


def fit(points):
    if len(points) < 3:
        return None
    mx = sum(p[0] for p in points) / len(points)
    my = sum(p[1] for p in points) / len(points)
    return sum((p[0] - mx) * (p[1] - my) for p in points) / sum((p[0] - mx) ** 2 for p in points)


def own_points(curve, n2):
    return [(math.log(n), math.log(mse - n2)) for n, mse in sorted(curve.items())
            if n >= 8 and mse - n2 >= 0.5 * n2 and mse - n2 > 0]


def mean_se(values):
    m = sum(values) / len(values)
    if len(values) < 2:
        return m, float("nan")
    sd = math.sqrt(sum((v - m) ** 2 for v in values) / (len(values) - 1))
    return m, sd / math.sqrt(len(values))


def main():
    if len(sys.argv) < 2 or any("=" not in a for a in sys.argv[1:]):
        sys.exit(__doc__)
    print("| variant | scene | estimator | region | seeds | slope (mean +- SE) | slope of mean | N | own MSE at N (mean +- SE) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for argument in sys.argv[1:]:
        label, files = argument.split("=", 1)
        studies = [read_run(path) for path in files.split(",")]
        keys = sorted(set.intersection(*(set(s[0]) for s in studies)),
                      key=lambda k: (k[0], ORDER.index(k[1]) if k[1] in ORDER else len(ORDER)))
        for scene, algorithm in keys:
            for region, column, noise_key in REGIONS:
                noise = float(studies[0][1].get(f"reference.{scene}.{noise_key}", "-1").split(" ")[0])
                n2 = noise * noise if noise > 0 else 0.0
                curves = [{n: float(row[column]) ** 2 for n, row in s[0][(scene, algorithm)].items()} for s in studies]
                common = sorted(set.intersection(*(set(c) for c in curves)))
                slopes = [s for s in (fit(own_points(c, n2)) for c in curves) if s is not None]
                mean_curve = {n: sum(c[n] for c in curves) / len(curves) for n in common}
                pooled = fit(own_points(mean_curve, n2))
                last = common[-1]
                own_mean, own_se = mean_se([c[last] - n2 for c in curves])
                slope_text = "%+.3f +- %.3f" % mean_se(slopes) if slopes else "n/a"
                pooled_text = "%+.3f" % pooled if pooled is not None else "n/a"
                print(f"| {label} | {scene} | {algorithm} | {region} | {len(curves)} | {slope_text} | {pooled_text} | "
                      f"{last} | {own_mean:.3e} +- {own_se:.1e} |")


if __name__ == "__main__":
    main()
