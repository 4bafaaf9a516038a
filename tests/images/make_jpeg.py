#!/usr/bin/python3
"""Builds the JPEG decoder's fixtures: tests/images/jpeg/X.jpg and X.expect.

X.expect is the independent reference: an ASCII header "w h channels depth\\n"
then the raw 8-bit samples that libjpeg-turbo's djpeg (default options)
decodes from X.jpg.  PIL's decode (also libjpeg-turbo) is checked to agree.

Sources are made here (deterministic), encoded with cjpeg / jpegtran / PIL,
and a few are edited by hand to reach syntax the encoders never write
(fill bytes, DQT between scans, a redefined table).

    make_jpeg.py            tests/images/jpeg/ (small, kept under 150 KB)
    make_jpeg.py --bench    tests/out/jpeg-bench/ 2048x2048 4:2:0 baseline and progressive
"""
import atexit, io, os, random, shutil, struct, subprocess, sys, math, tempfile
from PIL import Image

HERE = os.path.dirname(os.path.abspath(__file__))
FIX = os.path.join(HERE, "jpeg")
TMP = tempfile.mkdtemp(prefix="appm-make-jpeg-")
atexit.register(shutil.rmtree, TMP, True)


def photo(w, h, seed, grey=False):
    """Smooth colour gradients, a few soft discs and some noise: photo-like."""
    rnd = random.Random(seed)
    discs = [(rnd.uniform(0, w), rnd.uniform(0, h), rnd.uniform(3, max(4, w / 3)),
              [rnd.randint(0, 255) for _ in range(3)]) for _ in range(4)]
    px = bytearray()
    for y in range(h):
        for x in range(w):
            r = 128 + 100 * math.sin(x * 0.11 + y * 0.05)
            g = 40 + 180 * y / max(1, h - 1)
            b = 200 - 150 * x / max(1, w - 1)
            c = [r, g, b]
            for cx, cy, rad, col in discs:
                t = max(0.0, 1 - math.hypot(x - cx, y - cy) / rad)
                c = [ci * (1 - t) + coli * t for ci, coli in zip(c, col)]
            n = rnd.gauss(0, 9)
            c = [min(255, max(0, int(ci + n + rnd.gauss(0, 3)))) for ci in c]
            px += bytes(c)
    img = Image.frombytes("RGB", (w, h), bytes(px))
    return img.convert("L") if grey else img


def run(args, data=None):
    return subprocess.run(args, input=data, stdout=subprocess.PIPE, check=True).stdout


def cjpeg(img, args):
    os.makedirs(TMP, exist_ok=True)
    src = os.path.join(TMP, "src.pnm")
    img.save(src, "PPM")
    return run(["cjpeg"] + args + [src])


def pil_jpeg(img, **kw):
    b = io.BytesIO()
    img.save(b, "JPEG", **kw)
    return b.getvalue()


def parse_pnm(data):
    """(w, h, channels, samples) of a binary P5/P6 with maxval 255."""
    fields, pos = [], 0
    while len(fields) < 4:
        while data[pos:pos + 1].isspace():
            pos += 1
        if data[pos:pos + 1] == b"#":
            while data[pos:pos + 1] != b"\n":
                pos += 1
            continue
        start = pos
        while not data[pos:pos + 1].isspace():
            pos += 1
        fields.append(data[start:pos])
    pos += 1
    assert fields[0] in (b"P5", b"P6") and fields[3] == b"255", fields
    w, h, ch = int(fields[1]), int(fields[2]), 1 if fields[0] == b"P5" else 3
    return w, h, ch, data[pos:pos + w * h * ch]


def segments(jpg):
    """Splits a JPEG into [(marker, bytes including the marker)], entropy data
    attached to its SOS."""
    out, pos = [(0xD8, jpg[:2])], 2
    while pos < len(jpg):
        assert jpg[pos] == 0xFF
        m = jpg[pos + 1]
        if m == 0xD9:
            out.append((m, jpg[pos:pos + 2]))
            break
        n = struct.unpack(">H", jpg[pos + 2:pos + 4])[0]
        end = pos + 2 + n
        if m == 0xDA:
            while not (jpg[end] == 0xFF and jpg[end + 1] not in (0,) and not 0xD0 <= jpg[end + 1] <= 0xD7):
                end += 1
        out.append((m, jpg[pos:end]))
        pos = end
    return out


SCRIPT_SPECTRAL = """0,1,2: 0 0 0 0;
0: 1 9 0 0;
2: 1 63 0 0;
1: 1 63 0 0;
0: 10 63 0 0;
"""
SCRIPT_SUCCESSIVE = """0: 0 0 0 2;
1 2: 0 0 0 1;
0: 0 0 2 1;
0: 1 5 0 3;
0: 6 63 0 3;
0: 1 63 3 2;
2: 1 63 0 1;
1: 1 63 0 1;
0: 1 63 2 1;
0: 1 63 1 0;
1 2: 0 0 1 0;
0: 0 0 1 0;
2: 1 63 1 0;
1: 1 63 1 0;
"""
SCRIPT_MULTISCAN = """0: 0 63 0 0;
1: 0 63 0 0;
2: 0 63 0 0;
"""
SCRIPT_TWO = """0 1: 0 63 0 0;
2: 0 63 0 0;
"""


def script(text):
    os.makedirs(TMP, exist_ok=True)
    path = os.path.join(TMP, "scans%d.txt" % (abs(hash(text)) % 100000))
    with open(path, "w") as f:
        f.write(text)
    return path


def fixtures():
    big = photo(64, 48, 1)
    mid = photo(33, 17, 2)
    small = photo(17, 9, 3)
    g33 = photo(33, 17, 4, grey=True)
    g64 = photo(64, 48, 5, grey=True)
    one = photo(1, 1, 6)
    f = {}
    # 64x48 photo: the main cases
    f["photo_420_q75"] = cjpeg(big, [])
    f["photo_420_prog"] = cjpeg(big, ["-progressive"])
    # (photo_444_q100_opt, 4:4:4 q100 -optimize, was dropped to keep tests/images small:
    # c33_444, c33_420_q100 and c33_pil_prog_opt cover the same syntax)
    f["photo_422_prog_rst"] = cjpeg(big, ["-sample", "2x1", "-progressive", "-restart", "3B"])
    f["grey64_q75"] = cjpeg(g64, [])
    # 33x17: samplings, qualities, restarts, colour spaces
    f["c33_420_q75"] = cjpeg(mid, [])
    f["c33_444"] = cjpeg(mid, ["-sample", "1x1"])
    f["c33_422"] = cjpeg(mid, ["-sample", "2x1"])
    f["c33_440"] = cjpeg(mid, ["-sample", "1x2"])
    f["c33_420_q10"] = cjpeg(mid, ["-quality", "10"])
    f["c33_420_q100"] = cjpeg(mid, ["-quality", "100"])
    f["c33_420_rst1"] = cjpeg(mid, ["-restart", "1B"])
    f["c33_440_prog"] = cjpeg(mid, ["-sample", "1x2", "-progressive"])
    f["c33_444_prog_q100"] = cjpeg(mid, ["-sample", "1x1", "-progressive", "-quality", "100"])
    f["c33_420_prog_rst1"] = cjpeg(mid, ["-progressive", "-restart", "1B"])
    f["c33_q1_sof1"] = cjpeg(mid, ["-quality", "1"])  # 16-bit tables force SOF1
    f["c33_rgb"] = cjpeg(mid, ["-rgb"])                # Adobe APP14, transform 0
    f["c33_rgb_420"] = cjpeg(mid, ["-rgb", "-sample", "2x2,1x1,1x1"])
    f["c33_411"] = cjpeg(mid, ["-sample", "4x1"])       # 4:1 replicated
    f["c33_yv2"] = cjpeg(mid, ["-sample", "1x1,1x2,1x1"])  # luma upsampled vertically
    f["c33_h4v2"] = cjpeg(mid, ["-sample", "4x2"])      # 10 blocks per MCU
    f["c33_h3"] = cjpeg(mid, ["-sample", "3x1"])
    f["c33_spectral"] = cjpeg(mid, ["-scans", script(SCRIPT_SPECTRAL)])
    f["c33_successive"] = cjpeg(mid, ["-scans", script(SCRIPT_SUCCESSIVE), "-restart", "2B"])
    f["c33_multiscan"] = cjpeg(mid, ["-scans", script(SCRIPT_MULTISCAN)])
    f["c33_twoscans_422"] = cjpeg(mid, ["-sample", "2x1", "-scans", script(SCRIPT_TWO)])
    f["c33_pil_exif"] = pil_jpeg(mid, quality=80, exif=exif_block(), subsampling=2)
    f["c33_pil_prog_opt"] = pil_jpeg(mid, quality=90, progressive=True, optimize=True, subsampling=1)
    f["grey33"] = cjpeg(g33, [])
    f["grey33_prog"] = cjpeg(g33, ["-progressive"])
    f["grey33_rst_q10"] = cjpeg(g33, ["-restart", "2B", "-quality", "10"])
    f["grey33_h2v2"] = cjpeg(g33, ["-grayscale", "-sample", "2x2"])
    # tiny and odd sizes: edge columns, box upsampling when a chroma row has <= 2 samples
    f["c17x9_422_prog"] = cjpeg(small, ["-sample", "2x1", "-progressive"])
    f["c17x9_420"] = cjpeg(small, [])
    f["c1x1_420"] = cjpeg(one, [])
    f["c1x1_prog"] = cjpeg(one, ["-progressive"])
    f["g1x1"] = cjpeg(one.convert("L"), [])
    f["c3x5_420"] = cjpeg(photo(3, 5, 7), [])
    f["c5x3_420"] = cjpeg(photo(5, 3, 8), [])
    f["c4x9_422"] = cjpeg(photo(4, 9, 9), ["-sample", "2x1"])
    f["c6x2_422"] = cjpeg(photo(6, 2, 10), ["-sample", "2x1"])
    f["c9x1_440"] = cjpeg(photo(9, 1, 11), ["-sample", "1x2"])
    # hand edits
    f["c33_fill"] = fill_bytes(f["c33_420_rst1"])
    f["c33_dqt_between"] = dqt_between(f["c33_multiscan"])
    f["c33_dqt_redefined"] = dqt_redefined(f["c33_multiscan"])
    f["c33_jpegtran_rst"] = run(["jpegtran", "-restart", "2B", "-progressive"], f["c33_422"])
    return f


def exif_block():
    ex = Image.Exif()
    ex[0x0112] = 6        # orientation: rotate 90 (ignored: pixels as stored)
    ex[0x010F] = "appm"
    return ex.tobytes()


def fill_bytes(jpg):
    """Extra 0xFF fill bytes before every marker, restart markers included."""
    out = bytearray()
    i = 0
    while i < len(jpg):
        if jpg[i] == 0xFF and i + 1 < len(jpg) and jpg[i + 1] != 0 and i > 0:
            out += b"\xff\xff\xff"
        out.append(jpg[i])
        i += 1
    return bytes(out)


def dqt_between(jpg):
    """Moves the chroma DQT (table 1) to just before the second scan."""
    segs = segments(jpg)
    dqts = [s for s in segs if s[0] == 0xDB]
    chroma = [s for s in dqts if s[1][4] & 15 == 1][0]
    segs.remove(chroma)
    sos = [i for i, s in enumerate(segs) if s[0] == 0xDA]
    segs.insert(sos[1], chroma)
    return b"".join(s[1] for s in segs)


def dqt_redefined(jpg):
    """Redefines both tables with junk after the first scan: the components
    keep the tables they latched at their first scan (libjpeg's rule), but
    components 2 and 3 start later and take the new table 1."""
    segs = segments(jpg)
    sos = [i for i, s in enumerate(segs) if s[0] == 0xDA]
    junk = b"\xff\xdb\x00\x84" + b"\x00" + bytes(range(3, 67)) + b"\x01" + bytes(range(2, 66))
    segs.insert(sos[0] + 1, (0xDB, junk))
    return b"".join(s[1] for s in segs)


def expect_bytes(jpg):
    w, h, ch, px = parse_pnm(run(["djpeg", "-pnm"], jpg))
    pil = Image.open(io.BytesIO(jpg))
    pil.load()
    pb = pil.tobytes()
    same = pil.mode in ("L", "RGB") and pb == px
    return b"%d %d %d 8\n" % (w, h, ch) + px, same


def main():
    if "--bench" in sys.argv:
        d = os.path.join(HERE, "..", "out", "jpeg-bench")
        os.makedirs(d, exist_ok=True)
        img = photo(512, 512, 42).resize((2048, 2048), Image.BICUBIC)
        rnd = random.Random(7)
        noise = bytes(min(255, max(0, v + rnd.randint(-6, 6))) for v in img.tobytes())
        img = Image.frombytes("RGB", img.size, noise)
        for name, args in (("base420", ["-quality", "85"]), ("prog420", ["-quality", "85", "-progressive"])):
            jpg = cjpeg(img, args)
            open(os.path.join(d, name + ".jpg"), "wb").write(jpg)
            open(os.path.join(d, name + ".expect"), "wb").write(expect_bytes(jpg)[0])
        return
    os.makedirs(FIX, exist_ok=True)
    for old in os.listdir(FIX):
        os.remove(os.path.join(FIX, old))
    total = 0
    names = []
    for name, jpg in fixtures().items():
        exp, same = expect_bytes(jpg)
        if not same:
            print("note: PIL and djpeg differ on", name)
        open(os.path.join(FIX, name + ".jpg"), "wb").write(jpg)
        open(os.path.join(FIX, name + ".expect"), "wb").write(exp)
        total += len(jpg) + len(exp)
        names.append(name)
    # refused (arithmetic coding): no .expect, not in LIST
    arith = cjpeg(photo(33, 17, 2), ["-arithmetic"])
    open(os.path.join(FIX, "c33_arith.jpg"), "wb").write(arith)
    total += len(arith)
    with open(os.path.join(FIX, "LIST"), "w") as f:
        f.write("\n".join(names) + "\n")
    print("%d fixtures, %d bytes" % (len(names), total))


if __name__ == "__main__":
    main()
