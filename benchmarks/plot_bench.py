#!/usr/bin/python3
"""Charts from the CSVs of build/bench --csv PREFIX.

    /usr/bin/python3 benchmarks/plot_bench.py docs/performance/bench_bvh.csv docs/performance/bench_render.csv

Each CSV given is recognised by its header (one of the two, or both, in any order):

PREFIX_bvh.csv (the BVH scaling: bumpy spheres of 10^2 .. 10^6 triangles, one thread)
    -> bvh_scaling.png, two log-log panels against the triangle count n:
       left, Scene::Finalize time in ms (the BVH build and the rest of Finalize) with
       reference lines c n and c n log2 n fitted through the points (they differ little
       over five decades, which is the point: the build is close to linear);
       right, nearest-hit and shadow rays per second, per wall second (solid) and per
       CPU second of the tracing thread (dashed; the two part when other programs share
       the cores), with the tree's depth at each point and an O(log n) reference,
       rays/s proportional to 1 / log2 n through the smallest mesh's nearest-hit rate
       (not fitted: where the measured rates fall below it, each level of the tree costs
       more than on the small meshes, as the tree outgrows the caches).

PREFIX_render.csv (seconds per iteration of every estimator on every Cornell scene)
    -> speed_per_iteration.png, a dot chart with a log y-axis: one group per Cornell
       scene, one column per estimator (the colours of benchmarks/plot_convergence.py), one
       marker per thread count (1 thread: filled circle, 2 threads: open diamond, ...)
       joined by a thin line, whose length on the log axis is the speed-up. Wall
       seconds by default; --clock cpu plots CPU seconds per iteration instead (the
       figure that stays comparable when the cores were shared).

The PNGs go to --out-dir (default: the folder of the first CSV). A missing, empty or
malformed CSV (unknown header, a cell that is not a number, a value a log axis cannot
show) ends the script with exit code 1 and a line naming the file and row.

Needs matplotlib (Debian: python3-matplotlib); uses the Agg backend, no display.
"""

import argparse
import csv
import math
import os
import sys
from collections import OrderedDict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402

BVH_COLUMNS = ["triangles", "build_ms", "build_runs", "build_cpu_utilisation", "nodes", "depth", "bvh_mib",
               "nearest_rays_per_s", "shadow_rays_per_s", "nearest_rays_per_cpu_s", "shadow_rays_per_cpu_s",
               "nearest_hit_fraction", "shadow_occluded_fraction", "peak_rss_mib"]
RENDER_COLUMNS = ["scene", "scene_name", "algorithm", "threads", "iterations", "s_per_iteration",
                  "cpu_s_per_iteration", "rays_per_s", "cpu_utilisation", "peak_rss_mib", "resolution"]
# Columns that are text; every other one must be a number.
TEXT_COLUMNS = {"scene_name", "algorithm", "resolution"}
# Columns a log axis shows: they must be > 0.
POSITIVE_COLUMNS = {"triangles", "build_ms", "nearest_rays_per_s", "shadow_rays_per_s", "nearest_rays_per_cpu_s",
                    "shadow_rays_per_cpu_s", "threads", "iterations", "s_per_iteration", "cpu_s_per_iteration"}

# The same colours and order as benchmarks/plot_convergence.py, so that an estimator looks the
# same on every chart of docs/performance.md.
COLORS = {
    "pt": "#1f77b4", "lt": "#8c564b", "ppm": "#2ca02c", "bpm": "#9467bd",
    "bpt": "#d62728", "vcm": "#ff7f0e", "pm": "#7f7f7f", "pmfg": "#17becf", "el": "#bcbd22",
}
ORDER = ["el", "pt", "lt", "ppm", "bpm", "bpt", "vcm", "pm", "pmfg"]
# Markers per thread count, in the order the thread counts appear: filled first.
THREAD_MARKERS = [("o", True), ("D", False), ("s", False), ("^", False), ("v", False)]


def fail(message):
    sys.exit("plot_bench.py: " + message)


def read_csv(path):
    """("bvh" or "render", [row dict with numbers converted]) of one CSV of build/bench."""
    try:
        file = open(path, newline="")
    except OSError as error:
        fail("%s: cannot read (%s); make it with build/bench --csv PREFIX" % (path, error.strerror))
    with file:
        reader = csv.reader(file)
        header = next(reader, None)
        if header == BVH_COLUMNS:
            kind = "bvh"
        elif header == RENDER_COLUMNS:
            kind = "render"
        else:
            fail("%s: the header is %s; expected the one of PREFIX_bvh.csv (%s) or of PREFIX_render.csv (%s)"
                 % (path, "missing (empty file)" if header is None else ",".join(header),
                    ",".join(BVH_COLUMNS), ",".join(RENDER_COLUMNS)))
        rows = []
        for cells in reader:
            line = reader.line_num
            if not cells:
                continue
            if len(cells) != len(header):
                fail("%s:%d: %d cells, the header has %d" % (path, line, len(cells), len(header)))
            row = {}
            for name, cell in zip(header, cells):
                if name in TEXT_COLUMNS:
                    if not cell:
                        fail("%s:%d: %s is empty" % (path, line, name))
                    row[name] = cell
                    continue
                try:
                    value = float(cell)
                except ValueError:
                    fail("%s:%d: %s = '%s' is not a number" % (path, line, name, cell))
                if not math.isfinite(value) or (name in POSITIVE_COLUMNS and value <= 0):
                    fail("%s:%d: %s = %s cannot be plotted (must be %s)"
                         % (path, line, name, cell, "> 0" if name in POSITIVE_COLUMNS else "finite"))
                row[name] = value
            rows.append(row)
    if not rows:
        fail("%s: no rows under the header" % path)
    return kind, rows


def fit_through_origin_log(xs, ys, model):
    """The factor c minimising the log-space error of y = c model(x): the geometric mean
    of y / model(x) (each point counts as much as the others on a log-log chart)."""
    return math.exp(sum(math.log(y / model(x)) for x, y in zip(xs, ys)) / len(xs))


def si(value):
    """3.9 M, 917 k: the report's way of writing rates."""
    if value >= 1e6:
        return "%.3g M" % (value / 1e6)
    if value >= 1e3:
        return "%.3g k" % (value / 1e3)
    return "%.3g" % value


def bvh_chart(rows, path):
    rows = sorted(rows, key=lambda r: r["triangles"])
    ns = [r["triangles"] for r in rows]
    n_lo, n_hi = min(ns), max(ns)
    if n_lo < 2:
        fail("the BVH CSV has a mesh of %g triangles; log2 n needs n >= 2" % n_lo)
    dense = [n_lo * (n_hi / n_lo) ** (i / 50.0) for i in range(51)] if n_hi > n_lo else [n_lo]
    figure, (left, right) = plt.subplots(1, 2, figsize=(12.0, 5.0), dpi=110)

    # Left: build time.
    build = [r["build_ms"] for r in rows]
    left.plot(ns, build, "-o", color="#1f77b4", linewidth=1.8, markersize=5, label="Scene::Finalize (fastest run), ms")
    for n, ms in zip(ns, build):
        left.annotate("%.3g ms" % ms, (n, ms), textcoords="offset points", xytext=(6, -12), fontsize=7.5,
                      color="#1f77b4")
    c_n = fit_through_origin_log(ns, build, lambda n: n)
    c_nlogn = fit_through_origin_log(ns, build, lambda n: n * math.log2(n))
    left.plot(dense, [c_n * n for n in dense], color="black", linewidth=0.9, linestyle=(0, (1, 3)), alpha=0.7,
              label="reference O(n): %.3g µs × n" % (1e3 * c_n))
    left.plot(dense, [c_nlogn * n * math.log2(n) for n in dense], color="black", linewidth=0.9,
              linestyle=(0, (5, 4)), alpha=0.7, label="reference O(n log n): %.3g µs × n log₂ n" % (1e3 * c_nlogn))
    left.set_xscale("log")
    left.set_yscale("log")
    left.yaxis.set_major_formatter(FuncFormatter(lambda y, _: "%g" % y))
    left.set_xlabel("triangles n")
    left.set_ylabel("build time [ms] (wall)")
    left.set_title("Build: Scene::Finalize (normals, bounds, BVH)", fontsize=10)
    left.grid(True, which="both", alpha=0.25)
    left.legend(fontsize=8, loc="upper left")

    # Right: tracing throughput.
    series = [("nearest_rays_per_s", "nearest-hit rays/s (wall)", "#d62728", "-", "o"),
              ("shadow_rays_per_s", "shadow rays/s (wall)", "#2ca02c", "-", "s"),
              ("nearest_rays_per_cpu_s", "nearest-hit rays/s (CPU s)", "#d62728", "--", "o"),
              ("shadow_rays_per_cpu_s", "shadow rays/s (CPU s)", "#2ca02c", "--", "s")]
    # In millions, so that the log axis reads 1, 2, 3 instead of 10^6, 2x10^6, ...
    for column, label, color, style, marker in series:
        solid = style == "-"
        right.plot(ns, [r[column] / 1e6 for r in rows], style, marker=marker, color=color, linewidth=1.8 if solid else 1.0,
                   markersize=5 if solid else 4, markerfacecolor=color if solid else "none", label=label,
                   alpha=1.0 if solid else 0.8)
    for n, r in zip(ns, rows):
        # Below the lowest line (nearest-hit, wall), where no other line runs.
        right.annotate("%s\ndepth %d" % (si(r["nearest_rays_per_s"]), r["depth"]), (n, r["nearest_rays_per_s"] / 1e6),
                       textcoords="offset points", xytext=(0, -10), ha="center", va="top", fontsize=7,
                       color="#444444", bbox=dict(boxstyle="round,pad=0.15", facecolor="white", edgecolor="none",
                                                  alpha=0.8))
    # O(log n) traversal: rays/s proportional to 1 / log2 n, through the smallest mesh's
    # nearest-hit rate. Not fitted: a fit through all points bends to the largest meshes,
    # where the tree no longer fits in the caches and every level costs more; this line
    # shows where the measured rates fall below what the depth alone explains.
    if n_hi > n_lo:
        anchor = rows[0]["nearest_rays_per_s"] * math.log2(n_lo)
        right.plot(dense, [anchor / math.log2(n) / 1e6 for n in dense], color="black", linewidth=0.9,
                   linestyle=(0, (5, 4)), alpha=0.7,
                   label="reference O(log n) per ray: ∝ 1 / log₂ n,\nthrough the first nearest-hit point")
    right.set_xscale("log")
    right.set_yscale("log")
    low = min(min(r[s[0]] for r in rows) for s in series)
    high = max(max(r[s[0]] for r in rows) for s in series)
    right.set_ylim(low / 1e6 / 1.7, high / 1e6 * 1.25)  # room for the labels below the points
    right.yaxis.set_major_formatter(FuncFormatter(lambda y, _: "%g" % y))
    right.yaxis.set_minor_formatter(FuncFormatter(lambda y, _: "%g" % y if ("%g" % y).lstrip("0.")[:1] in ("2", "3", "5") else ""))
    right.tick_params(axis="y", which="minor", labelsize=8)
    for axis in (left, right):
        axis.set_xlim(n_lo / 1.8, n_hi * 1.8)  # room for the labels at the ends
    right.set_xlabel("triangles n")
    right.set_ylabel("million rays per second, one thread")
    right.set_title("Tracing: Scene::Intersect (nearest hit), Scene::Occluded (shadow)", fontsize=10)
    right.grid(True, which="both", alpha=0.25)
    right.legend(fontsize=8, loc="upper right")

    figure.suptitle("BVH scaling on a bumpy sphere of n triangles (one thread; labels: nearest-hit rays/s and tree depth)",
                    fontsize=11)
    figure.tight_layout()
    figure.savefig(path, bbox_inches="tight")  # the legends outside the axes included
    plt.close(figure)


def speed_chart(rows, clock, path):
    column = "s_per_iteration" if clock == "wall" else "cpu_s_per_iteration"
    scenes = OrderedDict()
    for r in sorted(rows, key=lambda r: r["scene"]):
        scenes.setdefault(int(r["scene"]), r["scene_name"])
    algorithms = sorted({r["algorithm"] for r in rows},
                        key=lambda a: (ORDER.index(a) if a in ORDER else len(ORDER), a))
    threads = sorted({int(r["threads"]) for r in rows})
    values = {}
    for r in rows:
        key = (int(r["scene"]), r["algorithm"], int(r["threads"]))
        if key in values:
            fail("scene %d, %s, %d thread(s) appears twice in the render CSV" % key)
        values[key] = r[column]
    resolutions = sorted({r["resolution"] for r in rows})

    group_width = len(algorithms) + 1.5  # one column per estimator, a gap between scenes
    figure, ax = plt.subplots(figsize=(max(8.0, 0.25 * group_width * len(scenes) + 1.5), 5.6), dpi=110)
    # The thread counts of one column side by side (not on top of each other, where a
    # marker would hide another of about the same value).
    spread = 0.5 / max(1, len(threads) - 1) if len(threads) > 1 else 0.0
    offsets = {t: (k - (len(threads) - 1) / 2.0) * spread for k, t in enumerate(threads)}
    for g, scene in enumerate(scenes):
        for i, algorithm in enumerate(algorithms):
            x = g * group_width + i
            ys = [(t, values[(scene, algorithm, t)]) for t in threads if (scene, algorithm, t) in values]
            if len(ys) > 1:
                ax.plot([x + offsets[t] for t, _ in ys], [y for _, y in ys], color=COLORS.get(algorithm, "black"),
                        linewidth=1.0, alpha=0.6)
            for t, y in ys:
                marker, filled = THREAD_MARKERS[min(threads.index(t), len(THREAD_MARKERS) - 1)]
                color = COLORS.get(algorithm, "black")
                ax.plot([x + offsets[t]], [y], marker=marker, markersize=6.5, color=color,
                        markerfacecolor=color if filled else "white", markeredgewidth=1.4, linestyle="none")
        if g > 0:
            ax.axvline(g * group_width - 1.25, color="grey", linewidth=0.6, alpha=0.5)
    ax.set_yscale("log")
    # Estimator names under their columns, the scene under its group.
    ax.set_xticks([g * group_width + i for g in range(len(scenes)) for i in range(len(algorithms))])
    ax.set_xticklabels(algorithms * len(scenes), fontsize=7, rotation=90)
    for g, (scene, name) in enumerate(scenes.items()):
        ax.text(g * group_width + (len(algorithms) - 1) / 2.0, -0.13, "%d: %s" % (scene, name), ha="center", va="top",
                fontsize=8.5, transform=ax.get_xaxis_transform())
    ax.set_xlim(-1, (len(scenes) - 1) * group_width + len(algorithms))
    ax.set_ylabel("%s seconds per iteration (log scale)" % ("wall" if clock == "wall" else "CPU"))
    ax.grid(True, axis="y", which="both", alpha=0.25)
    algorithm_handles = [Line2D([], [], linestyle="none", marker="o", markersize=7, color=COLORS.get(a, "black"),
                                label=a) for a in algorithms]
    thread_handles = []
    for k, t in enumerate(threads):
        marker, filled = THREAD_MARKERS[min(k, len(THREAD_MARKERS) - 1)]
        thread_handles.append(Line2D([], [], linestyle="none", marker=marker, markersize=7, color="black",
                                     markerfacecolor="black" if filled else "white", markeredgewidth=1.4,
                                     label="%d thread%s" % (t, "" if t == 1 else "s")))
    legend = ax.legend(handles=algorithm_handles, title="estimator", fontsize=8,
                       title_fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    ax.add_artist(legend)
    ax.legend(handles=thread_handles, title="threads", fontsize=8, title_fontsize=8, loc="lower left",
              bbox_to_anchor=(1.01, 0.0), borderaxespad=0.0)
    ax.yaxis.set_major_formatter(FuncFormatter(lambda y, _: "%g" % y))
    ax.yaxis.set_minor_formatter(FuncFormatter(lambda y, _: "%g" % y if ("%g" % y).lstrip("0.")[:1] in ("2", "5") else ""))
    ax.tick_params(axis="y", which="minor", labelsize=7)
    ax.set_title("Cost of one iteration (one sample per pixel, %s) per estimator and Cornell scene\n"
                 "%s time; a line joins the thread counts of a column: its drop is the speed-up"
                 % (", ".join(resolutions), "wall-clock" if clock == "wall" else "CPU (user + system of all threads)"),
                 fontsize=10)
    figure.tight_layout()
    figure.savefig(path, bbox_inches="tight")  # the legends outside the axes included
    plt.close(figure)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("csv", nargs="+", help="PREFIX_bvh.csv and/or PREFIX_render.csv written by build/bench --csv")
    parser.add_argument("--out-dir", help="folder for the PNGs (default: the folder of the first CSV)")
    parser.add_argument("--clock", choices=["wall", "cpu"], default="wall",
                        help="seconds per iteration by the wall clock (default) or in CPU time")
    args = parser.parse_args()

    tables = {}
    for path in args.csv:
        kind, rows = read_csv(path)
        if kind in tables:
            fail("%s: a second %s CSV (the first was %s)" % (path, kind, tables[kind][0]))
        tables[kind] = (path, rows)
    out_dir = args.out_dir or os.path.dirname(os.path.abspath(args.csv[0]))
    try:
        os.makedirs(out_dir, exist_ok=True)
    except OSError as error:
        fail("%s: cannot create the output folder (%s)" % (out_dir, error.strerror))
    charts = []
    if "bvh" in tables:
        charts.append(("bvh_scaling.png", lambda p: bvh_chart(tables["bvh"][1], p)))
    if "render" in tables:
        charts.append(("speed_per_iteration.png", lambda p: speed_chart(tables["render"][1], args.clock, p)))
    for name, draw in charts:
        path = os.path.join(out_dir, name)
        # Through PATH.partial.png and a rename, as everywhere in the project: an
        # interrupted run never leaves half a picture under the real name.
        partial = os.path.join(out_dir, name[:-len(".png")] + ".partial.png")
        try:
            draw(partial)
            os.replace(partial, path)
        except OSError as error:
            if os.path.exists(partial):
                os.remove(partial)
            fail("%s: cannot write (%s)" % (path, error.strerror))
        print("wrote", path, file=sys.stderr)


if __name__ == "__main__":
    main()
