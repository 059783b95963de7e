#!/usr/bin/env python3
"""The MSE rate per sample of a path tracer with Sobol points, LuxCore's against ours, on
SmallVCM's default scene: does an independent production sampler reach a steeper slope on
the diffuse region than smallvcm's?

    build/luxcore-venv/bin/python benchmarks/luxcore_rates.py [--seeds 4] [--resolution 64]
        [--budgets 1,2,4,8,16,32,64] [--out build/luxcore_rates]

(`make bench-luxcore` makes that virtual environment.) Scene, conversion, reference and
regions as benchmarks/luxcore_compare.py (its functions are used): LuxCore's PATHCPU with
its SOBOL sampler (no adaptivity, one thread), its film read at each CPU budget with the
number of passes (samples per pixel) done; ours: build/convergence, pt with Sobol points,
checkpoints at 1, 2, 4, ... iterations. Own MSE = MSE against our reference less its
noise^2 (whole image and diffuse region); slope = least squares of log own MSE against log
samples per pixel over the checkpoints from 8 samples on whose own MSE is at least half the
noise^2, per seed; mean +- standard error over the seeds. Writes DIR/rates.md.
"""
import argparse
import math
import os
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import luxcore_compare as lc  # noqa: E402


def slope(points, noise2):
    """points: (samples, mse); F18's fit of the own MSE."""
    kept = [(math.log(n), math.log(e - noise2)) for n, e in points if n >= 8 and e - noise2 >= 0.5 * noise2]
    if len(kept) < 3:
        return float("nan")
    x, y = np.array(kept).T
    return float(np.polyfit(x, y, 1)[0])


def mean_se(values):
    v = np.array([x for x in values if not math.isnan(x)])
    return float(v.mean()), float(v.std(ddof=1) / math.sqrt(len(v))) if len(v) > 1 else float("nan")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--budgets", default="1,2,4,8,16,32,64")
    parser.add_argument("--iterations", type=int, default=1024, help="our pt's last checkpoint")
    parser.add_argument("--out", default=os.path.join(lc.ROOT, "build", "luxcore_rates"))
    args = parser.parse_args()
    budgets = [int(b) for b in args.budgets.split(",")]
    size = args.resolution
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "scene.scn"), "w") as f:
        f.write(lc.convert(args.out))
    reference, noise, noise_diffuse, diffuse = lc.load_reference(size)
    inner = lc.interior(size)
    regions = {"whole": (inner, noise ** 2), "diffuse": (inner & diffuse, noise_diffuse ** 2)}
    slopes = {(who, region): [] for who in ("luxcore PATHCPU", "smallvcm pt") for region in regions}
    last = {key: [] for key in slopes}
    for k in range(args.seeds):
        renders = lc.render_lux(args.out, "PATHCPU", size, budgets, 300 + k, False)
        for region, (mask, noise2) in regions.items():
            points = []
            for budget in budgets:
                image, _, passes = renders[budget]
                aligned, _ = lc.align(image, reference, inner)
                points.append((passes, lc.mse(aligned, reference, mask)))
            slopes[("luxcore PATHCPU", region)].append(slope(points, noise2))
            last[("luxcore PATHCPU", region)].append(points[-1])
        csv = os.path.join(args.out, f"ours_pt_{k}.csv")
        subprocess.run([lc.CONVERGENCE, "-q", "--scenes", "4", "--resolution", f"{size}x{size}", "--algorithms", "pt",
                        "--sampler", "sobol", "--seed", str(4000 + k), "--max-iterations", str(args.iterations),
                        "--references", lc.REFERENCES, "--out", csv], check=True)
        rows = [line.strip().split(",") for line in open(csv).readlines()[1:]]
        for region, (_, noise2) in regions.items():
            column = 4 if region == "whole" else 6
            points = [(int(r[2]), float(r[column]) ** 2) for r in rows]
            slopes[("smallvcm pt", region)].append(slope(points, noise2))
            last[("smallvcm pt", region)].append(points[-1])
    lines = ["| renderer | region | MSE slope per sample (mean ± SE over seeds) | samples at the last checkpoint | own MSE there |",
             "|---|---|---:|---:|---:|"]
    for (who, region), values in slopes.items():
        m, se = mean_se(values)
        noise2 = regions[region][1]
        n = np.mean([p[0] for p in last[(who, region)]])
        e = np.mean([p[1] - noise2 for p in last[(who, region)]])
        lines.append(f"| {who} | {region} | {m:.2f} ± {se:.2f} | {n:.0f} | {e:.3g} |")
    text = "\n".join(lines) + "\n"
    with open(os.path.join(args.out, "rates.md"), "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
