#!/usr/bin/env python3
"""bench/envmap.py OUT - the scene of bench/envmap.sh: a white sphere on a grey
floor under a 256 x 128 PFM map with a dim sky and a 1-degree sun."""
import math, os, struct, sys

out = sys.argv[1]
w, h = 256, 128
el, az, rad = math.radians(35.0), math.radians(60.0), math.radians(0.5)
sd = (math.cos(el) * math.sin(az), math.sin(el), -math.cos(el) * math.cos(az))
lsun = 3.0 / (math.pi * rad * rad)  # irradiance 3 at normal incidence: the sky gives about 1


def direction(x, y):
    th, ph = math.pi * y / h, 2 * math.pi * x / w
    return (math.sin(th) * math.sin(ph), math.cos(th), -math.sin(th) * math.cos(ph))


rows = []
for y in range(h):
    row = []
    for x in range(w):
        d = direction(x + 0.5, y + 0.5)
        v = 0.2 + 0.3 * max(0.0, d[1])
        if sum(a * b for a, b in zip(d, sd)) > math.cos(math.radians(3.0)):
            n = 16
            cover = sum(1 for i in range(n) for j in range(n)
                        if sum(a * b for a, b in zip(direction(x + (i + .5) / n, y + (j + .5) / n), sd)) > math.cos(rad))
            v += cover / float(n * n) * lsun
        row.append(v)
    rows.append(row)
with open(os.path.join(out, 'sun.pfm'), 'wb') as f:
    f.write(b'PF\n%d %d\n-1.0\n' % (w, h))
    for y in range(h - 1, -1, -1):  # PFM: bottom row first
        f.write(b''.join(struct.pack('<3f', v, v, v) for v in rows[y]))
n = 32
v, fs = [], []
for i in range(n + 1):
    th = math.pi * i / n
    for j in range(2 * n):
        ph = math.pi * j / n
        v.append((math.sin(th) * math.cos(ph), 1 + math.cos(th), math.sin(th) * math.sin(ph)))
for i in range(n):
    for j in range(2 * n):
        a, b = i * 2 * n + j + 1, i * 2 * n + (j + 1) % (2 * n) + 1
        fs.append((a, a + 2 * n, b + 2 * n, b))
with open(os.path.join(out, 'sun.obj'), 'w') as f:
    f.write('mtllib sun.mtl\nusemtl floor\nv -4 0 -4\nv -4 0 4\nv 4 0 4\nv 4 0 -4\nf 1 2 3 4\nusemtl white\n')
    f.write(''.join('v %.6f %.6f %.6f\n' % p for p in v))
    f.write(''.join('f %d %d %d %d\n' % tuple(k + 4 for k in q) for q in fs))
with open(os.path.join(out, 'sun.mtl'), 'w') as f:
    f.write('newmtl floor\nKd 0.5 0.5 0.5\nnewmtl white\nKd 0.8 0.8 0.8\n')
with open(os.path.join(out, 'sun.scene'), 'w') as f:
    f.write('mesh sun.obj\nenvironment map sun.pfm\ncamera eye 0 2.5 6 target 0 0.8 0 fov 40\nimage 128 96\n')
