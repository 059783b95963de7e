#!/usr/bin/env python3
"""Write the figure gallery (docs/figures.md) from the records the figure programs wrote.

Every figure program (figures/fig_*.cpp) writes, per figure, <ID>.json and the PNGs it
names into one folder (docs/figures/, or build/figures-quick/ with --quick). This script
reads every F??.json there, in figure order, and writes one markdown page: per figure the
slide, the claim, whether it held in this run and the numbers behind it, each image with
its caption, time and error, the settings, the reference(s) and the time taken.

It also checks that every file the page shows exists, and fails (exit 1, naming the
missing files) when one does not: `make figures` relies on that.

Usage:  python3 figures/make_gallery.py FOLDER OUTPUT.md
        (make figures runs: docs/figures docs/figures.md; QUICK=1: build/figures-quick
        build/figures-quick/figures.md)
Needs:  Python 3, standard library only.
"""

import glob
import json
import os
import sys

EXPECTED = ["F%02d" % i for i in range(1, 23)]


def number(value):
    """A short, readable form of a number."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "%.4g" % value
    return str(value)


def flat_numbers(numbers, limit=12):
    """key = value pairs of the scalar numbers of a record (lists and tables left out)."""
    items = [(k, v) for k, v in numbers.items() if isinstance(v, (int, float, str, bool))]
    text = ", ".join("%s = %s" % (k.replace("_", " "), number(v)) for k, v in items[:limit])
    if len(items) > limit:
        text += ", ... (%d more in the .json)" % (len(items) - limit)
    return text


def settings_text(settings):
    return "; ".join("%s: %s" % (k.replace("_", " "), number(v) if not isinstance(v, (list, dict)) else json.dumps(v))
                     for k, v in settings.items())


def figure_section(record, link):
    """The markdown of one figure; link(file) gives the path as the page must write it."""
    out = []
    fid = record["id"]
    out.append("## %s — %s" % (fid, record["title"]))
    out.append("")
    out.append("*Slide:* %s  " % record["slide"])
    out.append("*Claim:* %s  " % record["claim"])
    if "claim_holds" in record:
        out.append("*In this run:* **%s** — %s  " % ("holds" if record["claim_holds"] else "does NOT hold",
                                                    record["verdict"]))
    elif "verdict" in record:
        out.append("*In this run:* %s  " % record["verdict"])
    out.append("*Made by:* `%s` in %.1f s%s" % (record["command"], record["seconds"],
                                              " (quick settings)" if record.get("quick") else ""))
    out.append("")
    panels = record.get("panels", [])
    charts = record.get("charts", [])
    files = []
    if charts:
        for chart in charts:
            out.append("![%s chart](%s)" % (fid, link(chart)))
            out.append("")
            files.append(chart)
    if panels and not record.get("page"):
        columns = min(4, len(panels))
        for start in range(0, len(panels), columns):
            row = panels[start:start + columns]
            out.append("| " + " | ".join("![%s](%s)" % (p["caption"], link(p["file"])) for p in row) + " |")
            out.append("|" + "---|" * len(row))
            cells = []
            for p in row:
                cell = "**%s**" % p["caption"]
                details = flat_numbers(p.get("numbers", {}), limit=5)
                if "exposure" in p:
                    details += (", " if details else "") + "shown x%s" % number(p["exposure"])
                if details:
                    cell += "<br>" + details
                cells.append(cell)
            out.append("| " + " | ".join(cells) + " |")
            out.append("")
        files.extend(p["file"] for p in panels)
    if record.get("page"):
        out.append("The whole report, every image with its time and error: [%s](%s)." % (record["page"], link(record["page"])))
        out.append("")
        files.append(record["page"])
    if record.get("numbers"):
        out.append("*Numbers:* %s" % flat_numbers(record["numbers"]))
        out.append("")
    if record.get("settings"):
        out.append("*Settings:* %s" % settings_text(record["settings"]))
        out.append("")
    for reference in record.get("references", []):
        s = reference["settings"]
        out.append("*Reference:* `%s` (%s): %s, %s iterations, %s, %.0f s; its own noise RMSE %.3g. Why: %s" % (
            reference["file"], s["scene"], s["algorithm"], s["iterations"], s["resolution"],
            reference["seconds"], reference["noise_rmse"], reference["why"]))
        out.append("")
        files.append("references/" + reference["file"])
    return "\n".join(out), files


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: make_gallery.py FOLDER OUTPUT.md")
    folder, output = sys.argv[1], sys.argv[2]
    records = {}
    for path in glob.glob(os.path.join(folder, "F[0-9][0-9].json")):
        with open(path, encoding="utf-8") as f:
            record = json.load(f)
        records[record["id"]] = record

    relative = os.path.relpath(folder, os.path.dirname(os.path.abspath(output)) or ".")

    def link(file):
        return file if relative == "." else relative + "/" + file

    quick = any(r.get("quick") for r in records.values())
    lines = ["# The course figures", "",
             "Generated by `figures/make_gallery.py` from the records the figure programs wrote "
             "(`make figures%s`); do not edit by hand." % (" QUICK=1" if quick else ""),
             "Every figure of `FIGURES.md` (the course's list) in the order of the course, each with its slide, "
             "its claim, whether the claim held in this run and the numbers behind it. Errors are RMSE (and "
             "relative MSE) against the reference named under each figure; times are wall-clock seconds on the "
             "machine that ran `make figures` (2 cores).", ""]
    if quick:
        lines += ["**Quick settings** (`make figures QUICK=1`): tiny images and budgets, made to check that every "
                  "program runs; the claims are only indicative at these settings.", ""]
    missing_figures = [f for f in EXPECTED if f not in records]
    if missing_figures:
        lines += ["Not produced in this run: %s." % ", ".join(missing_figures), ""]
    lines.append("| figure | claim | in this run |")
    lines.append("|---|---|---|")
    for fid in EXPECTED:
        if fid in records:
            r = records[fid]
            state = ("holds" if r["claim_holds"] else "**does not hold**") if "claim_holds" in r else "—"
            lines.append("| [%s %s](#%s) | %s | %s |" % (fid, r["title"], anchor(fid, r["title"]), r["claim"], state))
    lines.append("")
    missing_files = []
    for fid in EXPECTED:
        if fid not in records:
            continue
        text, files = figure_section(records[fid], link)
        lines += [text, ""]
        missing_files += [f for f in files if not os.path.exists(os.path.join(folder, f))]
    with open(output + ".partial", "w", encoding="utf-8", newline="\n") as f:
        f.write("\n".join(lines).rstrip() + "\n")
    os.replace(output + ".partial", output)
    print("make_gallery: %s: %d figures%s" % (output, len(records),
                                              "; missing: " + ", ".join(missing_figures) if missing_figures else ""))
    if missing_files:
        sys.exit("make_gallery: files the page shows do not exist in %s: %s" % (folder, ", ".join(missing_files)))
    if missing_figures:
        sys.exit("make_gallery: no record for %s in %s" % (", ".join(missing_figures), folder))


def anchor(fid, title):
    """GitHub's anchor of the heading '## <fid> — <title>'."""
    text = ("%s — %s" % (fid, title)).lower()
    kept = "".join(c for c in text if c.isalnum() or c in " -_")
    return kept.replace(" ", "-")


if __name__ == "__main__":
    main()
