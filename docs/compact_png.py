#!/usr/bin/env python3
"""Re-encode PNG files losslessly so that the committed figures take less room.

    python3 docs/compact_png.py FILE_OR_FOLDER...

Why: the renderer writes PNGs with stb_image_write, whose deflate uses only the fixed
Huffman code. On a noisy render that code saves almost nothing (a 256x256 figure is
197 KB, its raw size), and docs/figures holds about two hundred of them. Python's zlib
(dynamic Huffman codes) makes the same pixels about 25 % smaller, with the best of six
filterings: each of the five PNG filters on every row, and a filter chosen per row as
the PNG specification suggests (the one whose bytes have the smallest sum of absolute
values). The renderer keeps stb (no new dependency in
the header); `make figures` runs this afterwards.

Safety: the new encoding is decoded again and compared with the old one pixel for
pixel before it replaces the file, and the file is replaced atomically (a temporary file
in the same folder, then os.replace), never written through a symbolic link. A file this
script cannot re-encode (palette, 16-bit, interlaced) is left as it is and named.
Standard library only.
"""

import os
import struct
import sys
import tempfile
import zlib

SIGNATURE = b"\x89PNG\r\n\x1a\n"
CHANNELS = {0: 1, 2: 3, 4: 2, 6: 4}  # PNG colour type -> samples per pixel (8-bit)
MAX_FILE_BYTES = 256 << 20           # refuse to read anything larger than this


class Unsupported(Exception):
    pass


def read_chunks(data, path):
    if not data.startswith(SIGNATURE):
        raise Unsupported("not a PNG file")
    chunks, offset = [], len(SIGNATURE)
    while offset + 12 <= len(data):
        (length,) = struct.unpack(">I", data[offset:offset + 4])
        kind = data[offset + 4:offset + 8]
        body = data[offset + 8:offset + 8 + length]
        if len(body) != length:
            raise Unsupported("truncated chunk " + kind.decode("latin-1"))
        chunks.append((kind, body))
        offset += 12 + length
        if kind == b"IEND":
            return chunks
    raise Unsupported("no IEND chunk")


def paeth(a, b, c):
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    if pa <= pb and pa <= pc:
        return a
    return b if pb <= pc else c


def unfilter(raw, height, stride, bpp):
    """The pixel rows of a decompressed IDAT stream (each row starts with its filter type)."""
    rows, previous = [], bytearray(stride)
    for y in range(height):
        start = y * (stride + 1)
        kind, row = raw[start], bytearray(raw[start + 1:start + 1 + stride])
        if kind == 1:
            for i in range(bpp, stride):
                row[i] = (row[i] + row[i - bpp]) & 255
        elif kind == 2:
            for i in range(stride):
                row[i] = (row[i] + previous[i]) & 255
        elif kind == 3:
            for i in range(stride):
                left = row[i - bpp] if i >= bpp else 0
                row[i] = (row[i] + ((left + previous[i]) >> 1)) & 255
        elif kind == 4:
            for i in range(stride):
                left = row[i - bpp] if i >= bpp else 0
                upper_left = previous[i - bpp] if i >= bpp else 0
                row[i] = (row[i] + paeth(left, previous[i], upper_left)) & 255
        elif kind != 0:
            raise Unsupported("unknown row filter %d" % kind)
        rows.append(bytes(row))
        previous = row
    return rows


def filtered_candidates(row, previous, bpp):
    """The row under each of the five PNG filters (filter type = list index)."""
    n = len(row)
    left = bytes(bpp) + row[:n - bpp]
    upper_left = bytes(bpp) + previous[:n - bpp]
    sub = bytes((x - a) & 255 for x, a in zip(row, left))
    up = bytes((x - b) & 255 for x, b in zip(row, previous))
    average = bytes((x - ((a + b) >> 1)) & 255 for x, a, b in zip(row, left, previous))
    paeth_row = bytes((x - paeth(a, b, c)) & 255 for x, a, b, c in zip(row, left, previous, upper_left))
    return [row, sub, up, average, paeth_row]


def signed_sum(data):
    return sum(v if v < 128 else 256 - v for v in data)


def encode(rows, bpp):
    """The smallest of six encodings: each filter for every row, and the per-row choice."""
    streams = [bytearray() for _ in range(6)]
    previous = bytes(len(rows[0]))
    for row in rows:
        candidates = filtered_candidates(row, previous, bpp)
        for kind in range(5):
            streams[kind].append(kind)
            streams[kind] += candidates[kind]
        best = min(range(5), key=lambda k: signed_sum(candidates[k]))
        streams[5].append(best)
        streams[5] += candidates[best]
        previous = row
    return min((zlib.compress(bytes(stream), 9) for stream in streams), key=len)


def chunk(kind, body):
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)


def compact(path):
    """Returns (old size, new size); new == old when the file was kept."""
    if os.path.islink(path):
        raise Unsupported("a symbolic link (not followed)")
    old_size = os.path.getsize(path)
    if old_size > MAX_FILE_BYTES:
        raise Unsupported("larger than %d bytes" % MAX_FILE_BYTES)
    with open(path, "rb") as f:
        data = f.read()
    chunks = read_chunks(data, path)
    if chunks[0][0] != b"IHDR":
        raise Unsupported("IHDR is not the first chunk")
    width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", chunks[0][1])
    if depth != 8 or colour not in CHANNELS or interlace != 0:
        raise Unsupported("only 8-bit, non-interlaced grey/RGB(A) is re-encoded")
    bpp = CHANNELS[colour]
    stride = width * bpp
    raw = zlib.decompress(b"".join(body for kind, body in chunks if kind == b"IDAT"))
    if len(raw) != height * (stride + 1):
        raise Unsupported("image data of the wrong size")
    rows = unfilter(raw, height, stride, bpp)
    idat = encode(rows, bpp)
    if unfilter(zlib.decompress(idat), height, stride, bpp) != rows:
        raise Unsupported("re-encoding changed the pixels (a bug in this script)")

    out, idat_written = bytearray(SIGNATURE), False
    for kind, body in chunks:
        if kind == b"IDAT":
            if not idat_written:
                out += chunk(b"IDAT", idat)
                idat_written = True
        else:
            out += chunk(kind, body)
    if len(out) >= old_size:
        return old_size, old_size
    folder = os.path.dirname(os.path.abspath(path))
    handle, temporary = tempfile.mkstemp(prefix=".compact_", suffix=".png", dir=folder)
    try:
        with os.fdopen(handle, "wb") as f:
            f.write(out)
        os.chmod(temporary, os.stat(path).st_mode & 0o777)
        os.replace(temporary, path)
    except BaseException:
        os.unlink(temporary)
        raise
    return old_size, len(out)


def png_files(arguments):
    for argument in arguments:
        if os.path.isdir(argument) and not os.path.islink(argument):
            for name in sorted(os.listdir(argument)):
                if name.lower().endswith(".png"):
                    yield os.path.join(argument, name)
        else:
            yield argument


def main(arguments):
    if not arguments:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    before = after = 0
    failures = 0
    for path in png_files(arguments):
        try:
            old, new = compact(path)
        except (OSError, Unsupported, zlib.error) as error:
            print("%s: left as it is: %s" % (path, error), file=sys.stderr)
            failures += isinstance(error, OSError)
            continue
        before += old
        after += new
    if before:
        print("compact_png: %.1f MB -> %.1f MB (%.0f %% smaller), pixels unchanged"
              % (before / 1e6, after / 1e6, 100.0 * (1.0 - after / before)))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
