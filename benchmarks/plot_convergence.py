#!/usr/bin/python3
"""Charts and an efficiency table from the CSV of build/convergence.

    /usr/bin/python3 benchmarks/plot_convergence.py docs/performance/convergence.csv

For every scene in the CSV (columns scene,algorithm,iterations,seconds,rmse,relmse) it
draws two log-log charts into the output folder (default: docs/performance/):

    convergence_s<i>_time.png        RMSE against rendering seconds
    convergence_s<i>_iterations.png  RMSE against iterations

one line per estimator, with the fitted convergence slope in the legend: a least-squares
line through (log x, log RMSE), skipping the first --skip points (default 2: the first
iterations are dominated by start-up effects, e.g. the largest merging radius). When the
study's settings file (FILE.csv -> FILE.txt, written by build/convergence) names the
reference's estimated noise, it is drawn as a grey band: no curve can fall far below it.

Then the efficiency table, in markdown, printed and written to --table (default
<output folder>/efficiency.md): per scene and estimator the final checkpoint's
iterations, seconds, RMSE and relative MSE, the two slopes, and

    error x time = RMSE^2 x seconds   (MSE times rendering time; lower is better)

For an unbiased estimator MSE falls as 1/time, so this product is about constant: it is
the variance of one second's worth of rendering, the inverse of the usual efficiency
1 / (variance x time). For biased estimators it depends on when it is measured (it grows
once the bias dominates), which is why the table uses the same final checkpoint the
charts end at. The winner of a scene is its estimator with the lowest error x time.

Needs matplotlib (Debian: python3-matplotlib); uses the Agg backend, no display.
"""

import argparse
import csv
import math
import os
import sys
from collections import OrderedDict, defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

SCENE_NAMES = {
    0: "cornell_0_sun (sun, mirror + glass spheres)",
    1: "cornell_1_mirror_ceiling (large mirror sphere, area light)",
    2: "cornell_2_point (point light, mirror + glass spheres)",
    3: "cornell_3_background (background light, mirror + glass spheres)",
    4: "cornell_4_default (area light, mirror + glass spheres)",
}
# Fixed colours, so that an estimator looks the same on every chart.
COLORS = {
    "pt": "#1f77b4", "lt": "#8c564b", "ppm": "#2ca02c", "bpm": "#9467bd",
    "bpt": "#d62728", "vcm": "#ff7f0e", "pm": "#7f7f7f", "pmfg": "#17becf",
}
# Line style by kind: unbiased solid, biased but consistent dashed, biased with a
# fixed photon count per iteration (iterations do not remove its bias) dotted.
STYLES = {"pt": "-", "lt": "-", "bpt": "-", "ppm": "--", "bpm": "--", "vcm": "--", "pm": ":", "pmfg": ":"}
ORDER = ["pt", "lt", "ppm", "bpm", "bpt", "vcm", "pm", "pmfg"]


def read_csv(path):
    """{scene: {algorithm: [row, ...]}} with rows sorted by iterations."""
    data = defaultdict(lambda: defaultdict(list))
    with open(path, newline="") as file:
        reader = csv.DictReader(file)
        expected = ["scene", "algorithm", "iterations", "seconds", "rmse", "relmse"]
        # Later studies add rmse_diffuse (build/convergence's header says what it is).
        if reader.fieldnames not in (expected, expected + ["rmse_diffuse"]):
            sys.exit("%s: the header is %s, expected %s" % (path, reader.fieldnames, ",".join(expected)))
        for row in reader:
            data[int(row["scene"])][row["algorithm"]].append({
                "iterations": int(row["iterations"]), "seconds": float(row["seconds"]),
                "rmse": float(row["rmse"]), "relmse": float(row["relmse"])})
    for scene in data.values():
        for rows in scene.values():
            rows.sort(key=lambda r: r["iterations"])
    return data


def read_settings(csv_path):
    """key = value pairs of the study's settings file, if there is one."""
    stem, extension = os.path.splitext(csv_path)
    path = stem + ".txt" if extension == ".csv" else csv_path + ".txt"
    settings = OrderedDict()
    if os.path.exists(path):
        with open(path) as file:
            for line in file:
                if " = " in line:
                    key, value = line.rstrip("\n").split(" = ", 1)
                    settings[key.strip()] = value.strip()
    return settings


def fit_slope(xs, ys, skip):
    """Least-squares slope of log(y) against log(x) without the first `skip` points;
    None when fewer than 3 points remain (two points always fit exactly)."""
    points = [(math.log(x), math.log(y)) for x, y in list(zip(xs, ys))[skip:] if x > 0 and y > 0]
    if len(points) < 3:
        return None
    mean_x = sum(p[0] for p in points) / len(points)
    mean_y = sum(p[1] for p in points) / len(points)
    sxx = sum((p[0] - mean_x) ** 2 for p in points)
    if sxx == 0:
        return None
    return sum((p[0] - mean_x) * (p[1] - mean_y) for p in points) / sxx


def ordered(algorithms):
    return sorted(algorithms, key=lambda a: (ORDER.index(a) if a in ORDER else len(ORDER), a))


def chart(scene, runs, axis, skip, noise, path):
    """One log-log chart of RMSE against `axis` ("seconds" or "iterations")."""
    figure, ax = plt.subplots(figsize=(9.0, 5.0), dpi=110)
    first_points = []
    for algorithm in ordered(runs):
        rows = runs[algorithm]
        xs = [r[axis] for r in rows]
        ys = [r["rmse"] for r in rows]
        slope = fit_slope(xs, ys, skip)
        label = "%s (slope %s)" % (algorithm, "n/a" if slope is None else "%+.2f" % slope)
        ax.plot(xs, ys, STYLES.get(algorithm, "-"), marker="o", markersize=3.5, linewidth=1.6,
                color=COLORS.get(algorithm), label=label)
        positive = [(x, y) for x, y in zip(xs, ys) if x > 0 and y > 0]
        if positive:
            first_points.append(positive[0])
    ax.set_xscale("log")
    ax.set_yscale("log")
    # Guides: slopes -1/2 (unbiased, 1/sqrt(N)) and -1/3 (PPM's optimum), from the
    # geometric middle of the first points, across the range of x.
    if first_points:
        x0 = math.exp(sum(math.log(p[0]) for p in first_points) / len(first_points))
        y0 = math.exp(sum(math.log(p[1]) for p in first_points) / len(first_points))
        x_max = max(max(r[axis] for r in rows) for rows in runs.values())
        for exponent, label in ((-0.5, "slope -1/2"), (-1.0 / 3.0, "slope -1/3")):
            ax.plot([x0, x_max], [y0, y0 * (x_max / x0) ** exponent], color="black",
                    linewidth=0.8, linestyle=(0, (1, 3)) if exponent == -0.5 else (0, (4, 4)),
                    alpha=0.5, label=label)
    if noise is not None and noise > 0:
        # The reference's own noise: measured errors cannot fall much below it.
        bottom = min(ax.get_ylim()[0], noise / 1.5)
        top = ax.get_ylim()[1]
        ax.axhspan(bottom, noise, color="grey", alpha=0.15, linewidth=0,
                   label="reference noise (RMSE %.2g)" % noise)
        ax.axhline(noise, color="grey", linewidth=0.8)
        ax.set_ylim(bottom, top)
    ax.set_xlabel("rendering time [s]" if axis == "seconds" else "iterations (samples per pixel)")
    ax.set_ylabel("RMSE against the reference")
    ax.set_title("%s\nRMSE vs %s (log-log)" % (SCENE_NAMES.get(scene, "scene %d" % scene),
                                                 "time" if axis == "seconds" else "iterations"), fontsize=10)
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    figure.tight_layout()
    figure.savefig(path)
    plt.close(figure)


def efficiency_table(data, skip, settings):
    lines = []
    lines.append("Efficiency: error x time = RMSE^2 x seconds at the final checkpoint (lower is better); "
                 "slopes fitted on log-log without the first %d points. Winner = lowest error x time." % skip)
    lines.append("")
    lines.append("| scene | estimator | iterations | seconds | RMSE | relMSE | slope vs time | slope vs iterations "
                 "| RMSE² × s | × winner |")
    lines.append("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    winners = []
    for scene in sorted(data):
        runs = data[scene]
        products = {}
        for algorithm in runs:
            last = runs[algorithm][-1]
            products[algorithm] = last["rmse"] ** 2 * last["seconds"] if last["seconds"] > 0 else float("inf")
        winner = min(products, key=products.get)
        best = products[winner]
        for algorithm in ordered(runs):
            rows = runs[algorithm]
            last = rows[-1]
            slope_time = fit_slope([r["seconds"] for r in rows], [r["rmse"] for r in rows], skip)
            slope_iterations = fit_slope([r["iterations"] for r in rows], [r["rmse"] for r in rows], skip)
            name = "**%s**" % algorithm if algorithm == winner else algorithm
            lines.append("| %d | %s | %d | %.2f | %.4g | %.4g | %s | %s | %.3g | %s |" % (
                scene, name, last["iterations"], last["seconds"], last["rmse"], last["relmse"],
                "n/a" if slope_time is None else "%+.2f" % slope_time,
                "n/a" if slope_iterations is None else "%+.2f" % slope_iterations,
                products[algorithm], "%.1f" % (products[algorithm] / best) if best > 0 else "n/a"))
        noise = settings.get("reference.%d.noise_rmse" % scene)
        winners.append((scene, winner, best, settings.get("reference.%d.algorithm" % scene), noise))
    lines.append("")
    lines.append("| scene | winner (lowest RMSE² × s) | RMSE² × s | reference | reference noise RMSE |")
    lines.append("|---|---|---:|---|---:|")
    for scene, winner, best, reference, noise in winners:
        lines.append("| %d %s | **%s** | %.3g | %s | %s |" % (
            scene, SCENE_NAMES.get(scene, "").split(" ")[0], winner, best, reference or "?", noise or "?"))
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("csv", nargs="?", default="docs/performance/convergence.csv")
    parser.add_argument("--out-dir", default="docs/performance", help="folder for the PNGs (default docs/performance)")
    parser.add_argument("--table", help="markdown file for the efficiency table (default OUT_DIR/efficiency.md)")
    parser.add_argument("--skip", type=int, default=2, help="points left out of the slope fit (default 2)")
    args = parser.parse_args()

    data = read_csv(args.csv)
    if not data:
        sys.exit("%s: no rows" % args.csv)
    settings = read_settings(args.csv)
    os.makedirs(args.out_dir, exist_ok=True)
    for scene in sorted(data):
        noise_text = settings.get("reference.%d.noise_rmse" % scene)
        noise = float(noise_text) if noise_text not in (None, "", "-1") else None
        for axis, suffix in (("seconds", "time"), ("iterations", "iterations")):
            path = os.path.join(args.out_dir, "convergence_s%d_%s.png" % (scene, suffix))
            chart(scene, data[scene], axis, args.skip, noise, path)
            print("wrote", path, file=sys.stderr)
    table = efficiency_table(data, args.skip, settings)
    table_path = args.table or os.path.join(args.out_dir, "efficiency.md")
    with open(table_path, "w") as file:
        file.write(table)
    print(table)
    print("wrote", table_path, file=sys.stderr)


if __name__ == "__main__":
    main()
