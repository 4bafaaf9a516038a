#!/usr/bin/env python3
"""scenes/textured/make.py - writes the textured example scene (python3, standard
library only, deterministic): a checker floor, a brick block, a fence whose holes
are a map_d cut-out, a glossy teapot with a marble-like map_Kd, all under
sky.hdr, an HDR sky with a small sun (Radiance RGBE, run-length encoded).

    python3 scenes/textured/make.py        (from the repository root)
"""
import math, os, struct, zlib

HERE = os.path.dirname(os.path.abspath(__file__))


def png(path, w, h, rows, channels):
    """8-bit PNG (colour type 0, 2, 4 or 6) from rows of bytes."""
    ctype = {1: 0, 2: 4, 3: 2, 4: 6}[channels]
    raw = b''.join(b'\x00' + bytes(r) for r in rows)
    def chunk(t, d):
        return struct.pack('>I', len(d)) + t + d + struct.pack('>I', zlib.crc32(t + d) & 0xffffffff)
    with open(path, 'wb') as f:
        f.write(b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', w, h, 8, ctype, 0, 0, 0)) +
                chunk(b'IDAT', zlib.compress(raw, 9)) + chunk(b'IEND', b''))


def rgbe(r, g, b):
    m = max(r, g, b)
    if m < 1e-32:
        return (0, 0, 0, 0)
    e = math.frexp(m)[1]
    s = 256.0 / 2.0 ** e
    return (int(r * s), int(g * s), int(b * s), e + 128)


def hdr(path, w, h, pix):
    """Radiance RGBE with the adaptive run-length encoding of each scanline."""
    out = bytearray(b'#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n' % (h, w))
    for y in range(h):
        row = [rgbe(*pix(x, y)) for x in range(w)]
        out += bytes((2, 2, w >> 8, w & 255))
        for c in range(4):
            vals = [p[c] for p in row]
            i = 0
            while i < w:
                j = i
                while j < w and j - i < 127 and vals[j] == vals[i]:
                    j += 1
                if j - i >= 3:
                    out += bytes((128 + j - i, vals[i]))
                    i = j
                    continue
                j = i
                while j < w and j - i < 128 and not (j + 2 < w and vals[j] == vals[j + 1] == vals[j + 2]):
                    j += 1
                out += bytes((j - i,)) + bytes(vals[i:j])
                i = j
    with open(path, 'wb') as f:
        f.write(bytes(out))


def noise(x, y, seed):
    """Smooth value noise in [0,1): bilinear between hashed lattice values."""
    def h(i, j):
        v = (i * 374761393 + j * 668265263 + seed * 982451653) & 0xffffffff
        v = (v ^ (v >> 13)) * 1274126177 & 0xffffffff
        return ((v ^ (v >> 16)) & 0xffff) / 65536.0
    xi, yi = math.floor(x), math.floor(y)
    fx, fy = x - xi, y - yi
    fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    a = h(xi, yi) * (1 - fx) + h(xi + 1, yi) * fx
    b = h(xi, yi + 1) * (1 - fx) + h(xi + 1, yi + 1) * fx
    return a * (1 - fy) + b * fy


def textures():
    n = 64  # the floor's checker: 8 x 8 squares a tile, the floor repeats it
    png(os.path.join(HERE, 'checker.png'), n, n,
        [[(200 if ((x // 8) + (y // 8)) % 2 else 60) for x in range(n) for _ in range(3)] for y in range(n)], 3)
    w, h = 128, 64  # bricks: 4 rows of 4, offset every other row, grey mortar
    rows = []
    for y in range(h):
        r = []
        for x in range(w):
            bx = (x + (16 if (y // 16) % 2 else 0)) % 32
            mortar = y % 16 < 2 or bx < 2
            k = noise(x / 6.0, y / 6.0, 3)
            c = (170, 165, 155) if mortar else (int(150 + 50 * k), int(60 + 25 * k), int(40 + 15 * k))
            r += c
        rows.append(r)
    png(os.path.join(HERE, 'brick.png'), w, h, rows, 3)
    n = 64  # a fence: boards with round holes, alpha 0 in the holes
    rows = []
    for y in range(n):
        r = []
        for x in range(n):
            cx, cy = (x % 16) - 7.5, (y % 16) - 7.5
            hole = cx * cx + cy * cy < 30 or x % 16 in (0, 15)
            k = noise(x / 3.0, y / 12.0, 5)
            r += (int(120 + 60 * k), int(90 + 40 * k), int(50 + 20 * k), 0 if hole else 255)
        rows.append(r)
    png(os.path.join(HERE, 'fence.png'), n, n, rows, 4)
    n = 128  # marble: veins of a sine of turbulent noise
    rows = []
    for y in range(n):
        r = []
        for x in range(n):
            t = sum(noise(x / s, y / s, 7) * s / 16.0 for s in (16.0, 8.0, 4.0))
            v = 0.5 + 0.5 * math.sin((x / 16.0 + 3 * t) * math.pi)
            r += (int(235 - 90 * v), int(230 - 95 * v), int(225 - 100 * v))
        rows.append(r)
    png(os.path.join(HERE, 'marble.png'), n, n, rows, 3)


def sky():
    """256 x 128: a blue sky brighter at the horizon, a ground below, and a sun of
    1 degree radius, 30 degrees high on the right behind the scene, that gives
    an irradiance of 6 at normal incidence (the sky about 2): sharp shadows
    towards the camera's left and a caustic under the glass sphere.  Each
    texel holds the sun's radiance times the part of it the disk covers."""
    w, h = 256, 128
    el, az, rad = math.radians(30.0), math.radians(60.0), math.radians(1.0)  # az: from -z towards +x
    sd = (math.cos(el) * math.sin(az), math.sin(el), -math.cos(el) * math.cos(az))
    lsun = 6.0 / (math.pi * rad * rad)

    def direction(x, y):
        th, ph = math.pi * y / h, 2 * math.pi * x / w
        return (math.sin(th) * math.sin(ph), math.cos(th), -math.sin(th) * math.cos(ph))

    def pix(x, y):
        d = direction(x + 0.5, y + 0.5)
        if d[1] >= 0:
            t = 1 - d[1]
            base = [0.25 + 0.5 * t * t, 0.45 + 0.45 * t * t, 0.9 + 0.2 * t * t]
        else:
            base = [0.18, 0.16, 0.13]
        c = sum(a * b for a, b in zip(d, sd))
        if c > math.cos(math.radians(4.0)):  # near the sun: how much of the texel it covers
            n = 16
            cover = sum(1 for i in range(n) for j in range(n)
                        if sum(a * b for a, b in zip(direction(x + (i + 0.5) / n, y + (j + 0.5) / n), sd)) >
                        math.cos(rad)) / float(n * n)
            base = [b + cover * lsun * k for b, k in zip(base, (1.0, 0.93, 0.82))]
        glow = 1.5 * max(0.0, c) ** 48
        return tuple(b + glow for b in base)
    hdr(os.path.join(HERE, 'sky.hdr'), w, h, pix)


def mesh():
    """textured.obj and textured.mtl."""
    v, vt, f = [], [], []

    def quad(p0, p1, p2, p3, uv, mat):
        """Corners counter-clockwise seen from the front; uv: (u0, v0, u1, v1)."""
        b = len(v)
        v.extend([p0, p1, p2, p3])
        t = len(vt)
        u0, v0, u1, v1 = uv
        vt.extend([(u0, v0), (u1, v0), (u1, v1), (u0, v1)])
        f.append((mat, [(b + k + 1, t + k + 1) for k in range(4)]))

    quad((-5, 0, 5), (5, 0, 5), (5, 0, -5), (-5, 0, -5), (0, 0, 2, 2), 'floor')
    x0, x1, y0, y1, z0, z1 = -2.4, -0.9, 0.0, 0.8, -0.6, 0.4  # the brick block, one brick texture per 0.75 units
    s = 1 / 0.75
    quad((x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1), (0, 0, (x1 - x0) * s, (y1 - y0) * s), 'brick')
    quad((x1, y0, z0), (x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (0, 0, (x1 - x0) * s, (y1 - y0) * s), 'brick')
    quad((x1, y0, z1), (x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (0, 0, (z1 - z0) * s, (y1 - y0) * s), 'brick')
    quad((x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0), (0, 0, (z1 - z0) * s, (y1 - y0) * s), 'brick')
    quad((x0, y1, z1), (x1, y1, z1), (x1, y1, z0), (x0, y1, z0), (0, 0, (x1 - x0) * s, (z1 - z0) * s), 'brick')
    quad((-3.5, 0, -1.8), (3.5, 0, -1.8), (3.5, 1.4, -1.8), (-3.5, 1.4, -1.8), (0, 0, 5, 1), 'fence')

    def sphere(c, r, mat, n=48):
        b, t = len(v), len(vt)
        for i in range(n + 1):
            th = math.pi * i / n
            for j in range(2 * n + 1):
                ph = math.pi * j / n
                v.append((c[0] + r * math.sin(th) * math.cos(ph), c[1] + r * math.cos(th), c[2] - r * math.sin(th) * math.sin(ph)))
                vt.append((j / (2.0 * n), 1 - i / float(n)))
        for i in range(n):
            for j in range(2 * n):
                a = i * (2 * n + 1) + j
                q = [a, a + 2 * n + 1, a + 2 * n + 2, a + 1]
                if i == 0:
                    q = [a, a + 2 * n + 1, a + 2 * n + 2]
                elif i == n - 1:
                    q = [a, a + 2 * n + 1, a + 1]
                f.append((mat, [(b + k + 1, t + k + 1) for k in q]))
    sphere((1.3, 0.75, -0.2), 0.75, 'marble')
    sphere((-0.2, 0.45, 1.4), 0.45, 'glass', 32)
    with open(os.path.join(HERE, 'textured.obj'), 'w') as o:
        o.write('# written by make.py: a floor, a brick block, a fence, a marble and a glass sphere\n')
        o.write('mtllib textured.mtl\n')
        o.write(''.join('v %.6g %.6g %.6g\n' % p for p in v))
        o.write(''.join('vt %.6g %.6g\n' % t for t in vt))
        cur = None
        for mat, corners in f:
            if mat != cur:
                o.write('usemtl %s\n' % mat)
                cur = mat
            o.write('f ' + ' '.join('%d/%d' % c for c in corners) + '\n')
    with open(os.path.join(HERE, 'textured.mtl'), 'w') as o:
        o.write('newmtl floor\nKd 0.9 0.9 0.9\nmap_Kd checker.png\n\n'
                'newmtl brick\nKd 1 1 1\nmap_Kd brick.png\n\n'
                'newmtl fence\nKd 1 1 1\nmap_Kd fence.png\nmap_d fence.png\n\n'
                'newmtl marble\nKd 0.9 0.9 0.9\nmap_Kd marble.png\nKs 0.08 0.08 0.08\nNs 300\n\n'
                'newmtl glass\nNi 1.5\nillum 7\n')


if __name__ == '__main__':
    textures()
    sky()
    mesh()
