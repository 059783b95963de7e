#!/usr/bin/env python3
"""smallvcm's environment light beside Mitsuba 3's `envmap` emitter, on one scene.

    build/mitsuba-venv/bin/python benchmarks/mitsuba_envmap.py [--out DIR] [--map FILE.hdr]
        [--spp N] [--batches B] [--resolution WxH]

(`make bench-mitsuba` makes that virtual environment; this script needs only Mitsuba's
`scalar_rgb` variant, so no LLVM.) Benchmark-only, like benchmarks/mitsuba_compare.py,
whose PFM reader and smallvcm runner it shares; never a test dependency.

The scene, written here as a glTF file (DIR/envmap_spheres.gltf) and as a Mitsuba
dictionary: a white Lambert sphere (reflectance 0.8) and a perfect-mirror sphere, side by
side, seen from the front by a pinhole camera, lit only by the map (default: the CC0 HDRI
scenes/hdri/royal_esplanade_1k.hdr, converted once to a float PFM so that both programs
read the same texels). The camera sees the map directly around the spheres and reflected
in the mirror, so the image shows whether the two programs orient the map alike; the
white sphere integrates it, so the image also shows whether they light alike.

The two conventions (from each program's source):
- smallvcm (docs/scene_format.md 5.4): the texel column at u faces
  phi = 2 pi (u - 1/2) measured from +X towards +Z: (cos phi sin theta, cos theta,
  sin phi sin theta), theta = pi v; u = 1/2 faces +X, u = 3/4 faces +Z.
- Mitsuba 3 (src/emitters/envmap.cpp, uv_to_direction): (sin(2 pi u) sin theta,
  cos theta, -cos(2 pi u) sin theta); u = 0 faces -Z, u = 1/4 faces +X, u = 1/2 faces +Z.
  Both put the top row at +Y.
So smallvcm's direction for u is Mitsuba's direction for u - 1/4: Mitsuba's map must be
turned about +Y so that +X goes to -Z and +Z to +X, a rotation by +90 degrees (right-hand
rule, Mitsuba's `rotate`): to_world = rotate([0, 1, 0], 90 + a) for smallvcm's
--envmap-rotate a. The script also renders Mitsuba with to_world = identity (the two
conventions taken as equal), to show that the comparison tells the difference.

What still differs, by design: smallvcm looks up the nearest texel, Mitsuba interpolates
bilinearly and puts the first and last rows at the poles (theta = pi y / (H - 1) instead
of pi (y + 1/2) / H): a fraction of a texel, which shows in single pixels of the
background and the mirror, not in a region's mean.

Compared: each image's mean, and the means of a 4 x 4 grid of regions, as relative
differences with z = (m_smallvcm - m_mitsuba) / sqrt(se_smallvcm^2 + se_mitsuba^2), each
standard error from the spread of B independent batches (other seeds). Writes
DIR/envmap_agreement.txt (and prints it) and the images as PFM.
"""

import argparse
import math
import os
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mitsuba_compare as common  # noqa: E402  (the PFM reader, the smallvcm binary's path)

ROOT = common.ROOT
MAX_PATH_LENGTH = common.MAX_PATH_LENGTH


def write_pfm(path, image):
    """A float PFM of image (rows top first), as smallvcm and Mitsuba both read it."""
    height, width, _ = image.shape
    with open(path, "wb") as f:
        f.write(f"PF\n{width} {height}\n-1\n".encode())
        f.write(np.ascontiguousarray(image[::-1], dtype="<f4").tobytes())


def write_scene(path, aspect, yfov):
    """Two unit spheres at x = -1.1 (white Lambert) and x = +1.1 (mirror), a camera at
    (0, 0.6, 5) looking at the origin, +Y up; no light (the map is the light)."""
    import json
    eye = np.array([0.0, 0.6, 5.0])
    forward = -eye / np.linalg.norm(eye)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    # glTF camera: looks along its -Z, +Y up; columns right, up, -forward, position.
    matrix = np.column_stack([np.r_[right, 0], np.r_[up, 0], np.r_[-forward, 0], np.r_[eye, 1]])
    gltf = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 1, 2]}],
        "extensionsUsed": ["SMALLVCM_sphere", "SMALLVCM_material"],
        "extensionsRequired": ["SMALLVCM_sphere", "SMALLVCM_material"],
        "materials": [{"extensions": {"SMALLVCM_material": {"diffuse": [0.8, 0.8, 0.8]}}},
                      {"extensions": {"SMALLVCM_material": {"mirror": [1, 1, 1]}}}],
        "nodes": [{"translation": [-1.1, 0, 0], "extensions": {"SMALLVCM_sphere": {"radius": 1.0, "material": 0}}},
                  {"translation": [1.1, 0, 0], "extensions": {"SMALLVCM_sphere": {"radius": 1.0, "material": 1}}},
                  {"camera": 0, "matrix": matrix.T.reshape(-1).tolist()}],
        "cameras": [{"type": "perspective", "perspective": {"yfov": yfov, "aspectRatio": aspect, "znear": 0.01}}],
    }
    with open(path, "w") as f:
        json.dump(gltf, f)
    return eye, forward, up


def mitsuba_scene(mi, map_path, rotation_degrees, eye, forward, up, fov_x, width, height):
    transform = mi.ScalarTransform4f()
    if rotation_degrees is not None:
        transform = transform.rotate(axis=[0, 1, 0], angle=rotation_degrees)
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": MAX_PATH_LENGTH, "rr_depth": 5, "hide_emitters": False},
        "white": {"type": "sphere", "center": [-1.1, 0, 0], "radius": 1.0,
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8, 0.8, 0.8]}}},
        "mirror": {"type": "sphere", "center": [1.1, 0, 0], "radius": 1.0,
                   "bsdf": {"type": "conductor", "material": "none"}},
        "light": {"type": "envmap", "filename": map_path, "to_world": transform},
        "sensor": {"type": "perspective", "fov_axis": "x", "fov": math.degrees(fov_x), "near_clip": 1e-3,
                   "to_world": mi.ScalarTransform4f().look_at(origin=eye.tolist(), target=(eye + forward).tolist(),
                                                              up=up.tolist()),
                   "sampler": {"type": "independent", "sample_count": 1},
                   "film": {"type": "hdrfilm", "width": width, "height": height, "pixel_format": "rgb",
                            "sample_border": False, "rfilter": {"type": "box"}}},
    })


def region_means(image, grid=4):
    height, width, _ = image.shape
    luminance = image @ np.array([0.2126, 0.7152, 0.0722])
    return np.array([[luminance[height * j // grid:height * (j + 1) // grid, width * i // grid:width * (i + 1) // grid].mean()
                      for i in range(grid)] for j in range(grid)])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default=os.path.join(ROOT, "build", "mitsuba"))
    parser.add_argument("--map", default=os.path.join(ROOT, "scenes", "hdri", "royal_esplanade_1k.hdr"))
    parser.add_argument("--rotate", type=float, default=0.0, help="smallvcm's --envmap-rotate (degrees)")
    parser.add_argument("--spp", type=int, default=64, help="samples per pixel per batch")
    parser.add_argument("--batches", type=int, default=4)
    parser.add_argument("--resolution", default="192x120")
    args = parser.parse_args()
    width, height = map(int, args.resolution.split("x"))
    os.makedirs(args.out, exist_ok=True)

    import drjit as dr
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    dr.set_thread_count(1)

    # One float PFM of the map for both programs (Mitsuba decodes the RGBE file once).
    texels = np.array(mi.Bitmap(args.map).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, False))
    map_pfm = os.path.join(args.out, "envmap.pfm")
    write_pfm(map_pfm, texels)

    aspect, yfov = width / height, 0.7
    gltf = os.path.join(args.out, "envmap_spheres.gltf")
    eye, forward, up = write_scene(gltf, aspect, yfov)
    fov_x = 2 * math.atan(math.tan(yfov / 2) * aspect)

    lines = [f"smallvcm pt vs Mitsuba 3 scalar_rgb path, {width}x{height}, {args.batches} batches x {args.spp} spp, "
             f"map {os.path.relpath(args.map, ROOT) if os.path.abspath(args.map).startswith(ROOT + os.sep) else args.map} "
             f"({texels.shape[1]}x{texels.shape[0]}), smallvcm --envmap-rotate "
             f"{args.rotate:g}, {time.strftime('%Y-%m-%d %H:%M')} UTC, load {os.getloadavg()[0]:.1f}"]

    ours = []
    for b in range(args.batches):
        path = os.path.join(args.out, "envmap_smallvcm.pfm")
        subprocess.run([common.SMALLVCM, "-q", "-s", gltf, "-a", "pt", "--sampler", "independent", "-j", "1", "-r", f"{width}x{height}",
                        "-i", str(args.spp), "--seed", str(1 + b), "--max-path-length", str(MAX_PATH_LENGTH),
                        "--envmap", map_pfm, "--envmap-rotate", str(args.rotate), "-o", path], check=True)
        ours.append(common.read_pfm(path))
    results = {}
    for name, rotation in (("derived to_world = rotate(+Y, 90 + a)", 90.0 + args.rotate), ("to_world = identity", None)):
        scene = mitsuba_scene(mi, map_pfm, rotation, eye, forward, up, fov_x, width, height)
        theirs = [np.array(mi.render(scene, spp=args.spp, seed=1000 + b), dtype=np.float64) for b in range(args.batches)]
        results[name] = theirs
        write_pfm(os.path.join(args.out, f"envmap_mitsuba_{'derived' if rotation is not None else 'identity'}.pfm"),
                  np.mean(theirs, axis=0))
    write_pfm(os.path.join(args.out, "envmap_smallvcm_mean.pfm"), np.mean(ours, axis=0))

    def stats(images):
        means = np.array([region_means(image) for image in images])
        whole = np.array([(image @ np.array([0.2126, 0.7152, 0.0722])).mean() for image in images])
        return (whole.mean(), whole.std(ddof=1) / math.sqrt(len(images)),
                means.mean(axis=0), means.std(axis=0, ddof=1) / math.sqrt(len(images)))

    m_ours, se_ours, r_ours, rse_ours = stats(ours)
    for name, theirs in results.items():
        m_theirs, se_theirs, r_theirs, rse_theirs = stats(theirs)
        z = (m_ours - m_theirs) / math.hypot(se_ours, se_theirs)
        relative = (r_ours - r_theirs) / r_theirs
        zr = (r_ours - r_theirs) / np.hypot(rse_ours, rse_theirs)
        lines.append(f"Mitsuba with {name}: image mean (luminance) smallvcm {m_ours:.5f} +- {se_ours:.5f}, "
                     f"Mitsuba {m_theirs:.5f} +- {se_theirs:.5f}: relative difference {100 * (m_ours - m_theirs) / m_theirs:+.2f} % "
                     f"(z {z:+.2f}); 4x4 regions: relative differences {100 * np.min(relative):+.1f} % .. "
                     f"{100 * np.max(relative):+.1f} %, median |.| {100 * np.median(np.abs(relative)):.2f} %, "
                     f"max |z| {np.max(np.abs(zr)):.1f}")
        lines.append("  per region (rows top to bottom), relative difference %: " +
                     " / ".join(" ".join(f"{100 * x:+.1f}" for x in row) for row in relative))
    text = "\n".join(lines) + "\n"
    print(text, end="")
    with open(os.path.join(args.out, "envmap_agreement.txt"), "a") as f:
        f.write(text)


if __name__ == "__main__":
    main()
