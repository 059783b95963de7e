#!/usr/bin/env python3
"""Independent numbers against Sobol points at equal CPU time, per scene and estimator.

    python3 benchmarks/sampler_table.py INDEPENDENT.csv SOBOL.csv > TABLE.md

Reads two studies of build/convergence (columns scene,algorithm,iterations,seconds,rmse,
relmse,rmse_diffuse), the same scenes, estimators, resolution, references and --max-seconds
with --clock cpu, one with --sampler independent and one with --sampler sobol, and their
settings files (FILE.csv -> FILE.txt: the references' noise). `make bench-samplers` makes
them and this table (docs/performance.md, "Samplers").

Per scene and estimator, at the last checkpoint of each run (where the CPU budget ran
out, so both samplers had the same time):
  s/it       CPU seconds per iteration (the run's seconds / iterations, one thread)
  cost       Sobol's seconds per iteration / independent's
  RMSE       against the reference, whole image and diffuse region (build/convergence's
             rmse_diffuse: pixels that see only Lambert surfaces)
  gain       independent's own MSE / Sobol's own MSE at equal time (own MSE = MSE - the
             reference's noise^2 on the same pixels; > 1: Sobol is better). Where an own
             MSE is below twice the reference's noise^2 the gain is uncertain and marked
             with "~"; at or below the noise it is not given ("-")
  slopes     the fitted slope of the diffuse own MSE against iterations, each sampler
             (F18's fit: checkpoints from 8 iterations on whose own MSE is at least half
             the noise^2; -1 is the rate of independent samples)
One run per sampler and estimator: a scene whose error is made by rare bright paths
(caustics of the sun or the point light seen through the glass) varies from run to run
by more than the samplers differ.
"""

import csv
import math
import sys
from collections import defaultdict

ORDER = ["pt", "lt", "bpt", "ppm", "bpm", "vcm", "pm", "pmfg"]


def read_study(path):
    runs = defaultdict(list)
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            runs[(int(row["scene"]), row["algorithm"])].append(
                (int(row["iterations"]), float(row["seconds"]), float(row["rmse"]) ** 2, float(row["rmse_diffuse"]) ** 2))
    return runs, read_settings(path)


def read_settings(path):
    """The "key = value" lines of a build/convergence run's settings file (FILE.txt beside FILE.csv)."""
    settings = {}
    with open(path[:-4] + ".txt" if path.endswith(".csv") else path + ".txt") as f:
        for line in f:
            if " = " in line:
                key, value = line.rstrip("\n").split(" = ", 1)
                settings[key] = value
    return settings


def noise2(settings, scene, key):
    value = float(settings.get(f"reference.{scene}.{key}", "-1").split(" ")[0])
    return value * value if value > 0 else 0.0


def gain(mse_a, mse_b, n2):
    own_a, own_b = mse_a - n2, mse_b - n2
    if min(own_a, own_b) <= 0.0:
        return "-"
    mark = "~" if min(own_a, own_b) < 2.0 * n2 else ""
    return f"{mark}{own_a / own_b:.2f}"


def slope(checkpoints, column, n2):
    points = [(math.log(c[0]), math.log(c[column] - n2)) for c in checkpoints
              if c[0] >= 8 and c[column] - n2 >= 0.5 * n2 and c[column] - n2 > 0]
    if len(points) < 3:
        return "n/a"
    mx = sum(p[0] for p in points) / len(points)
    my = sum(p[1] for p in points) / len(points)
    return "%+.2f" % (sum((p[0] - mx) * (p[1] - my) for p in points) / sum((p[0] - mx) ** 2 for p in points))


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    independent, settings_i = read_study(sys.argv[1])
    sobol, settings_s = read_study(sys.argv[2])
    print(f"Equal CPU time: {settings_s.get('max_seconds', '?')} s of one thread per run, "
          f"{settings_s.get('resolution', '?')}; references: {settings_s.get('reference.4.file', '?').rsplit('/', 1)[0]}/ "
          f"(the noise columns: the reference's own RMSE, whole / diffuse).\n")
    print("| scene | estimator | s/it indep. | s/it sobol | cost | RMSE indep. | RMSE sobol | gain (MSE) | "
          "RMSE diffuse indep. | RMSE diffuse sobol | gain diffuse (MSE) | slope diffuse indep. / sobol | ref. noise |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    keys = sorted(set(independent) & set(sobol),
                  key=lambda k: (k[0], ORDER.index(k[1]) if k[1] in ORDER else len(ORDER)))
    for scene, algorithm in keys:
        a, b = independent[(scene, algorithm)][-1], sobol[(scene, algorithm)][-1]
        n2, n2d = noise2(settings_s, scene, "noise_rmse"), noise2(settings_s, scene, "noise_rmse_diffuse")
        spi_a, spi_b = a[1] / a[0], b[1] / b[0]
        print(f"| {scene} | {algorithm} | {spi_a:.4f} | {spi_b:.4f} | {spi_b / spi_a:.2f} | {math.sqrt(a[2]):.4g} | "
              f"{math.sqrt(b[2]):.4g} | {gain(a[2], b[2], n2)} | {math.sqrt(a[3]):.4g} | {math.sqrt(b[3]):.4g} | "
              f"{gain(a[3], b[3], n2d)} | {slope(independent[(scene, algorithm)], 3, n2d)} / "
              f"{slope(sobol[(scene, algorithm)], 3, n2d)} | "
              f"{math.sqrt(n2):.3g} / {math.sqrt(n2d):.3g} |")


if __name__ == "__main__":
    main()
