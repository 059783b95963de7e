#!/usr/bin/python3
"""The charts of the course figures, drawn from the CSVs the figure programs write.

    python3 figures/plot_figures.py docs/figures            # or build/figures-quick

reads, in that folder,

    F18.csv  (build/fig_convergence: algorithm,iterations,seconds,rmse[,rmse_own,fitted])
             -> F18_convergence.png: RMSE against iterations and against seconds, log-log,
                one line per estimator, the fitted slope in the legend; an estimator
                with Sobol points ("bpt-sobol") in its estimator's colour, dash-dotted
                with square markers
    F12.csv  (build/fig_photon_mapping: method,photons,seconds,rmse)
             -> F12_convergence.png: RMSE against photons and against seconds, log-log,
                with the fitted rate of each method

A missing CSV is skipped with a message; the exit code is 1 only when no chart was drawn.

F18: the curve drawn is the estimator's own RMSE (rmse_own = sqrt(rmse^2 - n^2), n the
reference's noise, which the record F18.json gives); the measured RMSE is the faint
dotted line above it, and n the grey line. The slope is the least-squares line through
(log x, log rmse_own) over the checkpoints marked fitted=1 (fig_convergence says which
and why), drawn dashed over that range; it is the slope F18.json records.
F12: every point of a method is fitted (its photon counts are chosen to show the rate);
when F12.json gives the reference's noise it is drawn as a grey line.

Needs matplotlib (Debian: python3-matplotlib), Agg backend. When the python3 first on
PATH has no matplotlib, the script runs itself again with /usr/bin/python3.
"""

import csv
import json
import math
import os
import sys

try:
    import matplotlib
except ImportError:
    # e.g. a pyenv python3 first on PATH, the Debian package installed for /usr/bin/python3
    system_python = "/usr/bin/python3"
    if os.path.exists(system_python) and os.path.realpath(sys.executable) != os.path.realpath(system_python):
        os.execv(system_python, [system_python] + sys.argv)
    sys.exit("plot_figures.py: needs matplotlib (Debian: apt-get install python3-matplotlib)")

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

# Fixed colours, as in benchmarks/plot_convergence.py, so an estimator looks the same everywhere.
COLORS = {
    "pt": "#1f77b4", "lt": "#8c564b", "ppm": "#2ca02c", "bpm": "#9467bd",
    "bpt": "#d62728", "vcm": "#ff7f0e", "pm": "#7f7f7f", "pmfg": "#17becf",
}
ORDER = ["pt", "lt", "bpt", "ppm", "bpm", "vcm", "pm", "pmfg"]
EXTRA_COLORS = ["#bcbd22", "#e377c2", "#393b79", "#637939", "#8c6d31"]


SOBOL_SUFFIX = "-sobol"  # F18: the same estimator with Sobol points


def base_name(name):
    return name[:-len(SOBOL_SUFFIX)] if name.endswith(SOBOL_SUFFIX) else name


def color_of(name, index):
    return COLORS.get(base_name(name), EXTRA_COLORS[index % len(EXTRA_COLORS)])


def ordered(names):
    return sorted(names, key=lambda n: (ORDER.index(base_name(n)) if base_name(n) in ORDER else len(ORDER), n))


def fit_slope(xs, ys):
    """Least-squares slope of log(y) against log(x); None with fewer than 2 usable points."""
    points = [(math.log(x), math.log(y)) for x, y in zip(xs, ys) if x > 0 and y > 0]
    if len(points) < 2:
        return None, None
    mean_x = sum(p[0] for p in points) / len(points)
    mean_y = sum(p[1] for p in points) / len(points)
    sxx = sum((p[0] - mean_x) ** 2 for p in points)
    if sxx == 0:
        return None, None
    slope = sum((p[0] - mean_x) * (p[1] - mean_y) for p in points) / sxx
    return slope, mean_y - slope * mean_x


def read_rows(path, required):
    with open(path, newline="") as file:
        reader = csv.DictReader(file)
        missing = [c for c in required if c not in (reader.fieldnames or [])]
        if missing:
            raise ValueError("%s: missing columns %s (has %s)" % (path, ",".join(missing), reader.fieldnames))
        return list(reader)


def read_record(folder, figure_id):
    path = os.path.join(folder, figure_id + ".json")
    if not os.path.exists(path):
        return {}
    with open(path) as file:
        return json.load(file)


def reference_noise(record):
    # A figure that measures its errors on part of the image (F12: the diffuse pixels)
    # records the reference's noise on that part; it wins over the whole-image value.
    own = record.get("numbers", {}).get("reference_noise_rmse_diffuse_pixels")
    if isinstance(own, (int, float)) and own > 0:
        return own
    for reference in record.get("references", []):
        noise = reference.get("noise_rmse")
        if isinstance(noise, (int, float)) and noise > 0:
            return noise
    return None


def draw_noise(ax, noise):
    if noise:
        ax.axhline(noise, color="grey", linewidth=1.0, alpha=0.8, label="reference noise %.3g" % noise)


def finish(ax, xlabel, title):
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("RMSE against the reference")
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=7.5, loc="lower left")


def chart_f18(folder):
    path = os.path.join(folder, "F18.csv")
    if not os.path.exists(path):
        print("plot_figures: %s not found: no F18 chart (run build/fig_convergence)" % path, file=sys.stderr)
        return False
    rows = read_rows(path, ["algorithm", "iterations", "seconds", "rmse"])
    record = read_record(folder, "F18")
    settings = record.get("settings", {})
    theory = record.get("numbers", {}).get("theory_slope", {})
    noise = reference_noise(record)
    runs = {}
    for row in rows:
        runs.setdefault(row["algorithm"], []).append({
            "iterations": int(row["iterations"]), "seconds": float(row["seconds"]),
            "rmse": float(row["rmse"]),
            "own": float(row["rmse_own"]) if row.get("rmse_own") not in (None, "") else float(row["rmse"]),
            "fitted": row.get("fitted", "1") == "1"})
    figure, axes = plt.subplots(1, 2, figsize=(12.0, 5.0), dpi=110)
    for ax, axis, xlabel in ((axes[0], "iterations", "iterations (samples per pixel)"),
                             (axes[1], "seconds", "rendering time [s] (wall clock)")):
        for index, name in enumerate(ordered(runs)):
            points = sorted(runs[name], key=lambda r: r["iterations"])
            color = color_of(name, index)
            xs = [p[axis] for p in points]
            fitted = [p for p in points if p["fitted"]]
            slope, intercept = fit_slope([p[axis] for p in fitted], [p["own"] for p in fitted])
            label = "%s: slope %s" % (name, "n/a" if slope is None else "%+.2f" % slope)
            sobol = name.endswith(SOBOL_SUFFIX)
            if axis == "iterations" and not sobol and isinstance(theory.get(name), (int, float)):
                label += " (theory %+.2f)" % theory[name]
            line, marker = ("-.", "s") if sobol else ("-", "o")
            ax.plot(xs, [p["rmse"] for p in points], ":", color=color, linewidth=0.9, alpha=0.45)
            # Hollow markers: checkpoints left out of the fit; filled: fitted.
            ax.plot(xs, [max(p["own"], 1e-12) for p in points], line, marker=marker, markersize=3.5,
                    markerfacecolor="white", linewidth=1.5, color=color, label=label)
            ax.plot([p[axis] for p in fitted], [max(p["own"], 1e-12) for p in fitted], marker, markersize=3.5,
                    color=color)
            if slope is not None:
                x0, x1 = fitted[0][axis], fitted[-1][axis]
                ax.plot([x0, x1], [math.exp(intercept) * x0 ** slope, math.exp(intercept) * x1 ** slope],
                        "--", color=color, linewidth=1.0, alpha=0.9)
        draw_noise(ax, noise)
        finish(ax, xlabel, "own RMSE vs %s (log-log; dotted: as measured; squares: Sobol)" % axis)
    alphas = settings.get("radius_alpha", {})
    subtitle = "F18 convergence rate: %s, %sx%s, mean MSE of %s runs per estimator (at most %s s or %s iterations each)" % (
        os.path.basename(str(settings.get("scene", "?"))), settings.get("resolution", "?"),
        settings.get("resolution", "?"), settings.get("runs_per_estimator", "?"),
        settings.get("seconds_per_run", "?"), settings.get("max_iterations_per_run", "?"))
    if alphas:
        subtitle += "; radius alpha " + ", ".join("%s %.3g" % (k, v) for k, v in alphas.items())
    figure.suptitle(subtitle + "\nslopes fitted (dashed) over the filled checkpoints (fitted=1 in F18.csv)",
                    fontsize=10)
    figure.tight_layout()
    out = os.path.join(folder, "F18_convergence.png")
    figure.savefig(out)
    plt.close(figure)
    print("plot_figures: wrote", out, file=sys.stderr)
    return True


def chart_f12(folder):
    path = os.path.join(folder, "F12.csv")
    if not os.path.exists(path):
        print("plot_figures: %s not found: no F12 chart (run build/fig_photon_mapping)" % path, file=sys.stderr)
        return False
    rows = read_rows(path, ["method", "photons", "seconds", "rmse"])
    noise = reference_noise(read_record(folder, "F12"))
    runs = {}
    for row in rows:
        runs.setdefault(row["method"], []).append({
            "photons": float(row["photons"]), "seconds": float(row["seconds"]), "rmse": float(row["rmse"])})
    figure, axes = plt.subplots(1, 2, figsize=(12.0, 5.0), dpi=110)
    for ax, axis, xlabel in ((axes[0], "photons", "photons (in total)"),
                             (axes[1], "seconds", "rendering time [s]")):
        for index, name in enumerate(ordered(runs)):
            points = sorted(runs[name], key=lambda r: r["photons"])
            color = color_of(name, index)
            xs = [p[axis] for p in points]
            ys = [p["rmse"] for p in points]
            slope, intercept = fit_slope(xs, ys)
            ax.plot(xs, ys, "-", marker="o", markersize=4, linewidth=1.5, color=color,
                    label="%s: rate %s" % (name, "n/a" if slope is None else "%+.2f" % slope))
            if slope is not None:
                ax.plot([xs[0], xs[-1]], [math.exp(intercept) * xs[0] ** slope, math.exp(intercept) * xs[-1] ** slope],
                        "--", color=color, linewidth=1.0, alpha=0.9)
        draw_noise(ax, noise)
        finish(ax, xlabel, "RMSE vs %s (log-log)" % axis)
    figure.suptitle("F12 biased but consistent: error against photons, fitted rates (dashed)", fontsize=10)
    figure.tight_layout()
    out = os.path.join(folder, "F12_convergence.png")
    figure.savefig(out)
    plt.close(figure)
    print("plot_figures: wrote", out, file=sys.stderr)
    return True


def main():
    if len(sys.argv) != 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0 if len(sys.argv) == 2 else 2)
    folder = sys.argv[1]
    if not os.path.isdir(folder):
        sys.exit("plot_figures: %s is not a folder" % folder)
    drawn = False
    for chart in (chart_f18, chart_f12):
        try:
            drawn = chart(folder) or drawn
        except (OSError, ValueError, KeyError) as error:
            print("plot_figures: %s" % error, file=sys.stderr)
    sys.exit(0 if drawn else 1)


if __name__ == "__main__":
    main()
