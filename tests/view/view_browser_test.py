#!/usr/bin/env python3
"""vox-view in headless Chromium, driven over the DevTools protocol: load the
page, drag to orbit, pan, zoom and fly, change the light and the background,
wait for the refined frame and save the scene; the picture changed with each
move, the frame used the pyramid (vox-render --lod 0 differs), the saved
command line, run as written, gives the page's float frame bit for bit, the
files were written under fresh names beside an existing one; the exact frame
equals vox-render --lod 0; the coarse frames are a quarter of the resolution
or less, and the server's 8-bit ones are the page's painting of the float
frame; the voxel under the cursor is vox-probe's answer
for the same ray; a second identical frame reads no brick (the store stays
open and warm); and two clients, a closed connection mid-frame and a
malformed request leave the server running and the store untouched.
Usage: view_browser_test.py BUILD_DIR [--screenshot OUT.png]"""
import base64, hashlib, json, os, shutil, socket, subprocess, sys, tempfile, threading, time
import urllib.request

import websocket  # python3-websocket

build = os.path.abspath(sys.argv[1])
shot = sys.argv[sys.argv.index("--screenshot") + 1] if "--screenshot" in sys.argv else None
sys.path.insert(0, os.path.join(build, "python"))
import vox  # noqa: E402  (the module's read_exr)
import numpy as np  # noqa: E402

chromium = shutil.which("chromium")
if not chromium:
    sys.exit("view_browser_test: chromium is not installed (scripts/install-deps.sh installs it)")
tmp = tempfile.mkdtemp(prefix="vox-view-test-")
procs = []


def fail(msg):
    sys.exit("view_browser_test: FAILED: " + msg)


def tree_hash(d):
    h = hashlib.sha256()
    for root, _, files in sorted(os.walk(d)):
        for f in sorted(files):
            p = os.path.join(root, f)
            h.update(p.encode())
            h.update(open(p, "rb").read())
    return h.hexdigest()


def get(url, timeout=60):
    with urllib.request.urlopen(url, timeout=timeout) as r:
        return r.read()


try:
    store = os.path.join(tmp, "s")
    subprocess.run([f"{build}/tools/gen/vox-gen", "sphere", store, "--size", "1024", "--quiet",
                    "--threads", "2"], check=True)
    before_store = tree_hash(store)
    # --out inside the store is refused before the server starts.
    bad = subprocess.run([f"{build}/tools/view/vox-view", store, "--out", store],
                         capture_output=True, text=True)
    if bad.returncode != 1 or "inside the store" not in bad.stderr:
        fail(f"--out STORE: exit {bad.returncode}, {bad.stderr!r}")
    out_dir = os.path.join(tmp, "out")
    os.mkdir(out_dir)
    taken = os.path.join(out_dir, "view-001.cam.json")
    open(taken, "w").write("not vox-view's\n")
    view = subprocess.Popen([f"{build}/tools/view/vox-view", store, "--threads", "2",
                             "--out", out_dir], stdout=subprocess.PIPE, text=True)
    procs.append(view)
    url = view.stdout.readline().split()[-1]
    profile = os.path.join(tmp, "profile")
    chrome = subprocess.Popen([chromium, "--headless=new", "--no-sandbox", "--disable-gpu",
                               "--remote-debugging-port=0", f"--user-data-dir={profile}",
                               "--window-size=900,560", url],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    procs.append(chrome)
    port_file = os.path.join(profile, "DevToolsActivePort")
    for _ in range(300):
        if os.path.exists(port_file) and open(port_file).read().count("\n") >= 1:
            break
        time.sleep(0.1)
    devport = open(port_file).read().split()[0]
    targets = json.loads(get(f"http://127.0.0.1:{devport}/json/list"))
    page = next(t for t in targets if t["type"] == "page")
    ws = websocket.create_connection(page["webSocketDebuggerUrl"], timeout=60)
    ids = [0]

    def cdp(method, **params):
        ids[0] += 1
        ws.send(json.dumps({"id": ids[0], "method": method, "params": params}))
        while True:
            m = json.loads(ws.recv())
            if m.get("id") == ids[0]:
                if "error" in m:
                    fail(f"{method}: {m['error']}")
                return m["result"]

    def js(expr):
        r = cdp("Runtime.evaluate", expression=expr, awaitPromise=True, returnByValue=True)
        return r["result"].get("value")

    def wait_refined(min_frames):
        for _ in range(600):
            if js(f"cv.dataset.refined === '1' && Number(cv.dataset.frames) >= {min_frames}"):
                return int(js("Number(cv.dataset.frames)"))
            time.sleep(0.1)
        fail("no refined frame within 60 s")

    def picture():
        return js("cv.toDataURL()")

    def page_float():
        return np.frombuffer(base64.b64decode(js("""(() => {
            const b = new Uint8Array(window.voxLastFloat.buffer); let s = '';
            for (let i = 0; i < b.length; i += 8192) s += String.fromCharCode.apply(null, b.subarray(i, i + 8192));
            return btoa(s); })()""")), dtype=np.float32)

    def render(args, exr):
        subprocess.run([f"{build}/tools/render/vox-render", store, *args, "--float", "-o", exr,
                        "--quiet", "--threads", "2"], check=True)
        ch = vox.read_exr(exr)["channels"]
        return np.stack([np.asarray(ch[c], dtype=np.float32) for c in "RGBA"], axis=-1).reshape(-1)

    def key(k):
        cdp("Input.dispatchKeyEvent", type="keyDown", key=k, text=k)
        cdp("Input.dispatchKeyEvent", type="keyUp", key=k)

    def settle(n):  # the refined frame after the last move, and no later coarse one
        n = wait_refined(n + 1)
        time.sleep(0.5)
        return wait_refined(n)

    n = wait_refined(1)
    pic0 = picture()
    box = js("(() => { const r = cv.getBoundingClientRect(); return [r.x, r.y]; })()")
    x, y = box[0] + 200, box[1] + 200
    cdp("Input.dispatchMouseEvent", type="mousePressed", x=x, y=y, button="left", clickCount=1)
    for i in range(1, 11):
        cdp("Input.dispatchMouseEvent", type="mouseMoved", x=x + 8 * i, y=y + 3 * i, button="left")
    cdp("Input.dispatchMouseEvent", type="mouseReleased", x=x + 80, y=y + 30, button="left",
        clickCount=1)
    n = settle(n)
    if picture() == pic0:
        fail("the picture did not change with the drag")
    # Pan (shift+drag) moves the look-at point, the wheel and W move the camera closer.
    cam0 = js("JSON.parse(JSON.stringify(st.cam))")
    cdp("Input.dispatchMouseEvent", type="mousePressed", x=x, y=y, button="left", clickCount=1,
        modifiers=8)
    cdp("Input.dispatchMouseEvent", type="mouseMoved", x=x + 40, y=y, button="left", modifiers=8)
    cdp("Input.dispatchMouseEvent", type="mouseReleased", x=x + 40, y=y, button="left",
        clickCount=1, modifiers=8)
    n = settle(n)
    cam1 = js("JSON.parse(JSON.stringify(st.cam))")
    if cam1["look_at"] == cam0["look_at"]:
        fail("shift+drag did not pan")
    dist = lambda c: float(np.linalg.norm(np.subtract(c["position"], c["look_at"])))
    pic1 = picture()
    cdp("Input.dispatchMouseEvent", type="mouseWheel", x=x, y=y, deltaX=0, deltaY=-100)
    n = settle(n)
    cam2 = js("JSON.parse(JSON.stringify(st.cam))")
    if not dist(cam2) < dist(cam1) * 0.95 or picture() == pic1:
        fail(f"the wheel did not zoom in ({dist(cam1)} -> {dist(cam2)})")
    js("cv.focus()")
    key("w")
    n = settle(n)
    cam3 = js("JSON.parse(JSON.stringify(st.cam))")
    moved = np.subtract(cam3["position"], cam2["position"])
    if not np.allclose(np.subtract(cam3["look_at"], cam2["look_at"]), moved) or \
            not np.dot(moved, np.subtract(cam2["look_at"], cam2["position"])) > 0:
        fail("W did not fly forward")
    # The light and the background.
    pic3 = picture()
    js("$('lightaz').value = -120; $('lightaz').dispatchEvent(new Event('input'))")
    js("$('bgtop').value = '#804020'; $('bgtop').dispatchEvent(new Event('input'))")
    n = settle(n)
    if picture() == pic3:
        fail("the picture did not change with the light")
    last = js("st.last")
    panel = last["panel"]
    if not (panel["bricks_read"] >= 0 and panel["cache_capacity"] > 0 and panel["rss"] > 0):
        fail(f"the panel lacks figures: {panel}")
    stops = {int(k): v for k, v in panel["stops_by_level"].items()}
    if not any(l > 0 for l in stops):
        fail(f"the refined frame stopped at no coarse level: {stops}")
    page_rgba = page_float()
    if shot:
        js("probe(256, 192)")  # the panel's voxel
        data = cdp("Page.captureScreenshot", format="png")["data"]
        open(shot, "wb").write(base64.b64decode(data))
    # Save scene: the files under fresh names, the command run as written.
    saved = js("save(true)")
    if saved is None or not saved["written"]:
        fail("save wrote nothing: " + js("$('cmd').textContent"))
    if open(taken).read() != "not vox-view's\n":
        fail("save replaced an existing file")
    base = os.path.join(out_dir, "view-002")
    if sorted(saved["written"]) != sorted([base + ".cam.json", base + ".scene.json", base + ".sh"]):
        fail(f"save wrote {saved['written']}")
    if f"--lod {last['lod']}" not in saved["command"] or saved["lod"] != json.loads(last["lod"]):
        fail(f"the command line {saved['command']!r} lacks the frame's --lod {last['lod']}")
    dflt = json.loads(subprocess.run([f"{build}/tools/render/vox-render", store, "--cam",
                                      base + ".cam.json", "--size", "8x6", "--stats", "/dev/stdout",
                                      "-o", os.path.join(tmp, "d.exr"), "--quiet"],
                                     check=True, capture_output=True, text=True).stdout)
    if dflt["lod"]["factor"] != saved["lod"]:
        fail(f"the page's --lod {saved['lod']} is not vox-render's default {dflt['lod']}")
    exr = os.path.join(out_dir, "view-002.exr")
    cmd = saved["command"].replace("vox-render", f"{build}/tools/render/vox-render", 1)
    subprocess.run(cmd + " --quiet --threads 2", shell=True, check=True)
    ch = vox.read_exr(exr)["channels"]
    ref = np.stack([np.asarray(ch[c], dtype=np.float32) for c in "RGBA"], axis=-1).reshape(-1)
    if ref.shape != page_rgba.shape or ref.tobytes() != page_rgba.tobytes():
        fail(f"the saved command's EXR differs from the page's frame ({ref.shape} vs {page_rgba.shape})")
    exact_args = ["--cam", base + ".cam.json", "--scene", base + ".scene.json", "--lod", "0"]
    if render(exact_args, os.path.join(tmp, "e0.exr")).tobytes() == page_rgba.tobytes():
        fail("vox-render --lod 0 equals the level-of-detail frame: the --lod check proves nothing")
    # The exact frame equals vox-render --lod 0.
    js("$('exact').click()")
    n = wait_refined(n + 1)
    if js("st.last.lod") not in ("0", "0.0"):
        fail(f"the exact frame's lod is {js('st.last.lod')}")
    if render(exact_args, os.path.join(tmp, "e.exr")).tobytes() != page_float().tobytes():
        fail("the page's exact frame differs from vox-render --lod 0")
    # The voxel under the cursor: vox-probe's answer for the ray /probe traced.
    for px, py in ((256, 192), (3, 3)):
        pr = js(f"probe({px}, {py})")
        got = subprocess.run([f"{build}/tools/probe/vox-probe", store], input=pr["ray"] + "\n",
                             capture_output=True, text=True, check=True).stdout.strip()
        if got != pr["answer"]:
            fail(f"/probe at ({px}, {py}) says {pr['answer']!r}, vox-probe {got!r}")
        if (px == 256) != pr["answer"].startswith("hit"):
            fail(f"/probe at ({px}, {py}): {pr['answer']!r}")
    # The coarse frames: a quarter of the canvas's resolution or less, painted by the server
    # (fmt=rgba8) into the bytes the page paints from the same frame in floats.
    coarse = js("window.voxTimes.filter(t => t.scale !== 1)")
    if not coarse or any(t["w"] > js("cv.width") / 4 + 0.5 for t in coarse):
        fail(f"coarse frames not at a quarter of the resolution or less: {coarse}")
    same = js("""(async () => {
        const q = `frame?w=96&h=64&cam=${encodeURIComponent(JSON.stringify(st.cam))}` +
                  `&scene=${encodeURIComponent(JSON.stringify(st.scene))}&aa=0`;
        const f = new Float32Array(await (await fetch(q)).arrayBuffer());
        const r = new Uint8Array(await (await fetch(q + '&fmt=rgba8')).arrayBuffer());
        const p = paint(f, 96, 64);
        let diff = r.length === p.length ? 0 : -1, lit = 0;
        for (let i = 0; i < p.length && diff >= 0; i++) diff += r[i] !== p[i];
        for (let i = 0; i < f.length; i += 4) lit += f[i + 3] > 0;
        return [diff, lit, r.length];
    })()""")
    if same[0] != 0 or same[1] == 0:
        fail(f"the server's rgba8 frame differs from the page's painting (differing bytes, "
             f"lit pixels, bytes): {same}")
    # Warm: a second identical frame reads no brick.
    warm = url + "frame?az=200&el=-40&w=256&h=192&lod=0"
    misses = []
    for _ in range(2):
        get(warm)
        st = json.loads(get(url + "stats"))
        misses.append((st["cache"]["misses"], st["io"]["brick_bytes_read"]))
    if not (misses[0][0] > 0 and misses[1] == (0, 0)):
        fail(f"the second identical frame read bricks (misses, bytes): {misses}")
    # Two clients at once, a connection closed mid-frame, malformed requests.
    big = url + "frame?az=10&el=10&w=1024&h=1024&lod=0"
    errors = []

    def client(u):
        try:
            get(u)
        except Exception as e:  # a 409 when superseded is fine; the server must answer
            if "409" not in str(e):
                errors.append(str(e))
    ts = [threading.Thread(target=client, args=(url + f"frame?az={a}&el=5&w=64&h=64",))
          for a in (1, 2)]
    [t.start() for t in ts]
    host, port = url.split("//")[1].rstrip("/").split(":")
    s = socket.create_connection((host, int(port)))
    s.sendall(f"GET /{big.split('/', 3)[3]} HTTP/1.1\r\nHost: x\r\n\r\n".encode())
    s.close()
    s = socket.create_connection((host, int(port)))
    s.sendall(b"\x00\xffGARBAGE / HTTP/9\r\n\r\n")
    s.close()
    [t.join() for t in ts]
    if errors:
        fail("a client failed: " + "; ".join(errors))
    try:
        get(url + "frame?az=1&el=1000&w=-3&h=x")
        fail("a malformed frame request was answered 200")
    except urllib.error.HTTPError as e:
        if e.code != 400:
            fail(f"a malformed frame request: HTTP {e.code}, expected 400")
    try:
        get(url + "frame?az=1&el=10&w=8&h=8&fmt=png")
        fail("a frame request in an unknown format was answered 200")
    except urllib.error.HTTPError as e:
        if e.code != 400 or b"fmt png" not in e.read():
            fail(f"a frame request in an unknown format: HTTP {e.code}, expected 400")
    get(url + "stats")
    if view.poll() is not None:
        fail("vox-view exited")
    if tree_hash(store) != before_store:
        fail("the store changed")
    print("view_browser_test: passed")
finally:
    for p in procs:
        p.terminate()
        p.wait()
    shutil.rmtree(tmp, ignore_errors=True)
