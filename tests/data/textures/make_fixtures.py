#!/usr/bin/env python3
"""Writes the tiny image fixtures for texture_io_test.cpp (python3 stdlib only).

Run from anywhere: python3 tests/data/textures/make_fixtures.py
Pixel values are chosen so that the tests can check them exactly.
"""
import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))


def png_bytes(width, height, channels, pixels):
    """PNG with 8-bit samples; channels 1 (gray), 2 (gray+alpha), 3 (RGB), 4 (RGBA).
    pixels: flat list, row 0 first (top of the image)."""
    color_type = {1: 0, 2: 4, 3: 2, 4: 6}[channels]

    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data +
                struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    rows = b""
    stride = width * channels
    for y in range(height):
        rows += b"\x00" + bytes(pixels[y * stride:(y + 1) * stride])  # filter 0 (none)
    ihdr = struct.pack(">IIBBBBB", width, height, 8, color_type, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) +
            chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b""))


def write(name, data):
    with open(os.path.join(HERE, name), "wb") as f:
        f.write(data)


def exr_bytes(width, height, rgb):
    """Uncompressed scanline OpenEXR with FLOAT R, G, B channels; rgb: list of (r, g, b), row 0 first."""
    def attr(name, kind, data):
        return name.encode() + b"\x00" + kind.encode() + b"\x00" + struct.pack("<i", len(data)) + data

    chlist = b""
    for ch in ("B", "G", "R"):  # channels are stored in alphabetical order
        chlist += ch.encode() + b"\x00" + struct.pack("<iBBBBii", 2, 0, 0, 0, 0, 1, 1)
    chlist += b"\x00"
    box = struct.pack("<iiii", 0, 0, width - 1, height - 1)
    header = (attr("channels", "chlist", chlist) + attr("compression", "compression", b"\x00") +
              attr("dataWindow", "box2i", box) + attr("displayWindow", "box2i", box) +
              attr("lineOrder", "lineOrder", b"\x00") + attr("pixelAspectRatio", "float", struct.pack("<f", 1.0)) +
              attr("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0)) +
              attr("screenWindowWidth", "float", struct.pack("<f", 1.0)) + b"\x00")
    prefix = struct.pack("<ii", 20000630, 2) + header
    line_size = width * 3 * 4
    chunk_size = 8 + line_size
    table_end = len(prefix) + 8 * height
    offsets = b"".join(struct.pack("<Q", table_end + y * chunk_size) for y in range(height))
    chunks = b""
    for y in range(height):
        row = rgb[y * width:(y + 1) * width]
        data = b""
        for c in (2, 1, 0):  # B, G, R
            data += b"".join(struct.pack("<f", px[c]) for px in row)
        chunks += struct.pack("<ii", y, line_size) + data
    return prefix + offsets + chunks


def main():
    # 2x2 RGB: red, green / blue, white.
    write("rgb_2x2.png", png_bytes(2, 2, 3, [255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255]))
    # 3x2 RGBA with varying alpha.
    write("rgba_3x2.png", png_bytes(3, 2, 4, [10, 20, 30, 0, 40, 50, 60, 128, 70, 80, 90, 255,
                                              1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]))
    # 2x1 gray.
    write("gray_2x1.png", png_bytes(2, 1, 1, [0, 200]))
    # PPM (P6), 2x1: yellow, cyan.
    write("tiny.ppm", b"P6\n2 1\n255\n" + bytes([255, 255, 0, 0, 255, 255]))
    # Uncompressed true-color TGA (type 2), 2x1, stored top-to-bottom (descriptor bit 5), BGR order: red, blue.
    write("tiny.tga", struct.pack("<BBBHHBHHHHBB", 0, 0, 2, 0, 0, 0, 0, 0, 2, 1, 24, 0x20) +
          bytes([0, 0, 255, 255, 0, 0]))
    # Radiance HDR, 2x1, flat RGBE (no RLE for widths < 8): (1, 0.5, 0.25) and (4, 4, 4).
    write("tiny.hdr", b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 2\n" +
          bytes([128, 64, 32, 129, 128, 128, 128, 131]))
    # OpenEXR float, 2x2.
    write("tiny.exr", exr_bytes(2, 2, [(0.5, 1.0, 2.0), (0.0, 0.25, 8.0), (16.0, 0.125, 0.0), (1.5, 2.5, 3.5)]))
    # Malformed: PNG signature then garbage; a valid PNG cut short; a gray PNG header
    # claiming 40000 x 20000 (within stb_image's own limit, beyond ours).
    write("corrupt.png", b"\x89PNG\r\n\x1a\n" + b"this is not a png chunk stream" * 2)
    good = png_bytes(2, 2, 3, [255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255])
    write("truncated.png", good[:40])
    huge_ihdr = struct.pack(">IIBBBBB", 40000, 20000, 8, 0, 0, 0, 0)
    write("huge.png", b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + huge_ihdr +
          struct.pack(">I", zlib.crc32(b"IHDR" + huge_ihdr) & 0xFFFFFFFF))
    write("empty.png", b"")


if __name__ == "__main__":
    main()
