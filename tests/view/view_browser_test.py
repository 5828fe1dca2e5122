#!/usr/bin/env python3
"""vox-view in headless Chromium, driven over the DevTools protocol: load the
page, drag to orbit, wait for the refined frame, save the camera; the picture
changed, vox-render with the saved camera and --lod gives the page's float
frame bit for bit, and two clients, a closed connection mid-frame and a
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
    subprocess.run([f"{build}/tools/gen/vox-gen", "sphere", store, "--size", "128", "--quiet"],
                   check=True)
    before_store = tree_hash(store)
    view = subprocess.Popen([f"{build}/tools/view/vox-view", store, "--threads", "2"],
                            stdout=subprocess.PIPE, text=True)
    procs.append(view)
    url = view.stdout.readline().split()[-1]
    profile = os.path.join(tmp, "profile")
    chrome = subprocess.Popen([chromium, "--headless=new", "--no-sandbox", "--disable-gpu",
                               "--remote-debugging-port=0", f"--user-data-dir={profile}",
                               "--window-size=900,500", url],
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

    n = wait_refined(1)
    pic0 = js("cv.toDataURL()")
    box = js("(() => { const r = cv.getBoundingClientRect(); return [r.x, r.y]; })()")
    x, y = box[0] + 200, box[1] + 200
    cdp("Input.dispatchMouseEvent", type="mousePressed", x=x, y=y, button="left", clickCount=1)
    for i in range(1, 11):
        cdp("Input.dispatchMouseEvent", type="mouseMoved", x=x + 8 * i, y=y + 3 * i, button="left")
    cdp("Input.dispatchMouseEvent", type="mouseReleased", x=x + 80, y=y + 30, button="left",
        clickCount=1)
    wait_refined(n + 1)
    time.sleep(0.5)  # a late coarse frame would be followed by its refinement
    wait_refined(n + 1)
    if js("cv.toDataURL()") == pic0:
        fail("the picture did not change with the drag")
    last = js("st.last")
    js("document.getElementById('savecam').click()")
    cmd = js("document.getElementById('cmd').textContent")
    if f"--lod {last['lod']}" not in cmd:
        fail(f"the command line {cmd!r} lacks the frame's --lod {last['lod']}")
    page_rgba = np.frombuffer(base64.b64decode(js("""(() => {
        const b = new Uint8Array(window.voxLastFloat.buffer); let s = '';
        for (let i = 0; i < b.length; i += 8192) s += String.fromCharCode.apply(null, b.subarray(i, i + 8192));
        return btoa(s); })()""")), dtype=np.float32)
    if shot:
        data = cdp("Page.captureScreenshot", format="png")["data"]
        open(shot, "wb").write(base64.b64decode(data))
    cam = os.path.join(tmp, "cam.json")
    open(cam, "wb").write(get(url + "camera"))
    exr = os.path.join(tmp, "view.exr")
    subprocess.run([f"{build}/tools/render/vox-render", store, "--cam", cam, "--lod",
                    str(last["lod"]), "--float", "-o", exr, "--quiet", "--threads", "2"],
                   check=True)
    ch = vox.read_exr(exr)["channels"]
    ref = np.stack([np.asarray(ch[c], dtype=np.float32) for c in "RGBA"], axis=-1).reshape(-1)
    if ref.shape != page_rgba.shape or ref.tobytes() != page_rgba.tobytes():
        fail(f"vox-render --cam differs from the page's frame ({ref.shape} vs {page_rgba.shape})")
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
