#!/usr/bin/python3
"""Error of a smallvcm image and of a SmallVCM image against one reference.

    /usr/bin/python3 benchmarks/smallvcm_equal_error.py REFERENCE.pfm OURS.pfm THEIRS.hdr

SmallVCM writes Radiance HDR (RGBE: 8-bit mantissas), so our image is rounded the same
way before it is compared: both then carry the same quantisation error. SmallVCM's rows
are tried as written and upside down, and the orientation closer to the reference is
used (and reported). Prints the mean of each image and its RMSE against the reference.
Used by benchmarks/compare_smallvcm.sh. Plain Python, no packages.
"""

import array
import math
import sys


def read_pfm(path):
    """Rows of floats (r, g, b, r, g, b, ...), top row first."""
    with open(path, "rb") as f:
        if f.readline().strip() != b"PF":
            sys.exit(f"{path}: not a colour PFM file")
        width, height = map(int, f.readline().split())
        scale = float(f.readline())
        values = array.array("f")
        values.frombytes(f.read())
    if scale > 0:  # big-endian
        values.byteswap()
    rows = [list(values[3 * width * y:3 * width * (y + 1)]) for y in range(height)]
    rows.reverse()  # PFM stores the bottom row first
    return rows


def read_hdr(path):
    """SmallVCM's flat (not run-length encoded) RGBE file, rows as written."""
    data = open(path, "rb").read()
    start = data.index(b"\n\n") + 2
    end = data.index(b"\n", start)
    dims = data[start:end].split()  # -Y height +X width
    height, width = int(dims[1]), int(dims[3])
    pixels = data[end + 1:]
    rows = []
    for y in range(height):
        row = []
        for x in range(width):
            r, g, b, e = pixels[4 * (y * width + x):4 * (y * width + x) + 4]
            unit = math.ldexp(1.0, e - 136) if e else 0.0
            row += [(r + 0.5) * unit, (g + 0.5) * unit, (b + 0.5) * unit] if e else [0.0, 0.0, 0.0]
        rows.append(row)
    return rows


def rgbe_rounded(rows):
    """The values SmallVCM's HDR writer would store for these (frexp, 8-bit mantissas)."""
    out = []
    for row in rows:
        rounded = []
        for k in range(0, len(row), 3):
            r, g, b = row[k:k + 3]
            v = max(r, g, b)
            if v < 1e-32:
                rounded += [0.0, 0.0, 0.0]
                continue
            mantissa, exponent = math.frexp(v)
            s = mantissa * 256.0 / v
            unit = math.ldexp(1.0, exponent - 8)
            rounded += [(int(r * s) + 0.5) * unit, (int(g * s) + 0.5) * unit, (int(b * s) + 0.5) * unit]
        out.append(rounded)
    return out


def rmse(a, b):
    total = sum((x - y) ** 2 for ra, rb in zip(a, b) for x, y in zip(ra, rb))
    return math.sqrt(total / (len(a) * len(a[0])))


def mean(a):
    return sum(sum(row) for row in a) / (len(a) * len(a[0]))


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    reference = read_pfm(sys.argv[1])
    ours = rgbe_rounded(read_pfm(sys.argv[2]))
    theirs = read_hdr(sys.argv[3])
    if len(reference) != len(theirs) or len(reference) != len(ours):
        sys.exit("the three images differ in size")
    as_written, flipped = rmse(theirs, reference), rmse(theirs[::-1], reference)
    if flipped < as_written:
        theirs = theirs[::-1]
    theirs_rmse, ours_rmse = min(as_written, flipped), rmse(ours, reference)
    print("reference mean %.5f | SmallVCM: mean %.5f, RMSE %.5f (rows %s) | smallvcm: mean %.5f, RMSE %.5f "
          "| RMSE ratio smallvcm / SmallVCM %.3f" % (
              mean(reference), mean(theirs), theirs_rmse, "flipped" if flipped < as_written else "as written",
              mean(ours), ours_rmse, ours_rmse / theirs_rmse))


if __name__ == "__main__":
    main()
