#!/usr/bin/env python3
"""tests/web.py - the classroom page (web/) in a real browser, against the native build.

make test-web runs it after `make web` and `make appm`.  It serves web/ on 127.0.0.1,
opens index.html in headless Chromium (DevTools protocol over a pipe: no package
needed), and lets the page itself - the same controls, workers and appm.wasm a
student gets - render CornellBox-Sphere with appm and ppm side by side for a fixed
number of passes (appm with the qmc sampler, ppm with the random one).  Then it checks:

  * the pixels against `appm render` of the same scene, seed, size and passes.
    Identical bytes are not possible: pow, sin, cos, tan, sinf and cosf of
    wasi-libc and of glibc differ in the last bit for some arguments, so a few
    paths take another turn (web/README.md).  The test holds the difference to
    a two-hundredth of the image's own noise, measured as the RMS difference of two
    native renders with seeds s and s + 1, and 99 % of the values to within 1e-3
    (relative, + 1e-3 absolute); it prints how many values are bit-identical;
  * the statistics (passes, photons) and that the estimated error was plotted;
  * the maps: appm's radius, variance and Laplacian maps drawn, ppm's Laplacian
    absent (it keeps none);
  * with camera=scene, the page's render of cornell-sphere.scene (the .scene with
    the OBJ and MTL it names, from memory) against `appm render` of that .scene;
  * no exception and no console error in the page or its workers;
and saves screenshots: build/web/classroom.png and .jpg (the README's picture), and
build/web/default.png (the page as it opens).

  python3 tests/web.py [--bench [SIZE [PASSES]]]
                     --bench: passes/s of appm, wasm in Chromium against the native build
                     on 1 thread, SIZE x SIZE (128) for PASSES passes (64), medians of 3
Environment: CHROMIUM (the browser; default: chromium, chromium-browser, google-chrome).
The last line is "N passed, N failed"; the exit status is non-zero on failure.
"""
import base64
import fcntl
import functools
import http.server
import json
import os
import shutil
import statistics
import struct
import subprocess
import sys
import tempfile
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "build", "web")
SCENE = "CornellBox-Sphere"
SIZE, PASSES, SEED = 128, 32, 7
SETTINGS = (("appm", "qmc"), ("ppm", "random"), ("appm-paper", "qmc"))  # method and sampler of the sides
NOISE_FRACTION = 1 / 200.0  # of the seed-to-seed RMS difference
REL_TOL, REL_QUANTILE = 1e-3, 0.99

passed = failed = 0


def check(ok, what):
    global passed, failed
    if ok:
        passed += 1
        print("ok   " + what)
    else:
        failed += 1
        print("FAIL " + what)
    sys.stdout.flush()
    return ok


# ---- the static server ---------------------------------------------------------

class QuietHandler(http.server.SimpleHTTPRequestHandler):
    extensions_map = dict(http.server.SimpleHTTPRequestHandler.extensions_map,
                          **{".wasm": "application/wasm", ".js": "text/javascript"})

    def log_message(self, *args):
        pass


def serve(folder):
    handler = functools.partial(QuietHandler, directory=folder)
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    return httpd


# ---- Chromium over the DevTools protocol (--remote-debugging-pipe) --------------

class Browser:
    """Chromium reads commands from its fd 3 and writes replies and events to fd 4,
    each a JSON text ended by a NUL byte."""

    def __init__(self, exe, profile):
        to_child_r, self.to_child = os.pipe()
        self.from_child, from_child_w = os.pipe()
        hi_r = fcntl.fcntl(to_child_r, fcntl.F_DUPFD, 10)
        hi_w = fcntl.fcntl(from_child_w, fcntl.F_DUPFD, 10)

        def child_fds():
            os.dup2(hi_r, 3)
            os.dup2(hi_w, 4)

        args = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                "--no-default-browser-check", "--disable-extensions", "--mute-audio",
                "--disable-background-networking", "--hide-scrollbars", "--disable-dev-shm-usage",
                "--user-data-dir=" + profile, "--remote-debugging-pipe", "about:blank"]
        self.log = open(os.path.join(OUT, "chromium.log"), "w")
        self.proc = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=self.log,
                                     stderr=self.log, close_fds=False, preexec_fn=child_fds)
        for fd in (to_child_r, from_child_w, hi_r, hi_w):
            os.close(fd)
        self.next_id = 0
        self.replies = {}
        self.events = []
        self.cond = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        buf = b""
        while True:
            chunk = os.read(self.from_child, 1 << 16)
            if not chunk:
                break
            buf += chunk
            while b"\0" in buf:
                raw, buf = buf.split(b"\0", 1)
                msg = json.loads(raw)
                with self.cond:
                    if "id" in msg:
                        self.replies[msg["id"]] = msg
                    else:
                        self.events.append(msg)
                        self._on_event(msg)
                    self.cond.notify_all()
        with self.cond:
            self.closed = True
            self.cond.notify_all()

    def _on_event(self, msg):
        # Workers are attached paused; enable their console, then let them run.
        if msg.get("method") == "Target.attachedToTarget":
            sid = msg["params"]["sessionId"]
            self.send("Runtime.enable", session=sid, wait=False)
            self.send("Runtime.runIfWaitingForDebugger", session=sid, wait=False)

    def send(self, method, params=None, session=None, wait=True, timeout=30):
        with self.cond:
            self.next_id += 1
            mid = self.next_id
        msg = {"id": mid, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self.to_child, json.dumps(msg).encode() + b"\0")
        if not wait:
            return None
        end = time.time() + timeout
        with self.cond:
            while mid not in self.replies:
                left = end - time.time()
                if left <= 0 or getattr(self, "closed", False):
                    raise RuntimeError("no reply to " + method)
                self.cond.wait(left)
            reply = self.replies.pop(mid)
        if "error" in reply:
            raise RuntimeError(method + ": " + json.dumps(reply["error"]))
        return reply.get("result", {})

    def close(self):
        try:
            self.send("Browser.close", wait=False)
            self.proc.wait(10)
        except Exception:
            self.proc.kill()
            self.proc.wait()
        self.log.close()


def page_errors(events):
    """Exceptions, console errors and error log entries of the page and its workers."""
    out = []
    for e in events:
        m, p = e.get("method"), e.get("params", {})
        if m == "Runtime.exceptionThrown":
            d = p["exceptionDetails"]
            out.append("exception: " + d.get("exception", {}).get("description", d.get("text", "")))
        elif m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
            out.append("console.error: " + " ".join(str(a.get("value", a.get("description", "")))
                                                     for a in p.get("args", [])))
        elif m == "Log.entryAdded" and p["entry"].get("level") == "error":
            out.append("log: " + p["entry"].get("text", "") + " " + p["entry"].get("url", ""))
    return out


def open_page(browser, url, width=1600, height=1500):
    target = browser.send("Target.createTarget", {"url": "about:blank"})["targetId"]
    sid = browser.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
    for method in ("Runtime.enable", "Log.enable", "Page.enable"):
        browser.send(method, session=sid)
    browser.send("Target.setAutoAttach", {"autoAttach": True, "waitForDebuggerOnStart": True,
                                          "flatten": True}, session=sid)
    browser.send("Emulation.setDeviceMetricsOverride", {"width": width, "height": height,
                                                        "deviceScaleFactor": 1, "mobile": False},
                 session=sid)
    browser.send("Page.navigate", {"url": url}, session=sid)
    return sid


def wait_result(browser, sid, timeout):
    end = time.time() + timeout
    while time.time() < end:
        r = browser.send("Runtime.evaluate", {
            "expression": "window.appmTest ? JSON.stringify(window.appmTest) : ''",
            "returnByValue": True}, session=sid)
        value = r.get("result", {}).get("value", "")
        if value:
            return json.loads(value)
        time.sleep(0.2)
    return None


# ---- the native side ------------------------------------------------------------

def read_pfm(path):
    """Linear RGB floats, row 0 at the top (PFM stores rows bottom to top)."""
    with open(path, "rb") as f:
        data = f.read()
    kind, dims, scale, body = data.split(b"\n", 3)
    w, h = map(int, dims.split())
    fmt = ("<" if float(scale) < 0 else ">") + "%df" % (3 * w)
    rows = [struct.unpack_from(fmt, body, 12 * w * y) for y in range(h)]
    out = []
    for row in reversed(rows):
        out.extend(row)
    return w, h, out


def native(method, passes, threads=None, size=SIZE, seed=SEED, sampler="qmc", scene=SCENE + ".obj"):
    path = os.path.join(OUT, "native-%s-%s-%s-seed%d.pfm" % (scene, method, sampler, seed))
    cmd = [os.path.join(ROOT, "appm"), "render", os.path.join(ROOT, "scenes", scene),
           "--size", "%dx%d" % (size, size), "--seed", str(seed), "--passes", str(passes),
           "--method", method, "--sampler", sampler, "-q", "-o", path]
    if threads:
        cmd += ["--threads", str(threads)]
    line = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    fields = dict(kv.split("=", 1) for kv in line.split() if "=" in kv)
    return path, fields


def rms_difference(a, b):
    return (sum((x - y) ** 2 for x, y in zip(a, b)) / len(a)) ** 0.5


def compare(side, ref_path):
    """Size, bit-identical values, count, RMS difference, REL_QUANTILE of the
    relative difference, of the page's image against the native one."""
    w, h, ref = read_pfm(ref_path)
    raw = base64.b64decode(side["linear"])
    with open(os.path.join(OUT, "wasm-%s.raw" % side["method"]), "wb") as f:
        f.write(raw)  # little-endian float RGB, row 0 at the top: for a look after a failure
    got = struct.unpack("<%df" % (3 * w * h), raw)
    same = sum(1 for a, b in zip(got, ref) if a == b)
    rel = sorted(abs(a - b) / (abs(b) + 1e-3) for a, b in zip(got, ref))
    return w, h, same, len(ref), rms_difference(got, ref), rel[int(REL_QUANTILE * (len(rel) - 1))]


# ---- the checks ---------------------------------------------------------------------

def browser_exe():
    for name in (os.environ.get("CHROMIUM"), "chromium", "chromium-browser", "google-chrome"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def check_side(side, ref, noise):
    m = side["method"]
    check(side["sampler"] == dict(SETTINGS)[m], "%s: the %s sampler" % (m, side["sampler"]))
    st = side["stats"]
    check(st["passes"] == PASSES and st["photons"] == PASSES * SIZE * SIZE,
          "%s: %d passes of %d photon paths (got %d passes, %d photons)"
          % (m, PASSES, SIZE * SIZE, st["passes"], st["photons"]))
    w, h, same, n, rms, rel = compare(side, ref)
    check((w, h) == (SIZE, SIZE), "%s: the native image is %dx%d" % (m, w, h))
    check(rms <= NOISE_FRACTION * noise,
          "%s: wasm against native, RMS difference %.3g <= 1/200 of the seed-to-seed noise %.3g "
          "(%d of %d values bit-identical)" % (m, rms, noise, same, n))
    check(rel <= REL_TOL, "%s: %g %% of the values within %g relative (the %g quantile is %.3g)"
          % (m, 100 * REL_QUANTILE, REL_TOL, REL_QUANTILE, rel))
    check(side["image_colours"] > 500, "%s: the image has %d colours" % (m, side["image_colours"]))
    radius, variance, laplacian = side["map_colours"]
    if m in ("appm", "appm-paper"):
        check(radius > 16 and variance > 16 and laplacian > 16,
              "%s: radius, variance and Laplacian maps drawn (%d, %d, %d colours)"
              % (m, radius, variance, laplacian))
        check(side["history"] == PASSES - 1,
              "%s: estimated error plotted for passes 2..%d (%d points)" % (m, PASSES, side["history"]))
    else:
        check(radius >= 1 and variance > 16 and laplacian == 0,
              "ppm: one global radius, a variance map, no Laplacian (%d, %d, %d colours)"
              % (radius, variance, laplacian))


def run_test(browser, base):
    refs, noise = {}, {}
    for m, smp in SETTINGS:
        refs[m] = native(m, PASSES, sampler=smp)[0]
        other = native(m, PASSES, seed=SEED + 1, sampler=smp)[0]
        noise[m] = rms_difference(read_pfm(refs[m])[2], read_pfm(other)[2])
    url = "%s/index.html?test=1&scene=%s&size=%d&passes=%d&seed=%d&methods=%s&equal=passes" % (
        base, SCENE, SIZE, PASSES, SEED, ",".join(m + ":" + smp for m, smp in SETTINGS))
    t0 = time.time()
    sid = open_page(browser, url)
    result = wait_result(browser, sid, 100)
    if not check(result is not None, "the page finished %d passes of appm, ppm and appm-paper (%.1f s)"
                 % (PASSES, time.time() - t0)):
        return
    if not check("error" not in result, "the page reported no error (%s)" % result.get("error", "")):
        return
    for side in result["sides"]:
        check_side(side, refs[side["method"]], noise[side["method"]])
    time.sleep(0.3)  # the last frame of the plot
    height = browser.send("Runtime.evaluate", {"expression": "document.documentElement.scrollHeight",
                                               "returnByValue": True}, session=sid)["result"]["value"]
    browser.send("Emulation.setDeviceMetricsOverride", {"width": 1600, "height": int(height) + 10,
                                                        "deviceScaleFactor": 1, "mobile": False},
                 session=sid)
    time.sleep(0.3)
    for fmt, extra in (("png", {}), ("jpeg", {"quality": 85})):  # the README shows the JPEG
        shot = browser.send("Page.captureScreenshot", dict(format=fmt, **extra), session=sid)
        path = os.path.join(OUT, "classroom." + fmt.replace("jpeg", "jpg"))
        with open(path, "wb") as f:
            f.write(base64.b64decode(shot["data"]))
        check(os.path.getsize(path) > 10000, "screenshot %s (%d bytes)"
              % (os.path.relpath(path, ROOT), os.path.getsize(path)))


def run_scene_camera(browser, base, size=64, passes=8):
    """camera=scene: the page loads cornell-sphere.scene with the OBJ and MTL it names
    (appm_scene_load_memory), so its image is `appm render scenes/cornell-sphere.scene`,
    not the render of the bare OBJ with its framed camera."""
    ref = native("appm", passes, size=size, scene="cornell-sphere.scene")[0]
    noise = rms_difference(read_pfm(ref)[2], read_pfm(native("appm", passes, size=size, seed=SEED + 1,
                                                             scene="cornell-sphere.scene")[0])[2])
    framed = read_pfm(native("appm", passes, size=size)[0])[2]
    url = "%s/index.html?test=1&scene=%s&size=%d&passes=%d&seed=%d&methods=appm:qmc&camera=scene" % (
        base, SCENE, size, passes, SEED)
    sid = open_page(browser, url)
    result = wait_result(browser, sid, 60)
    if not check(result is not None and "error" not in result,
                 "camera=scene: the page rendered cornell-sphere.scene (%s)" % (result or {}).get("error", "")):
        return
    side = result["sides"][0]
    w, h, same, n, rms, rel = compare(side, ref)
    got = struct.unpack("<%df" % (3 * w * h), base64.b64decode(side["linear"]))
    check(rms <= NOISE_FRACTION * noise,
          "camera=scene: against `appm render scenes/cornell-sphere.scene`, RMS difference %.3g <= 1/200 "
          "of the seed-to-seed noise %.3g (%d of %d values bit-identical)" % (rms, noise, same, n))
    far = rms_difference(got, framed)
    check(far > 3 * noise, "camera=scene: not the framed camera of the bare OBJ (RMS difference %.3g > "
          "3 x the noise, %.3g)" % (far, 3 * noise))
    browser.send("Target.closeTarget", {"targetId": browser.send("Target.getTargetInfo", session=sid)
                                        ["targetInfo"]["targetId"]})


def state(browser, sid):
    r = browser.send("Runtime.evaluate", {"expression": "JSON.stringify(window.appmState())",
                                          "returnByValue": True}, session=sid)
    return json.loads(r["result"]["value"])


def key(browser, sid, k, code):
    for kind in ("keyDown", "keyUp"):
        browser.send("Input.dispatchKeyEvent", {"type": kind, "key": k, "code": code,
                                                "text": k if kind == "keyDown" else ""}, session=sid)


def run_default_page(browser, base):
    """The page as a student opens it: the first preset (ppm with a quarter of the
    automatic radius against appm, at equal time) starts by itself; Space pauses,
    N runs one more pass of each setting."""
    sid = open_page(browser, base + "/index.html")
    time.sleep(4)
    s = state(browser, sid)
    if not check(s is not None and len(s["sides"]) == 2 and all(x["passes"] >= 3 for x in s["sides"]),
                 "index.html starts rendering by itself (%s)" % s):
        return
    secs = [x["seconds"] for x in s["sides"]]
    slack = max(x["lastPass"] for x in s["sides"]) + 0.05
    check(s["equal"] == "time" and abs(secs[0] - secs[1]) <= 2 * slack,
          "equal time: %.2f s and %.2f s inside passes, apart by at most about a pass (%.2f s)"
          % (secs[0], secs[1], slack))
    shot = browser.send("Page.captureScreenshot", {"format": "png"}, session=sid)
    with open(os.path.join(OUT, "default.png"), "wb") as f:
        f.write(base64.b64decode(shot["data"]))
    browser.send("Runtime.evaluate", {"expression": "document.activeElement.blur()"}, session=sid)
    key(browser, sid, " ", "Space")
    time.sleep(1.0)
    a = state(browser, sid)
    time.sleep(0.6)
    b = state(browser, sid)
    check(not a["running"] and [x["passes"] for x in a["sides"]] == [x["passes"] for x in b["sides"]],
          "Space pauses (passes stay at %s)" % [x["passes"] for x in b["sides"]])
    mean = ("(function () { var c = document.querySelector('canvas.img'), d = c.getContext('2d')"
            ".getImageData(0, 0, c.width, c.height).data, t = 0; for (var i = 0; i < d.length; i += 4)"
            " t += d[i] + d[i + 1] + d[i + 2]; return t / d.length; })()")
    before = browser.send("Runtime.evaluate", {"expression": mean, "returnByValue": True},
                          session=sid)["result"]["value"]
    key(browser, sid, "+", "Equal")
    time.sleep(0.8)
    after = browser.send("Runtime.evaluate", {"expression": mean, "returnByValue": True},
                         session=sid)["result"]["value"]
    check(after > before * 1.05, "+ raises the exposure of the paused picture (mean byte %.1f -> %.1f)"
          % (before, after))
    key(browser, sid, "n", "KeyN")
    time.sleep(1.5)
    c = state(browser, sid)
    want = [1 + x["passes"] for x in b["sides"]]
    check([x["passes"] for x in c["sides"]] == want,
          "N runs one more pass of each setting (%s, want %s)" % ([x["passes"] for x in c["sides"]], want))
    browser.send("Target.closeTarget", {"targetId": browser.send("Target.getTargetInfo", session=sid)
                                        ["targetInfo"]["targetId"]})


def run_bench(browser, base, size=128, passes=64):
    """Passes/s of one appm render, wasm in Chromium against native on 1 thread."""
    wasm, nat = [], []
    for k in range(3):
        url = "%s/index.html?test=1&scene=%s&size=%d&passes=%d&seed=%d&methods=appm" % (
            base, SCENE, size, passes, SEED)
        sid = open_page(browser, url)
        r = wait_result(browser, sid, 300)
        st = r["sides"][0]["stats"]
        wasm.append(st["passes"] / st["seconds"])
        fields = native("appm", passes, threads=1, size=size)[1]
        nat.append(passes / float(fields["seconds"]))
        print("run %d: wasm %.2f passes/s, native 1 thread %.2f passes/s" % (k + 1, wasm[-1], nat[-1]))
    mw, mn = statistics.median(wasm), statistics.median(nat)
    print("%s %dx%d appm, %d passes, seed %d: median wasm %.2f passes/s, native %.2f passes/s, "
          "wasm/native %.2f" % (SCENE, size, size, passes, SEED, mw, mn, mw / mn))


def main():
    bench = sys.argv[1:2] == ["--bench"]
    os.makedirs(OUT, exist_ok=True)
    exe = browser_exe()
    if not check(exe is not None, "a Chromium is installed (CHROMIUM, chromium, google-chrome)"):
        print("%d passed, %d failed" % (passed, failed))
        return 1
    for f in ("appm.wasm", "scenes/%s.obj" % SCENE):
        if not check(os.path.exists(os.path.join(ROOT, "web", f)), "web/%s is built (make web)" % f):
            print("%d passed, %d failed" % (passed, failed))
            return 1
    httpd = serve(os.path.join(ROOT, "web"))
    base = "http://127.0.0.1:%d" % httpd.server_address[1]
    profile = tempfile.mkdtemp(prefix="appm-chromium-")
    browser = Browser(exe, profile)
    try:
        if bench:
            n = [int(a) for a in sys.argv[2:4]]
            run_bench(browser, base, *n)
        else:
            run_test(browser, base)
            run_scene_camera(browser, base)
            run_default_page(browser, base)
            errors = page_errors(browser.events)
            check(not errors, "no exception or console error in the pages and their workers%s"
                  % "".join("\n     | " + e for e in errors))
    except Exception as e:  # a protocol failure is a failed test, with its reason
        check(False, "the browser session: %s" % e)
    finally:
        browser.close()
        httpd.shutdown()
        shutil.rmtree(profile, ignore_errors=True)
    print("%d passed, %d failed" % (passed, failed))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
