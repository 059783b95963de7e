#!/usr/bin/env python3
"""Write the compressed-geometry inputs of tests/test_gltf.cpp ([gltf][compressed]).

  avocado_plain.glb      the Avocado's geometry (scenes/avocado: CC0 1.0, LICENSE.md there),
                         with two small generated textures instead of its own: an 8 x 8
                         checker as base colour (so TEXCOORD_0 is read) and a gently bumped
                         normal map (so NORMAL and TANGENT are read); no light, no camera.
  avocado_quantized.glb  the same through `gltf-transform quantize` (KHR_mesh_quantization)
  avocado_meshopt.glb    through `gltf-transform meshopt` (EXT_meshopt_compression)
  avocado_gltfpack.glb   through `gltfpack -cc -vpf` (meshopt with the octahedral and
                         exponential filters, floating-point positions)
  avocado_draco.glb      through `gltf-transform draco` (KHR_draco_mesh_compression)

Usage:   python3 tests/data/compressed/make_compressed.py   (Python 3 and npx, which
fetches @gltf-transform/cli 4.x and gltfpack from the npm registry). Commit what it writes.
"""

import json
import os
import struct
import subprocess
import sys
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
AVOCADO = os.path.join(HERE, "..", "..", "..", "scenes", "avocado")


def png_bytes(width, height, rgb):
    raw = b"".join(b"\x00" + bytes(c for p in rgb[y * width:(y + 1) * width] for c in p) for y in range(height))
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def plain_glb():
    doc = json.load(open(os.path.join(AVOCADO, "Avocado.gltf")))
    binary = open(os.path.join(AVOCADO, "Avocado.bin"), "rb").read()
    checker = png_bytes(8, 8, [(200, 150, 40) if (x + y) % 2 else (60, 120, 50) for y in range(8) for x in range(8)])
    bumps = png_bytes(8, 8, [(128 + (40 if x % 4 == 0 else 0), 128 + (40 if y % 4 == 0 else 0), 230)
                             for y in range(8) for x in range(8)])
    images = []
    for data in (checker, bumps):
        binary += b"\0" * (-len(binary) % 4)
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(binary), "byteLength": len(data)})
        images.append({"bufferView": len(doc["bufferViews"]) - 1, "mimeType": "image/png"})
        binary += data
    binary += b"\0" * (-len(binary) % 4)
    doc["buffers"] = [{"byteLength": len(binary)}]
    doc["images"] = images
    doc["textures"] = [{"source": 0}, {"source": 1}]
    doc["materials"] = [{"name": "checker", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
                                                                   "metallicFactor": 0.0, "roughnessFactor": 0.5},
                         "normalTexture": {"index": 1}}]
    doc["asset"] = {"version": "2.0", "extras": {"note": "The Khronos glTF sample model Avocado (CC0 1.0: "
                    "scenes/avocado/LICENSE.md), its textures replaced by generated ones; written by "
                    "tests/data/compressed/make_compressed.py."}}
    text = json.dumps(doc, separators=(",", ":")).encode("ascii")
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def run(arguments):
    print("+", " ".join(arguments))
    subprocess.run(arguments, check=True, cwd=HERE)


def main():
    with open(os.path.join(HERE, "avocado_plain.glb"), "wb") as f:
        f.write(plain_glb())
    cli = ["npx", "-y", "@gltf-transform/cli@4.5.1"]
    run(cli + ["quantize", "avocado_plain.glb", "avocado_quantized.glb"])
    run(cli + ["meshopt", "avocado_plain.glb", "avocado_meshopt.glb"])
    run(cli + ["draco", "avocado_plain.glb", "avocado_draco.glb"])
    run(["npx", "-y", "gltfpack@1.3", "-i", "avocado_plain.glb", "-o", "avocado_gltfpack.glb", "-cc", "-vpf"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
