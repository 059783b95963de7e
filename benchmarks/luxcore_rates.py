#!/usr/bin/env python3
"""The MSE rate per sample with Sobol points, LuxCore's against ours, on SmallVCM's default
scene: does an independent production renderer reach a steeper slope on the diffuse region
than smallvcm's?

    build/luxcore-venv/bin/python benchmarks/luxcore_rates.py [--engine PATHCPU|BIDIRCPU]
        [--seeds 4] [--resolution 64] [--budgets 1,2,4,8,16,32,64]
        [--self-reference SECONDS] [--out build/luxcore_rates]

(`make bench-luxcore` makes that virtual environment.) Scene, conversion, reference and
regions as benchmarks/luxcore_compare.py (its functions are used): LuxCore's engine
(PATHCPU, or BIDIRCPU) with its SOBOL sampler (no adaptivity, one thread), its film read at
each CPU budget with the number of passes (samples per pixel) done; ours: build/convergence
with Sobol points (pt beside PATHCPU, bpt beside BIDIRCPU), checkpoints at 1, 2, 4, ...
iterations. Own MSE = MSE against the reference less its noise^2 (whole image and diffuse
region); slope = least squares of log own MSE against log samples per pixel over the
checkpoints from 8 samples on whose own MSE is at least half the noise^2, per seed; mean +-
standard error over the seeds. The reference is ours (docs/performance/references_sobol/),
unless --self-reference S is given (BIDIRCPU's default: its image differs from ours by
several per cent, see docs/performance.md): then LuxCore's runs are measured against two
LuxCore renders of S CPU seconds each (other seeds), averaged, whose noise^2 is E|A - B|^2 / 4
on each region. Writes DIR/rates_<engine>.md.
"""
import argparse
import json
import math
import os
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import luxcore_compare as lc  # noqa: E402


def render_lux_to(out, scene_dir, engine, size, budgets, seed):
    """{budget: (image, CPU seconds, passes)} of one LuxCore run (luxcore_compare.py's worker
    process), its films at out_<budget>.npy."""
    subprocess.run([sys.executable, os.path.abspath(lc.__file__), "--worker", os.path.join(scene_dir, "scene.scn"), engine,
                    str(size), ",".join(map(str, budgets)), str(seed), out], check=True, stdout=subprocess.DEVNULL)
    with open(out + ".json") as f:
        records = json.load(f)
    return {r["budget"]: (np.load(f"{out}_{r['budget']}.npy").astype(np.float64), r["cpu"], r["passes"]) for r in records}


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
    parser.add_argument("--engine", choices=["PATHCPU", "BIDIRCPU"], default="PATHCPU")
    parser.add_argument("--self-reference", type=float, default=None,
                        help="LuxCore against two LuxCore renders of this many CPU seconds (BIDIRCPU default: 400)")
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--budgets", default="1,2,4,8,16,32,64")
    parser.add_argument("--iterations", type=int, default=1024, help="our estimator's last checkpoint")
    parser.add_argument("--out", default=os.path.join(lc.ROOT, "build", "luxcore_rates"))
    args = parser.parse_args()
    budgets = [int(b) for b in args.budgets.split(",")]
    size = args.resolution
    engine, ours = args.engine, "pt" if args.engine == "PATHCPU" else "bpt"
    self_reference = args.self_reference if args.self_reference else (400.0 if engine == "BIDIRCPU" else None)
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "scene.scn"), "w") as f:
        f.write(lc.convert(args.out))
    reference, noise, noise_diffuse, diffuse = lc.load_reference(size)
    inner = lc.interior(size)
    masks = {"whole": inner, "diffuse": inner & diffuse}
    ours_noise2 = {"whole": noise ** 2, "diffuse": noise_diffuse ** 2}
    lux_reference, lux_noise2 = reference, ours_noise2
    if self_reference:
        halves = []
        for k in range(2):
            out = os.path.join(args.out, f"reference_{engine}_{k}")
            renders = render_lux_to(out, args.out, engine, size, [int(self_reference)], 900 + k)
            halves.append(lc.align(renders[int(self_reference)][0], reference, inner)[0])
        lux_reference = (halves[0] + halves[1]) / 2
        lux_noise2 = {region: lc.mse(halves[0], halves[1], mask) / 4 for region, mask in masks.items()}
    who_lux, who_ours = f"luxcore {engine}", f"smallvcm {ours}"
    slopes = {(who, region): [] for who in (who_lux, who_ours) for region in masks}
    last = {key: [] for key in slopes}
    for k in range(args.seeds):
        renders = render_lux_to(os.path.join(args.out, f"lux_{engine}_{k}"), args.out, engine, size, budgets, 300 + k)
        for region, mask in masks.items():
            points = []
            for budget in budgets:
                image, _, passes = renders[budget]
                aligned, _ = lc.align(image, reference, inner)
                points.append((passes, lc.mse(aligned, lux_reference, mask)))
            slopes[(who_lux, region)].append(slope(points, lux_noise2[region]))
            last[(who_lux, region)].append((points[-1][0], points[-1][1] - lux_noise2[region]))
        csv = os.path.join(args.out, f"ours_{ours}_{k}.csv")
        subprocess.run([lc.CONVERGENCE, "-q", "--scenes", "4", "--resolution", f"{size}x{size}", "--algorithms", ours,
                        "--sampler", "sobol", "--seed", str(4000 + k), "--max-iterations", str(args.iterations),
                        "--references", lc.REFERENCES, "--out", csv], check=True)
        rows = [line.strip().split(",") for line in open(csv).readlines()[1:]]
        for region in masks:
            column = 4 if region == "whole" else 6
            points = [(int(r[2]), float(r[column]) ** 2) for r in rows]
            slopes[(who_ours, region)].append(slope(points, ours_noise2[region]))
            last[(who_ours, region)].append((points[-1][0], points[-1][1] - ours_noise2[region]))
    lines = [f"reference of LuxCore's runs: {'two LuxCore renders of %g CPU s' % self_reference if self_reference else 'ours'}"
             f" (noise^2 whole {lux_noise2['whole']:.3g}, diffuse {lux_noise2['diffuse']:.3g}); of ours: ours", "",
             "| renderer | region | MSE slope per sample (mean ± SE over seeds) | samples at the last checkpoint | own MSE there |",
             "|---|---|---:|---:|---:|"]
    for (who, region), values in slopes.items():
        m, se = mean_se(values)
        n = np.mean([p[0] for p in last[(who, region)]])
        e = np.mean([p[1] for p in last[(who, region)]])
        lines.append(f"| {who} | {region} | {m:.2f} ± {se:.2f} | {n:.0f} | {e:.3g} |")
    text = "\n".join(lines) + "\n"
    with open(os.path.join(args.out, f"rates_{engine}.md"), "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
