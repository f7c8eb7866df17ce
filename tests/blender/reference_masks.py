"""Reference silhouettes written by hand, for tests whose footage is a simulation's own exact
silhouettes: `score` against an empty reference draws them as its difference image."""

import json
import os
import struct
import zlib

import bpy


def write_gray_png(path, rows):
    """An 8-bit greyscale PNG from rows of 0..255 values (top row first)."""
    raw = b"".join(b"\x00" + bytes(row) for row in rows)

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xffffffff)
    with open(path, "wb") as fh:
        fh.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", len(rows[0]), len(rows), 8, 0, 0, 0, 0))
                 + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def write_manifest(folder, frames, fps, size, masks, source):
    """An extracted reference's manifest.json: `frames` of the clip at `fps`, masks of `size` (w, h)."""
    with open(os.path.join(folder, "manifest.json"), "w", encoding="utf-8") as fh:
        json.dump({"format": "viscoscope.reference", "version": 1, "source": source, "fps": float(fps),
                   "width": size[0], "height": size[1], "frames": list(frames),
                   "times_s": [f / fps for f in frames], "weights": [1.0] * len(frames), "masks": list(masks)},
                  fh, indent=1)


def silhouette_rows(diff_png):
    """The simulated silhouette from `score`'s difference image against an empty reference: false
    positives (orange, R = 255) are the silhouette, agreement outside (grey 40) is background."""
    img = bpy.data.images.load(diff_png)
    try:
        img.colorspace_settings.name = 'Non-Color'
        w, h = img.size
        px = img.pixels[:]
        rows = [[255 if px[4 * (y * w + x)] > 0.5 else 0 for x in range(w)] for y in range(h)]
    finally:
        bpy.data.images.remove(img)
    return rows[::-1]  # Blender's pixels start at the bottom row
