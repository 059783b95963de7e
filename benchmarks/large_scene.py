#!/usr/bin/env python3
"""Builds the large benchmark scene: a closed atrium hall furnished with real models.

    python3 benchmarks/large_scene.py ASSETS [--out FILE]

ASSETS is a folder that holds the models named in benchmarks/large_scene.json (where
they come from: benchmarks/README.md, "The large scene"). The script writes
ASSETS/large_atrium.gltf and ASSETS/large_atrium_hall.bin: the hall (floor, walls,
ceiling, two galleries, two rows of columns and ceiling lights) is generated here; the
models are referenced where they lie, their buffers and images by relative URI, each
placed one or more times (the placements reuse the model's meshes). A model image that
is absent (a partial copy) is dropped with a line that says so, and the materials that
used it keep their factors. Nothing of the models is copied: the output is small, but
it only renders next to them.
"""
import argparse
import json
import math
import os
import struct
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def mat_mul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def node_matrix(node):
    if "matrix" in node:
        m = node["matrix"]  # column-major
        return [[m[c * 4 + r] for c in range(4)] for r in range(4)]
    t = node.get("translation", [0, 0, 0])
    x, y, z, w = node.get("rotation", [0, 0, 0, 1])
    s = node.get("scale", [1, 1, 1])
    r = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    return [[r[i][0] * s[0], r[i][1] * s[1], r[i][2] * s[2], t[i]] for i in range(3)] + [[0, 0, 0, 1]]


def source_box(doc):
    """The bounding box of the default scene, from the POSITION accessors' min and max."""
    lo, hi = [math.inf] * 3, [-math.inf] * 3

    def visit(index, parent):
        node = doc["nodes"][index]
        world = mat_mul(parent, node_matrix(node))
        if "mesh" in node:
            for prim in doc["meshes"][node["mesh"]]["primitives"]:
                acc = doc["accessors"][prim["attributes"]["POSITION"]]
                for c in range(8):
                    p = [acc["max"][a] if c >> a & 1 else acc["min"][a] for a in range(3)]
                    q = [sum(world[i][k] * p[k] for k in range(3)) + world[i][3] for i in range(3)]
                    for a in range(3):
                        lo[a], hi[a] = min(lo[a], q[a]), max(hi[a], q[a])
        for child in node.get("children", []):
            visit(child, world)

    identity = [[float(i == j) for j in range(4)] for i in range(4)]
    for root in doc["scenes"][doc.get("scene", 0)]["nodes"]:
        visit(root, identity)
    return lo, hi


class Mesh:
    """Triangles with per-vertex normals, written as one primitive."""

    def __init__(self):
        self.positions, self.normals, self.indices = [], [], []

    def quad(self, p0, p1, p2, p3, n):
        base = len(self.positions)
        self.positions += [p0, p1, p2, p3]
        self.normals += [n] * 4
        self.indices += [base, base + 1, base + 2, base, base + 2, base + 3]

    def box(self, lo, hi):
        """An axis-aligned box, faces outwards."""
        x0, y0, z0 = lo
        x1, y1, z1 = hi
        self.quad((x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0), (0, 1, 0))
        self.quad((x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1), (0, -1, 0))
        self.quad((x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1), (0, 0, 1))
        self.quad((x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (x1, y0, z0), (0, 0, -1))
        self.quad((x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1), (1, 0, 0))
        self.quad((x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0), (-1, 0, 0))

    def column(self, x, z, radius, height, segments, rings):
        """A vertical cylinder with smooth normals, no caps (it runs floor to ceiling)."""
        base = len(self.positions)
        for r in range(rings + 1):
            y = height * r / rings
            for s in range(segments + 1):
                a = 2 * math.pi * s / segments
                c, d = math.cos(a), math.sin(a)
                self.positions.append((x + radius * c, y, z + radius * d))
                self.normals.append((c, 0, d))
        row = segments + 1
        for r in range(rings):
            for s in range(segments):
                i = base + r * row + s
                self.indices += [i, i + row, i + 1, i + 1, i + row, i + row + 1]


def build_hall(spec):
    length, height, width = spec["size"]
    hx, hz = length / 2, width / 2
    shell, columns, galleries, lights = Mesh(), Mesh(), Mesh(), Mesh()
    # The shell faces inwards: floor up, ceiling down, walls towards the centre.
    shell.quad((-hx, 0, -hz), (-hx, 0, hz), (hx, 0, hz), (hx, 0, -hz), (0, 1, 0))
    shell.quad((-hx, height, -hz), (hx, height, -hz), (hx, height, hz), (-hx, height, hz), (0, -1, 0))
    shell.quad((-hx, 0, -hz), (hx, 0, -hz), (hx, height, -hz), (-hx, height, -hz), (0, 0, 1))
    shell.quad((-hx, 0, hz), (-hx, height, hz), (hx, height, hz), (hx, 0, hz), (0, 0, -1))
    shell.quad((-hx, 0, -hz), (-hx, height, -hz), (-hx, height, hz), (-hx, 0, hz), (1, 0, 0))
    shell.quad((hx, 0, -hz), (hx, 0, hz), (hx, height, hz), (hx, height, -hz), (-1, 0, 0))
    gy, gd = spec["gallery_height"], spec["gallery_depth"]
    for side in (-1, 1):
        z0, z1 = sorted((side * hz, side * (hz - gd)))
        galleries.box((-hx, gy - 0.3, z0), (hx, gy, z1))
        galleries.box((-hx, gy, z0 if side < 0 else z1 - 0.15), (hx, gy + 1.0, z0 + 0.15 if side < 0 else z1))
    n = spec["columns_per_side"]
    for side in (-1, 1):
        for i in range(n):
            x = -hx + length * (i + 0.5) / n
            columns.column(x, side * (hz - spec["column_inset"]), spec["column_radius"], height,
                           spec["column_segments"], spec["column_rings"])
    nx, nz = spec["ceiling_lights"]
    sx, sz = spec["ceiling_light_size"]
    for i in range(nx):
        for j in range(nz):
            cx = -hx + length * (i + 0.5) / nx
            cz = -hz + width * (j + 0.5) / nz
            y = height - 0.05
            lights.quad((cx - sx / 2, y, cz - sz / 2), (cx + sx / 2, y, cz - sz / 2),
                        (cx + sx / 2, y, cz + sz / 2), (cx - sx / 2, y, cz + sz / 2), (0, -1, 0))
    return [("hall shell", shell, [0.78, 0.74, 0.66]), ("galleries", galleries, [0.62, 0.58, 0.52]),
            ("columns", columns, [0.70, 0.67, 0.60]), ("ceiling lights", lights, None)]


def add_hall(doc, spec, bin_name, out_dir):
    blob = bytearray()
    parts = build_hall(spec)
    buffer_index = len(doc["buffers"])
    nodes = []
    for name, mesh, colour in parts:
        material = {"name": name, "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 0.9}}
        if colour is None:
            material["pbrMetallicRoughness"]["baseColorFactor"] = [0.0, 0.0, 0.0, 1.0]
            material["emissiveFactor"] = [1.0, 0.95, 0.85]
            material["extensions"] = {"KHR_materials_emissive_strength": {"emissiveStrength": spec["ceiling_light_strength"]}}
        else:
            material["pbrMetallicRoughness"]["baseColorFactor"] = colour + [1.0]
        doc["materials"].append(material)
        attributes = {}
        for key, values in (("POSITION", mesh.positions), ("NORMAL", mesh.normals)):
            offset = len(blob)
            for v in values:
                blob += struct.pack("<3f", *v)
            doc["bufferViews"].append({"buffer": buffer_index, "byteOffset": offset, "byteLength": len(blob) - offset})
            accessor = {"bufferView": len(doc["bufferViews"]) - 1, "componentType": 5126, "count": len(values), "type": "VEC3"}
            if key == "POSITION":
                accessor["min"] = [min(v[a] for v in values) for a in range(3)]
                accessor["max"] = [max(v[a] for v in values) for a in range(3)]
            doc["accessors"].append(accessor)
            attributes[key] = len(doc["accessors"]) - 1
        offset = len(blob)
        blob += struct.pack("<%dI" % len(mesh.indices), *mesh.indices)
        doc["bufferViews"].append({"buffer": buffer_index, "byteOffset": offset, "byteLength": len(blob) - offset})
        doc["accessors"].append({"bufferView": len(doc["bufferViews"]) - 1, "componentType": 5125,
                                 "count": len(mesh.indices), "type": "SCALAR"})
        doc["meshes"].append({"name": name, "primitives": [{"attributes": attributes, "indices": len(doc["accessors"]) - 1,
                                                            "material": len(doc["materials"]) - 1}]})
        doc["nodes"].append({"name": name, "mesh": len(doc["meshes"]) - 1})
        nodes.append(len(doc["nodes"]) - 1)
    doc["buffers"].append({"uri": bin_name, "byteLength": len(blob)})
    with open(os.path.join(out_dir, bin_name), "wb") as f:
        f.write(blob)
    return nodes, sum(len(m.indices) // 3 for _, m, _ in parts)


def merge_source(doc, src, src_dir, out_dir, label):
    """Appends a model's buffers, views, accessors, images, textures, materials and meshes;
    returns its root nodes' indices in src (for copying per placement) and the offsets."""
    off = {k: len(doc[k]) for k in ("buffers", "bufferViews", "accessors", "images", "samplers", "textures", "materials", "meshes")}
    rel = os.path.relpath(src_dir, out_dir)
    for b in src.get("buffers", []):
        b = dict(b)
        b["uri"] = os.path.join(rel, b["uri"]).replace(os.sep, "/")
        doc["buffers"].append(b)
    for v in src.get("bufferViews", []):
        v = dict(v)
        v["buffer"] += off["buffers"]
        doc["bufferViews"].append(v)
    for a in src.get("accessors", []):
        a = dict(a)
        if "bufferView" in a:
            a["bufferView"] += off["bufferViews"]
        doc["accessors"].append(a)
    # Images whose file is absent are dropped; so are the textures that show them and
    # every material slot that reads such a texture.
    image_map, texture_map = {}, {}
    for i, image in enumerate(src.get("images", [])):
        path = os.path.join(src_dir, image.get("uri", ""))
        if "uri" not in image or not os.path.isfile(path):
            print("%s: image %s is absent, dropped (its materials keep their factors)" % (label, image.get("uri")), file=sys.stderr)
            continue
        image = dict(image)
        image["uri"] = os.path.join(rel, image["uri"]).replace(os.sep, "/")
        image_map[i] = len(doc["images"])
        doc["images"].append(image)
    doc["samplers"] += src.get("samplers", [])
    for i, t in enumerate(src.get("textures", [])):
        if t.get("source") not in image_map:
            continue
        t = dict(t)
        t["source"] = image_map[t["source"]]
        if "sampler" in t:
            t["sampler"] += off["samplers"]
        texture_map[i] = len(doc["textures"])
        doc["textures"].append(t)

    def remap(info_holder, key):
        info = info_holder.get(key)
        if info is None:
            return
        if info["index"] not in texture_map:
            del info_holder[key]
        else:
            info["index"] = texture_map[info["index"]]

    for m in src.get("materials", []):
        m = json.loads(json.dumps(m))
        for key in ("normalTexture", "occlusionTexture", "emissiveTexture"):
            remap(m, key)
        pbr = m.get("pbrMetallicRoughness", {})
        for key in ("baseColorTexture", "metallicRoughnessTexture"):
            remap(pbr, key)
        doc["materials"].append(m)
    for mesh in src.get("meshes", []):
        mesh = json.loads(json.dumps(mesh))
        for p in mesh["primitives"]:
            p["attributes"] = {k: v + off["accessors"] for k, v in p["attributes"].items()}
            if "indices" in p:
                p["indices"] += off["accessors"]
            if "material" in p:
                p["material"] += off["materials"]
        doc["meshes"].append(mesh)
    return off


def copy_subtree(doc, src, index, mesh_offset):
    node = src["nodes"][index]
    copy = {k: v for k, v in node.items() if k in ("name", "matrix", "translation", "rotation", "scale")}
    if "mesh" in node:
        copy["mesh"] = node["mesh"] + mesh_offset
    children = [copy_subtree(doc, src, c, mesh_offset) for c in node.get("children", [])]
    if children:
        copy["children"] = children
    doc["nodes"].append(copy)
    return len(doc["nodes"]) - 1


def count_triangles(src, roots):
    total = 0

    def visit(i):
        nonlocal total
        node = src["nodes"][i]
        for p in src["meshes"][node["mesh"]]["primitives"] if "mesh" in node else []:
            acc = p["indices"] if "indices" in p else p["attributes"]["POSITION"]
            total += src["accessors"][acc]["count"] // 3
        for c in node.get("children", []):
            visit(c)

    for r in roots:
        visit(r)
    return total


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("assets", help="folder that holds the models (benchmarks/README.md)")
    parser.add_argument("--description", default=os.path.join(HERE, "large_scene.json"))
    parser.add_argument("--out", help="the glTF to write (default ASSETS/large_atrium.gltf); it must lie in ASSETS")
    args = parser.parse_args()
    with open(args.description) as f:
        spec = json.load(f)
    assets = os.path.abspath(args.assets)
    out = os.path.abspath(args.out or os.path.join(assets, "large_atrium.gltf"))
    out_dir = os.path.dirname(out)
    doc = {"asset": {"version": "2.0", "generator": "smallvcm benchmarks/large_scene.py"},
           "extensionsUsed": ["KHR_materials_emissive_strength"],
           "buffers": [], "bufferViews": [], "accessors": [], "images": [], "samplers": [], "textures": [],
           "materials": [], "meshes": [], "nodes": []}
    roots, triangles = add_hall(doc, spec["hall"], os.path.splitext(os.path.basename(out))[0] + "_hall.bin", out_dir)
    merged = {}
    for name, source in spec["sources"].items():
        path = os.path.join(assets, source["gltf"])
        if not os.path.isfile(path):
            sys.exit("missing model: %s (benchmarks/README.md, 'The large scene', says where to get it)" % path)
        with open(path) as f:
            src = json.load(f)
        unsupported = set(src.get("extensionsRequired", []))
        if unsupported:
            sys.exit("%s requires %s: not supported by this script" % (path, ", ".join(sorted(unsupported))))
        offsets = merge_source(doc, src, os.path.dirname(path), out_dir, name)
        src_roots = src["scenes"][src.get("scene", 0)]["nodes"]
        merged[name] = (src, offsets, src_roots, source_box(src), count_triangles(src, src_roots))
    for place in spec["placements"]:
        src, offsets, src_roots, (lo, hi), tris = merged[place["source"]]
        s = place["fit"] / (hi[1] - lo[1])
        yaw = math.radians(place.get("yaw", 0.0))
        c, d = math.cos(yaw), math.sin(yaw)
        # Bottom centre of the model's box, scaled and turned about +Y, lands on 'at'.
        bx, by, bz = s * (lo[0] + hi[0]) / 2, s * lo[1], s * (lo[2] + hi[2]) / 2
        at = place["at"]
        translation = [at[0] - (c * bx + d * bz), at[1] - by, at[2] - (-d * bx + c * bz)]
        children = [copy_subtree(doc, src, r, offsets["meshes"]) for r in src_roots]
        doc["nodes"].append({"name": place["source"], "translation": translation,
                             "rotation": [0.0, math.sin(yaw / 2), 0.0, math.cos(yaw / 2)],
                             "scale": [s, s, s], "children": children})
        roots.append(len(doc["nodes"]) - 1)
        triangles += tris
    doc["scenes"] = [{"nodes": roots}]
    doc["scene"] = 0
    for key in [k for k, v in doc.items() if v == []]:
        del doc[key]
    with open(out, "w") as f:
        json.dump(doc, f, indent=1)
    print("wrote %s: %d triangles (%d placements), no camera, lit by %d ceiling lights"
          % (out, triangles, len(spec["placements"]), spec["hall"]["ceiling_lights"][0] * spec["hall"]["ceiling_lights"][1]))


if __name__ == "__main__":
    main()
