#!/usr/bin/python3
"""Writes the PNG and OpenEXR fixtures of tests/t_decode.c into tests/images/png/.

Every fixture X comes with X.expect: an ASCII header "w h channels depth\\n"
then the raw samples the file encodes (uint8; uint16 little-endian; float32
little-endian), made from the array given to the encoder here - not from any
decoder - so the C test checks appm's readers against independent writers:
PIL for some PNGs, and for the rest the small PNG and EXR writers below,
written from the PNG specification and the OpenEXR file layout document.
A fixture X with X.fail instead must be refused; X.fail holds a piece of the
expected error message.

Run: /usr/bin/python3 tests/images/make_png.py   (needs PIL and zlib; a C compiler
     for the appm-written EXRs, see gen_appm_exr.c)
     /usr/bin/python3 tests/images/make_png.py --bench DIR   also writes DIR/big.png,
     a 2048x2048 RGBA PNG by PIL, and DIR/big.zlib/.raw for the speed test.
"""
import os
import random
import struct
import sys
import zlib

from PIL import Image

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "png")
ROOT = os.path.dirname(os.path.dirname(HERE))  # the repository


def expect(name, w, h, ch, depth, samples):
    """samples: a flat list of w*h*ch numbers (ints; floats given as uint32 bits)."""
    assert len(samples) == w * h * ch, (name, len(samples), w * h * ch)
    head = b"%d %d %d %d\n" % (w, h, ch, depth)
    if depth == 8:
        body = bytes(samples)
    elif depth == 16:
        body = struct.pack("<%dH" % len(samples), *samples)
    else:
        body = struct.pack("<%dI" % len(samples), *samples)
    with open(os.path.join(OUT, name + ".expect"), "wb") as f:
        f.write(head + body)


def fail(name, data, message):
    with open(os.path.join(OUT, name), "wb") as f:
        f.write(data)
    with open(os.path.join(OUT, name + ".fail"), "w") as f:
        f.write(message)


# ---- PNG ------------------------------------------------------------------------

ADAM7 = [(0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2)]
NCH = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}


def chunk(ty, data):
    return struct.pack(">I", len(data)) + ty + data + struct.pack(">I", zlib.crc32(ty + data) & 0xFFFFFFFF)


def pack_row(pixels, depth):
    """pixels: list of tuples of samples.  PNG 7.2: big-endian, sub-byte
    samples packed leftmost in the high bits, the last byte padded."""
    if depth == 8:
        return bytes(s for px in pixels for s in px)
    if depth == 16:
        return b"".join(struct.pack(">H", s) for px in pixels for s in px)
    out, acc, nb = bytearray(), 0, 0
    for px in pixels:
        for s in px:
            acc = (acc << depth) | s
            nb += depth
            if nb == 8:
                out.append(acc)
                acc, nb = 0, 0
    if nb:
        out.append(acc << (8 - nb))
    return bytes(out)


def paeth(a, b, c):
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    if pa <= pb and pa <= pc:
        return a
    return b if pb <= pc else c


def filt(ftype, cur, prev, bpp):
    out = bytearray([ftype])
    for i in range(len(cur)):
        a = cur[i - bpp] if i >= bpp else 0
        b = prev[i]
        c = prev[i - bpp] if i >= bpp else 0
        pred = [0, a, b, (a + b) >> 1, paeth(a, b, c)][ftype]
        out.append((cur[i] - pred) & 255)
    return bytes(out)


def write_png(name, w, h, ctype, depth, img, palette=None, trns=None, interlace=0,
              filters=None, idat_split=None, level=6, extra=b""):
    """img[y][x] is a tuple of samples at the file's depth.  filters(pass, row)
    picks each row's filter (default: cycles through all five)."""
    if filters is None:
        filters = lambda p, r: (r + p) % 5
    bpp = max(1, NCH[ctype] * depth // 8)
    raw = bytearray()
    passes = ADAM7 if interlace else [(0, 0, 1, 1)]
    for pi, (x0, y0, dx, dy) in enumerate(passes):
        xs, ys = list(range(x0, w, dx)), list(range(y0, h, dy))
        if not xs or not ys:
            continue
        prev = None
        for r, y in enumerate(ys):
            cur = pack_row([img[y][x] for x in xs], depth)
            if prev is None:
                prev = bytes(len(cur))
            raw += filt(filters(pi, r), cur, prev, bpp)
            prev = cur
    z = zlib.compress(bytes(raw), level)
    data = b"\x89PNG\r\n\x1a\n"
    data += chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, ctype, 0, 0, interlace))
    data += chunk(b"gAMA", struct.pack(">I", 45455)) + extra
    if palette is not None:
        data += chunk(b"PLTE", b"".join(bytes(c) for c in palette))
    if trns is not None:
        data += chunk(b"tRNS", trns)
    if idat_split:
        pieces, at, k = [], 0, 0
        while at < len(z):
            n = idat_split[k % len(idat_split)]
            pieces.append(z[at:at + n])
            at += n
            k += 1
        for piece in pieces:
            data += chunk(b"IDAT", piece)
    else:
        data += chunk(b"IDAT", z)
    data += chunk(b"tEXt", b"Comment\x00made by make_fixtures.py")
    data += chunk(b"IEND", b"")
    with open(os.path.join(OUT, name), "wb") as f:
        f.write(data)
    return data


def png_expected(w, h, ctype, depth, img, palette=None, trns=None):
    """The decoded samples appm promises (decode_png.c's header comment)."""
    out = []
    if ctype == 3:
        alpha = list(trns) if trns is not None else []
        ch = 4 if trns is not None else 3
        for y in range(h):
            for x in range(w):
                i = img[y][x][0]
                out += list(palette[i])
                if trns is not None:
                    out.append(alpha[i] if i < len(alpha) else 255)
        return ch, 8, out
    n = NCH[ctype]
    key = None
    if trns is not None:
        key = struct.unpack(">%dH" % (len(trns) // 2), trns)
    top = 65535 if depth == 16 else 255
    for y in range(h):
        for x in range(w):
            px = img[y][x]
            if depth < 8:
                out += [v * 255 // ((1 << depth) - 1) for v in px]
            else:
                out += list(px)
            if key is not None:
                out.append(0 if tuple(px) == tuple(key) else top)
    return n + (1 if key is not None else 0), (16 if depth == 16 else 8), out


def make_img(rng, w, h, n, depth, smooth=True):
    top = (1 << depth) - 1
    img = []
    for y in range(h):
        row = []
        for x in range(w):
            if smooth and rng.random() < 0.7:
                px = tuple(((x * 37 + y * 11 + c * 53) * (top // 31 + 1)) % (top + 1) for c in range(n))
            else:
                px = tuple(rng.randint(0, top) for c in range(n))
            row.append(px)
        img.append(row)
    return img


def png_case(name, rng, w, h, ctype, depth, trns_mode=None, **kw):
    n = NCH[ctype]
    palette = trns = None
    if ctype == 3:
        npal = min(1 << depth, 200 if depth == 8 else 1 << depth)
        palette = [(rng.randint(0, 255), rng.randint(0, 255), rng.randint(0, 255)) for _ in range(npal)]
        img = [[(rng.randint(0, npal - 1),) for x in range(w)] for y in range(h)]
        if trns_mode:
            trns = bytes(rng.randint(0, 255) for _ in range(max(1, npal // 2)))
    else:
        img = make_img(rng, w, h, n, depth)
        if trns_mode:
            key = img[h // 2][w // 2]  # a colour that occurs, so alpha 0 shows up
            trns = b"".join(struct.pack(">H", v) for v in key)
    write_png(name, w, h, ctype, depth, img, palette=palette, trns=trns, **kw)
    ch, d, out = png_expected(w, h, ctype, depth, img, palette, trns)
    expect(name, w, h, ch, d, out)


def pil_case(name, mode, w, h, rng, **save):
    if mode == "1":
        img = Image.new("1", (w, h))
        vals = [rng.randint(0, 1) for _ in range(w * h)]
        img.putdata([v * 255 for v in vals])
        exp = (1, 8, [v * 255 for v in vals])
    elif mode == "I;16":
        vals = [rng.randint(0, 65535) for _ in range(w * h)]
        img = Image.frombytes("I;16", (w, h), struct.pack("<%dH" % len(vals), *vals))
        exp = (1, 16, vals)
    elif mode == "P":
        npal = 5
        pal = [rng.randint(0, 255) for _ in range(3 * npal)]
        idx = [rng.randint(0, npal - 1) for _ in range(w * h)]
        img = Image.new("P", (w, h))
        img.putpalette(pal)
        img.putdata(idx)
        if "transparency" in save:
            t = save["transparency"]
            alpha = list(t) + [255] * (npal - len(t))
            out = []
            for i in idx:
                out += pal[3 * i:3 * i + 3] + [alpha[i]]
            exp = (4, 8, out)
        else:
            out = []
            for i in idx:
                out += pal[3 * i:3 * i + 3]
            exp = (3, 8, out)
    else:
        n = {"L": 1, "LA": 2, "RGB": 3, "RGBA": 4}[mode]
        vals = [rng.randint(0, 255) if rng.random() < 0.5 else (i // n) % 256 for i in range(w * h * n)]
        img = Image.frombytes(mode, (w, h), bytes(vals))
        exp = (n, 8, vals)
    img.save(os.path.join(OUT, name), **save)
    expect(name, w, h, exp[0], exp[1], exp[2])


def make_pngs():
    rng = random.Random(1950)
    legal = {0: [1, 2, 4, 8, 16], 2: [8, 16], 3: [1, 2, 4, 8], 4: [8, 16], 6: [8, 16]}
    for ctype, depths in legal.items():
        for d in depths:
            png_case("t%d_d%d_13x7.png" % (ctype, d), rng, 13, 7, ctype, d)
            png_case("t%d_d%d_1x1.png" % (ctype, d), rng, 1, 1, ctype, d)
            png_case("t%d_d%d_adam7_11x9.png" % (ctype, d), rng, 11, 9, ctype, d, interlace=1)
            if ctype in (0, 2, 3):
                png_case("t%d_d%d_trns_13x7.png" % (ctype, d), rng, 13, 7, ctype, d, trns_mode=1)
    png_case("t6_d16_33x17.png", rng, 33, 17, 6, 16)
    png_case("t2_d8_adam7_33x17.png", rng, 33, 17, 2, 8, interlace=1)
    png_case("t3_d8_trns_adam7_13x7.png", rng, 13, 7, 3, 8, trns_mode=1, interlace=1)
    png_case("t0_d16_trns_adam7_7x13.png", rng, 7, 13, 0, 16, trns_mode=1, interlace=1)
    for w, h in [(1, 1), (2, 3), (5, 5), (9, 2), (1, 9)]:  # Adam7 with empty passes
        png_case("t2_d8_adam7_%dx%d.png" % (w, h), rng, w, h, 2, 8, interlace=1)
    for f in range(5):  # one filter type for every row, bytes per pixel 1, 3, 8
        png_case("t0_d8_filter%d_9x5.png" % f, rng, 9, 5, 0, 8, filters=lambda p, r, f=f: f)
        png_case("t2_d8_filter%d_9x5.png" % f, rng, 9, 5, 2, 8, filters=lambda p, r, f=f: f)
        png_case("t6_d16_filter%d_9x5.png" % f, rng, 9, 5, 6, 16, filters=lambda p, r, f=f: f)
        png_case("t0_d2_filter%d_9x5.png" % f, rng, 9, 5, 0, 2, filters=lambda p, r, f=f: f)
    png_case("t2_d8_split_33x17.png", rng, 33, 17, 2, 8, idat_split=[1, 7, 100, 2])
    png_case("t6_d8_split1_7x5.png", rng, 7, 5, 6, 8, idat_split=[1])
    png_case("t2_d8_level0_33x17.png", rng, 33, 17, 2, 8, level=0)
    png_case("t2_d8_level9_33x17.png", rng, 33, 17, 2, 8, level=9)
    png_case("t4_d8_ancillary_13x7.png", rng, 13, 7, 4, 8,
             extra=chunk(b"prIv", b"an unknown ancillary chunk") + chunk(b"sRGB", b"\x00"))
    png_case("t0_d8_wide_300x2.png", rng, 300, 2, 0, 8)
    # PIL as a second, independent encoder
    pil_case("pil_L_33x17.png", "L", 33, 17, rng)
    pil_case("pil_LA_13x7.png", "LA", 13, 7, rng)
    pil_case("pil_RGB_17x9.png", "RGB", 17, 9, rng)
    pil_case("pil_RGBA_17x9.png", "RGBA", 17, 9, rng, optimize=True)
    pil_case("pil_1_13x7.png", "1", 13, 7, rng)
    pil_case("pil_I16_13x7.png", "I;16", 13, 7, rng)
    pil_case("pil_P_13x7.png", "P", 13, 7, rng)
    pil_case("pil_P_trns_13x7.png", "P", 13, 7, rng, transparency=bytes([0, 128, 255]))
    pil_case("pil_P4_13x7.png", "P", 13, 7, rng, bits=4)

    # files that must be refused, and the words the message must contain
    img = make_img(rng, 4, 4, 3, 8)
    good = write_png("tmp.png", 4, 4, 2, 8, img)
    os.remove(os.path.join(OUT, "tmp.png"))
    ihdr_end = 8 + 25
    fail("bad_critical.png", good[:ihdr_end] + chunk(b"CRIT", b"x") + good[ihdr_end:], "unknown critical chunk CRIT")
    bad = bytearray(good)
    bad[ihdr_end + 8 + 4 + 2] ^= 1  # a bit of the gAMA data
    fail("bad_crc.png", bytes(bad), "CRC mismatch in chunk gAMA")
    fail("bad_depth.png", good[:8] + chunk(b"IHDR", struct.pack(">IIBBBBB", 4, 4, 4, 2, 0, 0, 0)) + good[ihdr_end:],
         "not legal")
    fail("bad_huge.png", good[:8] + chunk(b"IHDR", struct.pack(">IIBBBBB", 32768, 32768, 16, 6, 0, 0, 0)) +
         good[ihdr_end:], "cannot come from")
    fail("bad_noiend.png", good[:-12], "IEND")
    pal = [(i, i, i) for i in range(4)]
    idx = [[(x % 8,) for x in range(8)] for y in range(2)]
    data = write_png("tmp.png", 8, 2, 3, 4, idx, palette=pal)
    os.remove(os.path.join(OUT, "tmp.png"))
    fail("bad_palette_index.png", data, "palette index")


# ---- OpenEXR -----------------------------------------------------------------------

HALF, FLOAT, UINT = 1, 2, 0


def exr_attr(name, ty, value):
    return name + b"\0" + ty + b"\0" + struct.pack("<I", len(value)) + value


def exr_pack(values, ty):
    if ty == HALF:
        return struct.pack("<%dH" % len(values), *values)
    return struct.pack("<%dI" % len(values), *values)


def exr_predict(raw):
    """OpenEXR's ZIP/RLE preprocessing: even bytes then odd bytes, then each
    byte as the difference from the one before, + 128."""
    t = raw[0::2] + raw[1::2]
    out = bytearray(t)
    for i in range(len(t) - 1, 0, -1):
        out[i] = (t[i] - t[i - 1] + 128) & 255
    return bytes(out)


def exr_rle(data):
    """OpenEXR RLE: runs of >= 3 equal bytes as (count - 1, byte), the rest as
    (-count, bytes...), counts up to 127."""
    out, i, n = bytearray(), 0, len(data)
    while i < n:
        j = i
        while j + 1 < n and data[j + 1] == data[i] and j - i < 127:
            j += 1
        run = j - i + 1
        if run >= 3:
            out += bytes([run - 1, data[i]])
            i = j + 1
            continue
        j = i
        while j < n and j - i < 127:
            if j + 2 < n and data[j] == data[j + 1] == data[j + 2]:
                break
            j += 1
        out += bytes([(256 - (j - i)) & 255]) + data[i:j]
        i = j
    return bytes(out)


def h2f_bits(h):
    """The float32 bits of half h (the expected value, computed here apart
    from the C reader)."""
    if (h >> 10) & 31 == 31:
        return ((h & 0x8000) << 16) | 0x7F800000 | ((h & 0x3FF) << 13)
    return struct.unpack("<I", struct.pack("<f", struct.unpack("<e", struct.pack("<H", h))[0]))[0]


def write_exr(name, w, h, chans, compression, x0=0, y0=0, order=0, level=6, extra_attr=b"", version=2):
    """chans: {name: (type, values)} with values[y][x] as half bits, float bits or uint."""
    names = sorted(chans)
    chl = b""
    for n in names:
        chl += n.encode() + b"\0" + struct.pack("<IB3xii", chans[n][0], 0, 1, 1)
    chl += b"\0"
    hdr = struct.pack("<II", 20000630, version)
    hdr += exr_attr(b"channels", b"chlist", chl)
    hdr += exr_attr(b"compression", b"compression", bytes([compression]))
    hdr += exr_attr(b"dataWindow", b"box2i", struct.pack("<iiii", x0, y0, x0 + w - 1, y0 + h - 1))
    hdr += exr_attr(b"displayWindow", b"box2i", struct.pack("<iiii", 0, 0, 99, 99))
    hdr += extra_attr
    hdr += exr_attr(b"lineOrder", b"lineOrder", bytes([order]))
    hdr += exr_attr(b"pixelAspectRatio", b"float", struct.pack("<f", 1))
    hdr += exr_attr(b"screenWindowCenter", b"v2f", struct.pack("<ff", 0, 0))
    hdr += exr_attr(b"screenWindowWidth", b"float", struct.pack("<f", 1))
    hdr += b"\0"
    lines = {0: 1, 1: 1, 2: 1, 3: 16}.get(compression, 16)
    blocks = []
    for b0 in range(0, h, lines):
        raw = b""
        for y in range(b0, min(h, b0 + lines)):
            for n in names:
                raw += exr_pack(chans[n][1][y], chans[n][0])
        if compression in (2, 3):
            z = zlib.compress(exr_predict(raw), level)
            data = z if len(z) < len(raw) else raw
        elif compression == 1:
            r = exr_rle(exr_predict(raw))
            data = r if len(r) < len(raw) else raw
        else:
            data = raw
        blocks.append(struct.pack("<iI", y0 + b0, len(data)) + data)
    # the table is in increasing-y order; DECREASING_Y stores the blocks bottom first
    table_end = len(hdr) + 8 * len(blocks)
    offsets, at = [0] * len(blocks), table_end
    for k in (range(len(blocks)) if order == 0 else reversed(range(len(blocks)))):
        offsets[k] = at
        at += len(blocks[k])
    body = b"".join(blocks[k] for k in (range(len(blocks)) if order == 0 else reversed(range(len(blocks)))))
    data = hdr + b"".join(struct.pack("<Q", o) for o in offsets) + body
    with open(os.path.join(OUT, name), "wb") as f:
        f.write(data)
    return data


def exr_values(rng, w, h, ty, special):
    rows = []
    for y in range(h):
        row = []
        for x in range(w):
            if ty == HALF:
                v = struct.unpack("<H", struct.pack("<e", (x - 3) * 0.37 + y * 1.5 + rng.random() * 0.1))[0]
            elif ty == FLOAT:
                v = struct.unpack("<I", struct.pack("<f", (x - 3) * 0.37 + y * 1.5 + rng.random()))[0]
            else:
                v = rng.randint(0, 0xFFFFFFFF) if rng.random() < 0.3 else x * 1000 + y
            row.append(v)
        rows.append(row)
    if special and h >= 2 and w >= 7:
        if ty == HALF:  # subnormals, zeros, infinities, NaNs with payloads, the largest half
            row = [0x0001, 0x03FF, 0x8001, 0x0000, 0x8000, 0x7C00, 0xFC00]
            rows[1][:7] = row
            rows[0][:4] = [0x7C01, 0xFE00, 0x7BFF, 0x0400]
        elif ty == FLOAT:
            rows[1][:5] = [0x7F800000, 0xFF800000, 0x7FA12345, 0x00000001, 0x80000000]
    return rows


def exr_expected(w, h, chans):
    if "R" in chans:
        order = ["R", "G", "B"] + (["A"] if "A" in chans else [])
    else:
        order = ["Y"]
    out = []
    for y in range(h):
        for x in range(w):
            for n in order:
                ty, vals = chans[n]
                v = vals[y][x]
                if ty == HALF:
                    out.append(h2f_bits(v))
                elif ty == FLOAT:
                    out.append(v)
                else:
                    out.append(struct.unpack("<I", struct.pack("<f", float(v)))[0])
    return len(order), out


def exr_case(name, rng, w, h, layout, compression, special=True, **kw):
    """layout: {channel name: type}"""
    chans = {n: (ty, exr_values(rng, w, h, ty, special)) for n, ty in layout.items()}
    write_exr(name, w, h, chans, compression, **kw)
    ch, out = exr_expected(w, h, chans)
    expect(name, w, h, ch, 32, out)


def make_exrs():
    rng = random.Random(20000630)
    cname = {0: "none", 1: "rle", 2: "zips", 3: "zip"}
    for c in range(4):
        exr_case("rgb_half_%s_7x5.exr" % cname[c], rng, 7, 5, {"R": HALF, "G": HALF, "B": HALF}, c)
        exr_case("rgb_float_%s_7x5.exr" % cname[c], rng, 7, 5, {"R": FLOAT, "G": FLOAT, "B": FLOAT}, c)
        hh = 18 if c == 3 else 5  # ZIP: more than one 16-line block, the last one short
        exr_case("rgba_half_%s_9x%d.exr" % (cname[c], hh), rng, 9, hh, {"R": HALF, "G": HALF, "B": HALF, "A": HALF}, c)
        exr_case("y_float_%s_7x5.exr" % cname[c], rng, 7, 5, {"Y": FLOAT}, c)
    exr_case("y_half_zip_1x1.exr", rng, 1, 1, {"Y": HALF}, 3)
    exr_case("rgb_mixed_zip_9x20.exr", rng, 9, 20,
             {"R": FLOAT, "G": HALF, "B": UINT, "Z": FLOAT, "diffuse.R": HALF}, 3)
    exr_case("rgba_float_zip_offset_decreasing_7x20.exr", rng, 7, 20,
             {"R": FLOAT, "G": FLOAT, "B": FLOAT, "A": HALF}, 3, x0=-5, y0=100, order=1)
    exr_case("rgb_half_none_decreasing_offset_13x7.exr", rng, 13, 7, {"R": HALF, "G": HALF, "B": HALF}, 0,
             x0=7, y0=-3, order=1)
    exr_case("rgb_half_zips_level9_13x7.exr", rng, 13, 7, {"R": HALF, "G": HALF, "B": HALF}, 2, level=9,
             extra_attr=exr_attr(b"owner", b"string", b"make_fixtures.py"))
    exr_case("rgb_float_zip_level0_13x7.exr", rng, 13, 7, {"R": FLOAT, "G": FLOAT, "B": FLOAT}, 3, level=0)
    exr_case("ya_half_zip_13x7.exr", rng, 13, 7, {"Y": HALF, "A": HALF}, 3)
    # refusals
    rgb = {"R": (HALF, exr_values(rng, 4, 4, HALF, False)), "G": (HALF, exr_values(rng, 4, 4, HALF, False)),
           "B": (HALF, exr_values(rng, 4, 4, HALF, False))}
    data = write_exr("tmp.exr", 4, 4, rgb, 4)
    fail("bad_piz.exr", data, "PIZ")
    data = write_exr("tmp.exr", 4, 4, rgb, 6)
    fail("bad_b44.exr", data, "B44")
    data = write_exr("tmp.exr", 4, 4, rgb, 0, version=2 | 0x200)
    fail("bad_tiled.exr", data, "tiled")
    data = write_exr("tmp.exr", 4, 4, rgb, 0, version=2 | 0x1000)
    fail("bad_multipart.exr", data, "multi-part")
    data = write_exr("tmp.exr", 4, 4, rgb, 0, version=2 | 0x800)
    fail("bad_deep.exr", data, "deep")
    data = write_exr("tmp.exr", 4, 4, {"R": rgb["R"], "B": rgb["B"]}, 3)
    fail("bad_missing_g.exr", data, "channel G is missing")
    os.remove(os.path.join(OUT, "tmp.exr"))


def appm_exrs():
    """EXRs written by appm itself (gen_appm_exr.c), when its source is here."""
    import subprocess
    src = os.path.join(ROOT, "appm.c")
    if not os.path.exists(src):
        print("no %s: appm-written EXR fixtures not made" % src)
        return
    exe = os.path.join(OUT, "gen_appm_exr")
    subprocess.check_call(["cc", "-O1", "-w", "-I" + ROOT, os.path.join(HERE, "gen_appm_exr.c"), src,
                           "-o", exe, "-lm", "-pthread"])
    subprocess.check_call([exe, OUT])
    os.remove(exe)


def zdata(n):
    """The inflate test data, also made by zdata() in tests/t_decode.c: words from a
    small vocabulary chosen by an LCG (compressible, with short matches), and a
    256-byte noise run repeated 32000 bytes later (a long-distance match) - all
    in integers so the two languages agree byte for byte."""
    words = [b"red ", b"green ", b"blue ", b"photon ", b"map\n", b"kd-tree ", b"splat ", b"x"]
    out = bytearray()
    x = 1
    while len(out) < n:
        x = (x * 1103515245 + 12345) & 0x7FFFFFFF
        if len(out) % 40000 < 8 and len(out) >= 8:
            # noise: 256 bytes; the same again 32000 bytes on
            noise = bytearray()
            y = len(out) // 40000 + 7
            for _ in range(256):
                y = (y * 1103515245 + 12345) & 0x7FFFFFFF
                noise.append((y >> 16) & 255)
            out += noise
            out += b"." * (32000 - 256)
            out += noise
            continue
        out += words[(x >> 16) & 7 if (x >> 24) & 15 == 0 else (x >> 16) & 1]
    return bytes(out[:n])


def make_zlib():
    big = zdata(70000)
    small = big[:3000]
    streams = [("z_level0_3000.zz", zlib.compress(small, 0)),
               ("z_level6_70000.zz", zlib.compress(big, 6)),
               ("z_level9_70000.zz", zlib.compress(big, 9)),
               ("z_empty_0.zz", zlib.compress(b"", 6))]
    c = zlib.compressobj(6, zlib.DEFLATED, 15, 9, zlib.Z_FIXED)
    streams.append(("z_fixed_70000.zz", c.compress(big) + c.flush()))
    c = zlib.compressobj(6, zlib.DEFLATED, 15, 9, zlib.Z_HUFFMAN_ONLY)
    streams.append(("z_huffonly_3000.zz", c.compress(small) + c.flush()))
    for name, z in streams:
        with open(os.path.join(OUT, name), "wb") as f:
            f.write(z)


def make_bench(d):
    os.makedirs(d, exist_ok=True)
    rng = random.Random(7)
    w = h = 2048
    # a photograph-like picture: smooth gradients with a little noise
    row = bytearray()
    buf = bytearray(w * h * 4)
    for y in range(h):
        for x in range(w):
            i = 4 * (y * w + x)
            n = rng.randint(0, 7) if (x * y) % 7 == 0 else 0
            buf[i] = (x // 8 + n) & 255
            buf[i + 1] = (y // 8 + n) & 255
            buf[i + 2] = ((x + y) // 16) & 255
            buf[i + 3] = 255 if x % 64 else 128
    del row
    Image.frombytes("RGBA", (w, h), bytes(buf)).save(os.path.join(d, "big.png"))
    with open(os.path.join(d, "big.rgba"), "wb") as f:
        f.write(buf)
    with open(os.path.join(d, "big.zlib"), "wb") as f:
        f.write(zlib.compress(bytes(buf), 6))


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--bench":
        make_bench(sys.argv[2])
        sys.exit(0)
    os.makedirs(OUT, exist_ok=True)
    for f in os.listdir(OUT):
        os.remove(os.path.join(OUT, f))
    make_pngs()
    make_exrs()
    appm_exrs()
    make_zlib()
    names = sorted(f for f in os.listdir(OUT) if f.endswith((".png", ".exr", ".zz")))
    with open(os.path.join(OUT, "index.txt"), "w") as f:
        f.write("".join(n + "\n" for n in names))
    total = sum(os.path.getsize(os.path.join(OUT, f)) for f in os.listdir(OUT))
    print("%d files, %d bytes" % (len(os.listdir(OUT)), total))
