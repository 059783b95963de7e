#!/usr/bin/env python3
"""Does the ray epsilon bias a dense medium? smallvcm's pt against its bpt on
scenes/dense_scattering_sphere.gltf (mean free path 0.05), as shipped and with a copy of the
floor 40 units below the closed room, which leaves the image alone but makes the scene
radius, and with it the ray epsilon (a fixed fraction of it), about 10 times larger.

    build/mitsuba-venv/bin/python benchmarks/media_epsilon_check.py [--batches 8] [--spp 64]

(any Python with NumPy; needs build/smallvcm.) Prints each estimator's image mean with its
standard error (from independent batches) and pt / bpt. Unbiased estimators of the same
scene give pt / bpt = 1 within noise in both versions; if the ratio moves with the
epsilon, the epsilon enters the estimate (a segment from a medium point starts one epsilon
along its direction, and the free flight is sampled from there). Writes its scenes and
images to build/media_epsilon/. About 1 minute of CPU at the defaults (32 x 32 pixels).
"""
import argparse
import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mitsuba_compare as mc  # noqa: E402  (its glTF reading and smallvcm runner; no Mitsuba needed)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--batches", type=int, default=8)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--resolution", type=int, default=32)
    parser.add_argument("--max-path-length", type=int, default=64)
    args = parser.parse_args()
    out = os.path.join(mc.ROOT, "build", "media_epsilon")
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(mc.ROOT, "scenes", "dense_scattering_sphere.gltf")) as f:
        gltf = json.load(f)
    for buffer in gltf["buffers"]:
        if not buffer["uri"].startswith("data:"):
            buffer["uri"] = os.path.join(mc.ROOT, "scenes", buffer["uri"])
    paths = {"as shipped": os.path.join(out, "dense.gltf"), "scene radius x10": os.path.join(out, "dense_far.gltf")}
    with open(paths["as shipped"], "w") as f:
        json.dump(gltf, f)
    gltf["nodes"].append({"name": "copy of the floor far below the room", "mesh": 0, "translation": [0, 0, -40]})
    gltf["scenes"][gltf.get("scene", 0)]["nodes"].append(len(gltf["nodes"]) - 1)
    with open(paths["scene radius x10"], "w") as f:
        json.dump(gltf, f)
    for label, path in paths.items():
        means = {}
        for algorithm in ("pt", "bpt"):
            m = [mc.render_smallvcm(path, args.resolution, args.resolution, args.spp, 9000 + k, out, algorithm,
                                    args.max_path_length)[0].mean() for k in range(args.batches)]
            means[algorithm] = (np.mean(m), np.std(m, ddof=1) / math.sqrt(len(m)))
        (p, sp), (b, sb) = means["pt"], means["bpt"]
        print(f"{label}: pt {p:.5f} +- {sp:.5f}, bpt {b:.5f} +- {sb:.5f}, pt / bpt {p / b:.4f}"
              f" ({(p - b) / math.hypot(sp, sb):+.1f} standard errors)", flush=True)


if __name__ == "__main__":
    main()
