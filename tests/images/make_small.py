#!/usr/bin/python3
"""make_small.py - writes the TGA, PGM/PPM and Radiance HDR fixtures of tests/t_decode.c
into tests/images/small/.

Every fixture X comes with X.expect: "w h channels depth\\n" then the raw samples
(uint8; uint16 little-endian; float32 little-endian), row 0 = top.  The expected
samples are the pixels handed to the encoder (PIL, ImageMagick, or the small
writers below, which follow the format specs), NOT what some decoder reads back:
  - TGA / PNM: the chosen pixel values, with 5-bit TGA values expanded as
    (v << 3) | (v >> 2) and PNM samples rescaled (v*full + maxval//2)//maxval;
  - HDR: what the stored RGBE bytes mean under Radiance's colr_color()
    convention, (m + 0.5) * 2^(e - 136), e == 0 -> 0 (computed from the bytes).
PIL is also asked to read its own TGA/PNM files back, as a sanity check.
A MANIFEST lists the fixtures.  Run: /usr/bin/python3 tests/images/make_small.py
(needs PIL and ImageMagick's convert at /usr/bin/convert)
"""
import io
import math
import os
import random
import struct
import subprocess
import tempfile
import zlib

from PIL import Image

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "small")
CONVERT = "/usr/bin/convert"  # the real ImageMagick, not /usr/local/bin's stand-in
manifest = []


def write(name, data, w, h, ch, depth, samples):
    """samples: flat list, row 0 = top."""
    assert len(samples) == w * h * ch, (name, len(samples), w * h * ch)
    with open(os.path.join(OUT, name), "wb") as f:
        f.write(data)
    if depth == 8:
        raw = bytes(samples)
    elif depth == 16:
        raw = struct.pack("<%dH" % len(samples), *samples)
    else:
        raw = struct.pack("<%df" % len(samples), *samples)
    with open(os.path.join(OUT, name + ".expect"), "wb") as f:
        f.write(b"%d %d %d %d\n" % (w, h, ch, depth) + raw)
    manifest.append(name)


def pattern(w, h, ch, seed, levels=256):
    """Pixels with flat patches (so RLE finds runs, some crossing rows) and noise."""
    rnd = random.Random(seed)
    px = []
    for y in range(h):
        for x in range(w):
            if (x // 5 + y // 3) % 3 == 0:
                px.append(tuple((17 * (c + 1) * (1 + (x // 5) % 2)) % levels for c in range(ch)))
            else:
                px.append(tuple(rnd.randrange(levels) for _ in range(ch)))
    # a corner that differs from its mirror images, so flips are caught
    px[0] = tuple([levels - 1] + [0] * (ch - 1))
    return px


def flat(px):
    return [v for p in px for v in p]


def pil_bytes(img, fmt, **kw):
    b = io.BytesIO()
    img.save(b, fmt, **kw)
    return b.getvalue()


# ---------------------------------------------------------------- TGA
def tga_header(idlen, cmtype, itype, cmfirst, cmlen, cmbits, w, h, bits, desc):
    return struct.pack("<BBBHHBHHHHBB", idlen, cmtype, itype, cmfirst, cmlen, cmbits, 0, 0,
                       w, h, bits, desc)


def tga_rle(pixels):
    """pixels: list of byte strings in stream order; packets cross rows freely."""
    out = bytearray()
    i = 0
    n = len(pixels)
    while i < n:
        j = i
        while j + 1 < n and pixels[j + 1] == pixels[i] and j + 1 - i < 128:
            j += 1
        if j > i:  # run of j - i + 1
            out.append(0x80 | (j - i))
            out += pixels[i]
            i = j + 1
        else:
            k = i
            while k < n and k - i < 128 and not (k + 1 < n and pixels[k + 1] == pixels[k]):
                k += 1
            k = max(k, i + 1)
            out.append(k - i - 1)
            for q in pixels[i:k]:
                out += q
            i = k
    return bytes(out)


def file_order(px, w, h, desc):
    """Reorders top-down, left-right pixels into the order the descriptor stores."""
    rows = [px[y * w:(y + 1) * w] for y in range(h)]
    if not desc & 0x20:
        rows = rows[::-1]
    if desc & 0x10:
        rows = [r[::-1] for r in rows]
    return [p for r in rows for p in r]


def exp5(v):
    return (v << 3) | (v >> 2)


def make_tga():
    # PIL-written: RGB / RGBA / L / P, raw and RLE, both vertical origins
    cases = [("tga_rgb_13x7.tga", "RGB", 13, 7, False, -1),
             ("tga_rgb_rle_13x7.tga", "RGB", 13, 7, True, 1),
             ("tga_rgba_33x17.tga", "RGBA", 33, 17, False, 1),
             ("tga_rgba_rle_33x17.tga", "RGBA", 33, 17, True, -1),
             ("tga_grey_13x7.tga", "L", 13, 7, False, -1),
             ("tga_grey_rle_33x17.tga", "L", 33, 17, True, 1),
             ("tga_rgb_1x1.tga", "RGB", 1, 1, False, -1),
             ("tga_rgba_rle_1x1.tga", "RGBA", 1, 1, True, 1)]
    for name, mode, w, h, rle, orient in cases:
        ch = len(mode)
        px = pattern(w, h, ch, zlib.crc32(name.encode()) & 0xFFFF)
        img = Image.new(mode, (w, h))
        img.putdata(px if ch > 1 else [p[0] for p in px])
        kw = {"orientation": orient}
        if rle:
            kw["compression"] = "tga_rle"
        data = pil_bytes(img, "TGA", **kw)
        assert list(Image.open(io.BytesIO(data)).convert(mode).getdata()) == \
            (px if ch > 1 else [p[0] for p in px]), name
        write(name, data, w, h, ch, 8, flat(px))

    # PIL-written colour-mapped (P): 24-bit BGR map entries, 8-bit indices
    for name, w, h, rle in [("tga_pal_13x7.tga", 13, 7, False), ("tga_pal_rle_33x17.tga", 33, 17, True)]:
        rnd = random.Random(w)
        pal = [rnd.randrange(256) for _ in range(3 * 40)]
        idx = [p[0] for p in pattern(w, h, 1, w, levels=40)]
        img = Image.new("P", (w, h))
        img.putpalette(pal)
        img.putdata(idx)
        kw = {"compression": "tga_rle"} if rle else {}
        data = pil_bytes(img, "TGA", **kw)
        write(name, data, w, h, 3, 8, [pal[3 * i + c] for i in idx for c in range(3)])

    # ImageMagick-written RLE true colour (rows bottom-up, runs kept per row)
    w, h = 33, 17
    px = pattern(w, h, 3, 99)
    with tempfile.TemporaryDirectory() as td:
        src, dst = os.path.join(td, "a.ppm"), os.path.join(td, "a.tga")
        with open(src, "wb") as f:
            f.write(b"P6\n%d %d\n255\n" % (w, h) + bytes(flat(px)))
        # ImageMagick 6.9 writes rows in memory order (top first) and takes the
        # origin bit from the image's orientation; a PPM's is undefined, written
        # as bottom-left, so without -orient the file would encode the picture
        # upside down.  Say the orientation explicitly.
        subprocess.run([CONVERT, src, "-orient", "TopLeft", "-compress", "RLE", dst], check=True)
        data = open(dst, "rb").read()
    assert data[2] == 10, "ImageMagick did not write an RLE TGA"
    assert list(Image.open(io.BytesIO(data)).convert("RGB").getdata()) == px
    write("tga_im_rle_33x17.tga", data, w, h, 3, 8, flat(px))

    # hand-written 16-bit A1R5G5B5 with one alpha bit (attribute bits = 1), bottom-up
    w, h = 13, 7
    rnd = random.Random(5)
    v5 = [(rnd.randrange(32), rnd.randrange(32), rnd.randrange(32), rnd.randrange(2)) for _ in range(w * h)]
    v5[0] = (31, 0, 0, 1)
    words = [struct.pack("<H", a << 15 | r << 10 | g << 5 | b) for r, g, b, a in v5]
    desc = 0x01
    data = tga_header(0, 0, 2, 0, 0, 0, w, h, 16, desc) + b"".join(file_order(words, w, h, desc))
    write("tga_555a_13x7.tga", data, w, h, 4, 8,
          [s for r, g, b, a in v5 for s in (exp5(r), exp5(g), exp5(b), 255 * a)])

    # hand-written RLE 15-bit (top bit set as garbage: no attribute bits, so no
    # alpha), origin top-right, runs crossing rows
    px5 = [(x // 4 % 32, 7, (y * 3) % 32) for y in range(h) for x in range(w)]
    px5[0] = (31, 31, 0)
    words = [struct.pack("<H", 0x8000 | r << 10 | g << 5 | b) for r, g, b in px5]
    desc = 0x30
    data = tga_header(0, 0, 10, 0, 0, 0, w, h, 15, desc) + tga_rle(file_order(words, w, h, desc))
    write("tga_555_rle_tr_13x7.tga", data, w, h, 3, 8, [exp5(v) for p in px5 for v in p])

    # hand-written RLE grey, 33x17, runs crossing rows, bottom-up, with an image ID
    w, h = 33, 17
    g = [(x // 7 + y // 2) * 9 % 256 for y in range(h) for x in range(w)]
    g[0] = 255
    ident = b"appm fixture"
    data = tga_header(len(ident), 0, 11, 0, 0, 0, w, h, 8, 0) + ident + \
        tga_rle(file_order([bytes([v]) for v in g], w, h, 0))
    write("tga_grey_rle_id_33x17.tga", data, w, h, 1, 8, g)

    # hand-written colour-mapped RLE: 16-bit map entries with an alpha bit
    # (attribute bits 1), first entry index 5, image ID, top-down
    w, h = 13, 7
    rnd = random.Random(7)
    cm = [(rnd.randrange(32), rnd.randrange(32), rnd.randrange(32), rnd.randrange(2)) for _ in range(20)]
    idx = [5 + (x // 3 + y) % 20 for y in range(h) for x in range(w)]
    cmap = b"".join(struct.pack("<H", a << 15 | r << 10 | g << 5 | b) for r, g, b, a in cm)
    desc = 0x21
    data = tga_header(3, 1, 9, 5, len(cm), 16, w, h, 8, desc) + b"xyz" + cmap + \
        tga_rle(file_order([bytes([i]) for i in idx], w, h, desc))
    exp = []
    for i in idx:
        r, g_, b, a = cm[i - 5]
        exp += [exp5(r), exp5(g_), exp5(b), 255 * a]
    write("tga_cmap16_rle_13x7.tga", data, w, h, 4, 8, exp)

    # hand-written colour-mapped raw: 16-bit indices, 32-bit BGRA entries with
    # alpha (attribute bits 8), first entry 300, origin bottom-right
    cm = [(rnd.randrange(256), rnd.randrange(256), rnd.randrange(256), rnd.randrange(256)) for _ in range(30)]
    idx = [300 + (x * 7 + y * 3) % 30 for y in range(h) for x in range(w)]
    cmap = b"".join(bytes([b, g_, r, a]) for r, g_, b, a in cm)
    desc = 0x18
    data = tga_header(0, 1, 1, 300, len(cm), 32, w, h, 16, desc) + cmap + \
        b"".join(file_order([struct.pack("<H", i) for i in idx], w, h, desc))
    write("tga_cmap32_idx16_13x7.tga", data, w, h, 4, 8, [v for i in idx for v in cm[i - 300]])

    # hand-written 24-bit with an (unused) colour map on a true-colour image,
    # origin bottom-right; and 32-bit with 0 attribute bits (fourth byte unused)
    px = pattern(w, h, 3, 11)
    desc = 0x10
    data = tga_header(0, 1, 2, 0, 2, 24, w, h, 24, desc) + b"\x01\x02\x03\x04\x05\x06" + \
        b"".join(file_order([bytes([b, g_, r]) for r, g_, b in px], w, h, desc))
    write("tga_rgb_br_cmap_13x7.tga", data, w, h, 3, 8, flat(px))
    data = tga_header(0, 0, 2, 0, 0, 0, w, h, 32, 0x20) + \
        b"".join(bytes([b, g_, r, 0x5A]) for r, g_, b in px)
    write("tga_rgbx_13x7.tga", data, w, h, 3, 8, flat(px))


# ---------------------------------------------------------------- PNM
def scale(v, maxval):
    if maxval in (255, 65535):
        return v
    full = 255 if maxval < 255 else 65535
    return (v * full + maxval // 2) // maxval


def ascii_raster(vals, per_line):
    lines = []
    for i in range(0, len(vals), per_line):
        lines.append(" ".join(str(v) for v in vals[i:i + per_line]))
    return ("\n".join(lines) + "\n").encode()


def make_pnm():
    # PIL-written P5/P6, maxval 255
    for name, mode, w, h in [("pgm_p5_255_13x7.pgm", "L", 13, 7), ("ppm_p6_255_33x17.ppm", "RGB", 33, 17),
                             ("ppm_p6_255_1x1.ppm", "RGB", 1, 1)]:
        ch = len(mode)
        px = pattern(w, h, ch, w * 31 + ch)
        img = Image.new(mode, (w, h))
        img.putdata(px if ch > 1 else [p[0] for p in px])
        data = pil_bytes(img, "PPM")
        write(name, data, w, h, ch, 8, flat(px))
    # PIL-written P5 maxval 65535 (mode I, written as 16-bit big-endian)
    w, h = 13, 7
    rnd = random.Random(3)
    vals = [rnd.randrange(65536) for _ in range(w * h)]
    vals[0] = 65535
    img = Image.new("I", (w, h))
    img.putdata(vals)
    data = pil_bytes(img, "PPM")
    assert data.startswith(b"P5") and b"65535" in data[:20], data[:20]
    write("pgm_p5_65535_13x7.pgm", data, w, h, 1, 16, vals)

    # hand-written with comments in every header gap
    def hdr(magic, w, h, maxval, tail):
        return (b"%s# a comment right after the magic\n%d # width\n# a whole comment line\n %d\t"
                b"#height\n%d%s" % (magic, w, h, maxval, tail))

    w, h = 13, 7
    vals = [rnd.randrange(16) for _ in range(w * h)]
    write("pgm_p2_15_13x7.pgm", hdr(b"P2", w, h, 15, b"\n") + ascii_raster(vals, 13), w, h, 1, 8,
          [scale(v, 15) for v in vals])
    vals = [rnd.randrange(1001) for _ in range(w * h * 3)]
    vals[:3] = [1000, 0, 999]
    write("ppm_p3_1000_13x7.ppm", hdr(b"P3", w, h, 1000, b"\n") + ascii_raster(vals, 9), w, h, 3, 16,
          [scale(v, 1000) for v in vals])
    vals = [rnd.randrange(65536) for _ in range(w * h)]
    write("pgm_p2_65535_13x7.pgm", hdr(b"P2", w, h, 65535, b"\n") + ascii_raster(vals, 5), w, h, 1, 16,
          vals)
    w, h = 33, 17
    vals = [rnd.randrange(256) for _ in range(w * h * 3)]
    write("ppm_p3_255_33x17.ppm", b"P3\n%d %d\n255\n" % (w, h) + ascii_raster(vals, 20), w, h, 3, 8, vals)
    # binary 16-bit maxval 1000
    w, h = 13, 7
    vals = [rnd.randrange(1001) for _ in range(w * h * 3)]
    vals[0] = 10  # the raster starts 0x00 0x0A: a whitespace byte that is data
    write("ppm_p6_1000_13x7.ppm", hdr(b"P6", w, h, 1000, b"\n") + struct.pack(">%dH" % len(vals), *vals),
          w, h, 3, 16, [scale(v, 1000) for v in vals])
    # binary 8-bit maxval 15, raster starting with a whitespace byte (9 = TAB),
    # comment after maxval standing for the single whitespace byte
    w, h = 33, 17
    vals = [rnd.randrange(16) for _ in range(w * h)]
    vals[:2] = [9, 10]
    write("pgm_p5_15_33x17.pgm", b"P5 33 17 15# comment where the whitespace byte goes\n" + bytes(vals),
          w, h, 1, 8, [scale(v, 15) for v in vals])

    # ImageMagick-written 16-bit P6
    w, h = 13, 7
    vals = [rnd.randrange(65536) for _ in range(w * h * 3)]
    with tempfile.TemporaryDirectory() as td:
        src, dst = os.path.join(td, "a.ppm"), os.path.join(td, "b.ppm")
        with open(src, "wb") as f:
            f.write(b"P6\n13 7\n65535\n" + struct.pack(">%dH" % len(vals), *vals))
        subprocess.run([CONVERT, src, "-depth", "16", dst], check=True)
        data = open(dst, "rb").read()
    write("ppm_im_p6_65535_13x7.ppm", data, w, h, 3, 16, vals)


# ---------------------------------------------------------------- HDR
def float2rgbe(r, g, b):
    """Radiance's setcolr(): frexp of the largest channel, mantissas truncated."""
    v = max(r, g, b)
    if v < 1e-32:
        return (0, 0, 0, 0)
    m, e = math.frexp(v)
    d = m * 256.0 / v
    return (int(r * d), int(g * d), int(b * d), e + 128)


def rgbe2float(q):
    if q[3] == 0:
        return [0.0, 0.0, 0.0]
    return [math.ldexp(q[k] + 0.5, q[3] - 136) for k in range(3)]


def hdr_values(w, h, seed):
    """Values spanning 1e-4 .. 1e4 with flat patches (RLE runs)."""
    rnd = random.Random(seed)
    px = []
    for y in range(h):
        for x in range(w):
            if (x // 6 + y // 4) % 3 == 0:
                px.append((0.5, 0.25, 2.0))
            else:
                px.append(tuple(10 ** rnd.uniform(-4, 4) for _ in range(3)))
    px[0] = (1e4, 1e-4, 0.0)
    px[1] = (0.0, 0.0, 0.0)
    return px


def rle_plane(vals):
    """Ward's fwritecolrs() plane coding: runs of >= 4 as (128+n, v), else literals."""
    out = bytearray()
    i, n = 0, len(vals)
    while i < n:
        j = i
        while j < n and vals[j] == vals[i] and j - i < 127:
            j += 1
        if j - i >= 4:
            out += bytes([128 + j - i, vals[i]])
            i = j
            continue
        k = i  # literal up to the next run of 4 or 128 bytes
        while k < n and k - i < 128:
            if k + 3 < n and vals[k] == vals[k + 1] == vals[k + 2] == vals[k + 3]:
                break
            k += 1
        out.append(k - i)
        out += bytes(vals[i:k])
        i = k
    return bytes(out)


def hdr_file(magic, res, scanlines, extra=b""):
    return magic + b"\n" + extra + b"FORMAT=32-bit_rle_rgbe\n\n" + res + b"\n" + b"".join(scanlines)


def hdr_expect(rgbe_rows, bottom_up=False):
    rows = rgbe_rows[::-1] if bottom_up else rgbe_rows
    return [v for row in rows for q in row for v in rgbe2float(q)]


def make_hdr():
    # flat, 13x7 (EXPOSURE and a comment in the header, both ignored)
    w, h = 13, 7
    rows = [[float2rgbe(*p) for p in hdr_values(w, h, 1)[y * w:(y + 1) * w]] for y in range(h)]
    for row in rows:
        for q in row:  # a flat file cannot hold these (they would be read as RLE markers)
            assert q[:3] != (1, 1, 1)
        assert not (row[0][0] == 2 and row[0][1] == 2 and row[0][2] < 128)
    data = hdr_file(b"#?RADIANCE", b"-Y 7 +X 13", [bytes(q for p in row for q in p) for row in rows],
                    b"# made by make_fixtures.py\nEXPOSURE=2.5\n")
    write("hdr_flat_13x7.hdr", data, w, h, 3, 32, hdr_expect(rows))

    # bottom-up flat
    data = hdr_file(b"#?RADIANCE", b"+Y 7 +X 13", [bytes(q for p in row for q in p) for row in rows])
    write("hdr_flat_bottomup_13x7.hdr", data, w, h, 3, 32, hdr_expect(rows, bottom_up=True))

    # 1x1 flat, "#?RGBE" magic, no FORMAT line
    q = float2rgbe(3.0, 0.001, 70.0)
    write("hdr_1x1.hdr", b"#?RGBE\n\n-Y 1 +X 1\n" + bytes(q), 1, 1, 3, 32, rgbe2float(q))

    # new-style RLE, 33x17, hand-encoded as Radiance does
    w, h = 33, 17
    rows = [[float2rgbe(*p) for p in hdr_values(w, h, 2)[y * w:(y + 1) * w]] for y in range(h)]
    lines = []
    for row in rows:
        line = bytes([2, 2, w >> 8, w & 255])
        for c in range(4):
            line += rle_plane([q[c] for q in row])
        lines.append(line)
    data = hdr_file(b"#?RADIANCE", b"-Y 17 +X 33", lines)
    assert any(b > 128 for ln in lines for b in ln[4:]), "no runs"
    write("hdr_rle_33x17.hdr", data, w, h, 3, 32, hdr_expect(rows))

    # new-style RLE bottom-up, 200 wide so that runs of 127 and literals of 128 occur
    w, h = 200, 2
    rows = []
    for y in range(h):
        row = [float2rgbe(0.125, 0.5, 8.0)] * 130 + \
              [float2rgbe(*(10 ** random.Random(x + y).uniform(-4, 4) for _ in range(3))) for x in range(70)]
        rows.append(row)
    lines = []
    for row in rows:
        line = bytes([2, 2, 0, w])
        for c in range(4):
            line += rle_plane([q[c] for q in row])
        lines.append(line)
    write("hdr_rle_bottomup_200x2.hdr", hdr_file(b"#?RADIANCE", b"+Y 2 +X 200", lines), w, h, 3, 32,
          hdr_expect(rows, bottom_up=True))

    # ImageMagick-written RLE (non-HDRI build: values in 0..1)
    w, h = 33, 17
    rnd = random.Random(4)
    vals = [rnd.randrange(65536) if (i // 3) % 7 else 40000 for i in range(w * h * 3)]
    with tempfile.TemporaryDirectory() as td:
        src, dst = os.path.join(td, "a.ppm"), os.path.join(td, "a.hdr")
        with open(src, "wb") as f:
            f.write(b"P6\n%d %d\n65535\n" % (w, h) + struct.pack(">%dH" % len(vals), *vals))
        subprocess.run([CONVERT, src, "-compress", "RLE", dst], check=True)
        data = open(dst, "rb").read()
    body = data[data.index(b"\n\n") + 2:]
    body = body[body.index(b"\n") + 1:]
    assert body[:4] == bytes([2, 2, 0, w]), "ImageMagick did not write new-style RLE"
    rows = decode_new_rle(body, w, h)
    write("hdr_im_rle_33x17.hdr", data, w, h, 3, 32, hdr_expect(rows))

    # old-style RLE, 300x2, "#?RGBE": a pixel, then repeats 43 + (1 << 8) = 299
    # (two consecutive markers), and a second row of singles and short repeats
    w, h = 300, 2
    a, b, c = float2rgbe(1e3, 2e3, 5e2), float2rgbe(1e-4, 3e-4, 2e-4), float2rgbe(7.0, 0.0, 0.3)
    row0 = bytes(a) + bytes([1, 1, 1, 43]) + bytes([1, 1, 1, 1])
    pix1 = [b] * 10 + [c] * 290
    # b, 9 more b; c, a zero repeat (shift becomes 8), 1 << 8 more c; c, 32 more c
    row1 = bytes(b) + bytes([1, 1, 1, 9]) + bytes(c) + bytes([1, 1, 1, 0]) + bytes([1, 1, 1, 1]) + \
        bytes(c) + bytes([1, 1, 1, 32])
    assert 1 + 256 + 1 + 32 == 290
    data = b"#?RGBE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 300\n" + row0 + row1
    write("hdr_oldrle_300x2.hdr", data, w, h, 3, 32, hdr_expect([[a] * 300, pix1]))


def decode_new_rle(body, w, h):
    """Reads new-style RLE scanlines (to interpret ImageMagick's bytes)."""
    rows, pos = [], 0
    for _ in range(h):
        assert body[pos:pos + 2] == b"\x02\x02"
        pos += 4
        planes = []
        for _c in range(4):
            pl = []
            while len(pl) < w:
                n = body[pos]
                pos += 1
                if n > 128:
                    pl += [body[pos]] * (n - 128)
                    pos += 1
                else:
                    pl += list(body[pos:pos + n])
                    pos += n
            assert len(pl) == w
            planes.append(pl)
        rows.append([tuple(planes[c][x] for c in range(4)) for x in range(w)])
    assert pos == len(body)
    return rows


def main():
    os.makedirs(OUT, exist_ok=True)
    for f in os.listdir(OUT):
        os.remove(os.path.join(OUT, f))
    make_tga()
    make_pnm()
    make_hdr()
    with open(os.path.join(OUT, "MANIFEST"), "w") as f:
        f.write("\n".join(manifest) + "\n")
    total = sum(os.path.getsize(os.path.join(OUT, f)) for f in os.listdir(OUT))
    print("%d fixtures, %d bytes in all" % (len(manifest), total))
    assert total < 80 * 1024


if __name__ == "__main__":
    main()
