"""``ftc monitor --sim --view web`` in a real headless Chromium (Debian's ``chromium`` and
``chromium-driver``, installed by scripts/bootstrap.sh) on dxl-arm's collision sweep: the page loads
without console errors, its 3-D canvas is not blank, the page's process sends each onset to the browsers
within 0.25 s of its sample, and the page shows the contact's link and a contact marker at one of the
contact's event points (read back from the page's three.js scene, within 1 mm) while the contact is drawn,
its time printed; a second viewer at the same time sees the contacts too; the page listens
on loopback only. ``ftc replay --view web`` over the run's recording: it plays when a viewer comes,
pauses, and a seek to the end shows the last contact where its events put it (a seek to the start, none).

Times: a watcher injected into the page notes (``Date.now()``, every 20 ms) when a contact marker is first
drawn where it is (its world matrix as the last render left it) and when the contact panel names it;
the event's time is its sample's host time from ``--events``, put on the wall clock by this process's
offset between the two clocks (one host).
"""
from __future__ import annotations

import io
import json
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.realtime

CHROMIUM, DRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")
# The page's own share: its process sends each onset to the browsers this soon after the onset's sample
# (measured 16-51 ms). The browsers render in software (SwiftShader) on the same 2 cores as the world, the
# monitor and each other: there a shown onset took 0.1-0.6 s, and up to 2.9-4.6 s where a browser compiled a
# shape's shaders at the first contact or the host was loaded (clean-clone runs). What a browser with a GPU
# on an idle host takes cannot be measured here: the test asks the page's share to be within 0.25 s and the
# browsers to show every onset while its contact is drawn, and prints how soon they did.
PAGE_SENT_WITHIN_S = 0.25
SHOWN_WITHIN_S = 5.0
POINT_TOL_M = 1e-3
CONTACTS = 3  # dxl-arm's sweep-with-collision: contacts at 1.74, 5.74 and 9.74 s of its 12
SCREENSHOT_AT_S = 11.0  # the page's time: the last contact's onset shown (it stays drawn to the run's end)
SETTLE_MS = 1000  # onsets judged from this long after the page has loaded (its first frames, shaders compiled)

# The browsers render in software on the host's own cores, beside the simulated world: while the arm
# moves a page renders as many frames as it can, 30-55 a second at 640x480, 1.0-1.2 cores a browser
# (measured on ftc replay --view web); capped at 20 frames a second without multisampling, 0.57 cores.
# Here capped at 10 (the page's time to show a contact grows by at most a frame, 0.1 s).
LIGHT_RENDERING = """
const raf = window.requestAnimationFrame.bind(window);
let lastFrame = -1e9;
window.requestAnimationFrame = (cb) => raf(function wait(t) {
  if (t - lastFrame < 98) return raf(wait);
  lastFrame = t;
  cb(t);
});
const getContext = HTMLCanvasElement.prototype.getContext;
HTMLCanvasElement.prototype.getContext = function (type, attrs) {
  if (String(type).startsWith("webgl")) attrs = Object.assign({}, attrs || {}, {antialias: false});
  return getContext.call(this, type, attrs);
};
"""

WATCHER = r"""
window.__ftcSeen = [];
window.__ftcGaps = [];
const seenPos = {}, seenText = {};
let last = performance.now();
setInterval(() => {
  const now = performance.now();
  const m = window.__viserMutable, points = window.__viserTestpoints;
  if (now - last > 100 && points) window.__ftcGaps.push([Date.now(), Math.round(now - last),
                                                         points.rendererInfo.render.frame]);
  last = now;
  if (!m || !points) return;
  const root = m.nodeRefFromName[""];
  if (!root) return;
  const arm = m.nodeRefFromName["/arm"];
  if (!window.__ftcReady && arm && arm.children.length && points.rendererInfo.render.frame > 0)
    window.__ftcReady = Date.now();  // the arm drawn: the page has loaded
  const inv = root.matrixWorld.clone().invert();
  for (const [name, o] of Object.entries(m.nodeRefFromName)) {
    if (!o || !/^\/contacts\/\d+\/sphere0$/.test(name)) continue;
    const e = inv.clone().multiply(o.matrixWorld).elements;
    const key = name + [e[12], e[13], e[14]].map(v => v.toFixed(5)).join(",");
    if (seenPos[key]) continue;
    seenPos[key] = 1;
    window.__ftcSeen.push({t: Date.now(), kind: "marker", name: name, pos: [e[12], e[13], e[14]]});
  }
  const text = document.body.textContent;  // the contact panel, or the events list (a contact that ended at once)
  for (const match of [...text.matchAll(/CONTACT #(\d+) on ([\w.-]+?)\s*point/g),
                       ...text.matchAll(/#(\d+) onset ([\w.-]+?) \d/g)]) {
    const key = match[1] + match[2];
    if (seenText[key]) continue;
    seenText[key] = 1;
    window.__ftcSeen.push({t: Date.now(), kind: "text", id: Number(match[1]), link: match[2]});
  }
}, 20);
"""


def _browser(size: str = "640,480"):
    from selenium import webdriver  # the test extra's
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    if not (CHROMIUM.is_file() and DRIVER.is_file()):
        pytest.fail("no /usr/bin/chromium or /usr/bin/chromedriver: scripts/bootstrap.sh installs Debian's")
    opts = Options()
    opts.binary_location = str(CHROMIUM)
    # software WebGL (SwiftShader through ANGLE), a small window at pixel ratio 1: the host's cores are few
    for arg in ("--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                f"--window-size={size}", "--force-device-scale-factor=1"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(str(DRIVER)), options=opts)
    driver.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument", {"source": LIGHT_RENDERING})
    return driver


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _listening(port: int) -> set[str]:
    """The local addresses listening on ``port`` (IPv4 and IPv6, from /proc/net)."""
    out = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            addr, p = local.split(":")
            if state == "0A" and int(p, 16) == port:
                out.add(addr)
    return out


def _url(proc: subprocess.Popen, lines: list[str], timeout: float = 120.0, pattern: str = "the live page: ") -> str:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        found = re.search(pattern + r"(http://\S+)", line)
        if found:
            return found.group(1)
    pytest.fail("the monitor printed no page URL:\n" + "".join(lines))


def _canvas_variance(driver, png: Path) -> float:
    from PIL import Image  # matplotlib's dependency

    driver.save_screenshot(str(png))
    canvas = driver.find_element("tag name", "canvas")
    img = Image.open(io.BytesIO(canvas.screenshot_as_png)).convert("L")
    return float(np.asarray(img, dtype=float).var())


def _seen(driver) -> list[dict]:
    return driver.execute_script("return window.__ftcSeen")


@pytest.fixture(scope="module")
def browsers():
    # started first (seconds each on a busy host); the second, another viewer, smaller
    drivers = [_browser(), _browser("400,300")]
    yield drivers
    for d in drivers:
        d.quit()


@pytest.fixture(scope="module")
def live(browsers, tmp_path_factory):
    """The monitor's run with both browsers on its page: what they saw, the events, the recording."""
    d = tmp_path_factory.mktemp("web")
    port = _free_port()
    proc = subprocess.Popen([sys.executable, "-m", "ftc_hw", "monitor", "--scene", "dxl-arm", "--sim", "--duration",
                             "12", "--view", "web", "--port", str(port), "--events", str(d / "events.jsonl"),
                             "--record", str(d / "run.mcap")],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1)
    lines: list[str] = []
    try:
        url = _url(proc, lines)
        listening = _listening(port)
        wall_minus_mono_ns = time.time_ns() - time.monotonic_ns()
        for b in browsers:
            b.get(url)
            b.execute_script(WATCHER)
        # the canvas once the last contact has been judged: a screenshot blocks the page's renderer for
        # 0.3-0.7 s (software rendering), and taken at the first contact seen it held up the one judged next
        # when the page loaded late (3.7-3.9 s against 1 s on a slow host)
        variance = None
        while proc.poll() is None and variance is None:
            time.sleep(0.5)
            if (_page_time(browsers[0]) or 0.0) >= SCREENSHOT_AT_S:
                variance = _canvas_variance(browsers[0], d / "page.png")
        lines.append(proc.communicate(timeout=240)[0])
        time.sleep(0.3)
        seen = [_seen(b) for b in browsers]
        ready_ms = browsers[0].execute_script("return window.__ftcReady")
        # the second viewer loads after the first (each get waits for its page): on a loaded host seconds later
        second_ready_ms = browsers[1].execute_script("return window.__ftcReady")
        print(f"the second viewer ready {second_ready_ms - ready_ms:.0f} ms after the first")
        gaps = browsers[0].execute_script("return window.__ftcGaps")
        print("main thread blocked > 100 ms:", [(round(t - ready_ms), g, f) for t, g, f in gaps])
        logs = [e for b in browsers for e in b.get_log("browser")]
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    text = "".join(lines)
    # the page is judged whatever the run's state; a run degraded (exit 3: frames not judged, a stream lost
    # for a moment) where the browsers' software rendering took the cores the world needs is reported
    assert proc.returncode in (0, 3), text
    print(next((x for x in text.splitlines() if "DEGRADED" in x), "clean run"))
    flat = " ".join(text.split())
    print(re.search(r"live page .*? after their sample|live page [^;]*", flat).group(0))  # the page's own share
    return {"dir": d, "url": url, "port": port, "listening": listening, "wall_minus_mono_ns": wall_minus_mono_ns,
            "variance": variance, "seen": seen, "ready_ms": ready_ms, "second_ready_ms": second_ready_ms, "logs": logs,
            "text": text,
            "events": [json.loads(x) for x in (d / "events.jsonl").read_text().splitlines()]}


def test_the_page_listens_on_loopback_and_loads_without_errors(live):
    assert live["url"] == f"http://127.0.0.1:{live['port']}/"
    assert live["listening"] == {"0100007F"}, "the page listens on loopback only"
    # the console until the run's last event: after it the run ends and the page with it (the pages then
    # fail to reconnect, as they should)
    page_up_ms = (live["events"][-1]["t_host_ns"] + live["wall_minus_mono_ns"]) / 1e6 + 500
    errors = [e for e in live["logs"] if e["level"] == "SEVERE" and e["timestamp"] < page_up_ms]
    assert not errors, errors
    assert live["variance"] is not None and live["variance"] > 20.0, f"a blank canvas ({live['variance']})"


def test_each_onset_is_sent_at_once_and_shown_in_both_viewers(live):
    events, seen = live["events"], live["seen"]
    onsets = [e for e in events if e["kind"] == "onset"]
    assert len(onsets) >= CONTACTS, live["text"]  # more: a contact split where a loaded host lost a stream
    results = []
    settled_ms = live["ready_ms"] + SETTLE_MS
    judged = [e for e in onsets if (e["t_host_ns"] + live["wall_minus_mono_ns"]) / 1e6 > settled_ms]
    print(f"{len(onsets) - len(judged)} of {len(onsets)} onsets came before the page had loaded and settled")
    assert judged, "no onset after the page had loaded: start the browsers sooner"
    for e in judged:
        of_contact = [x for x in events if x.get("contact_id") == e["contact_id"] and x["kind"] != "offset"
                      and "no_estimate" not in x["flags"]]
        if not of_contact:
            continue  # a contact with no point: nothing to place
        onset_wall_ms = (e["t_host_ns"] + live["wall_minus_mono_ns"]) / 1e6
        markers = [s for s in seen[0] if s["kind"] == "marker" and s["name"] == f"/contacts/{e['contact_id']}/sphere0"]
        shown = [(s, x) for s in markers for x in of_contact
                 if np.linalg.norm(np.subtract(s["pos"], x["point"])) < POINT_TOL_M]
        # the onset's link: in the contact panel, or in the events list when a newer estimate named another
        labels = [s for s in seen[0] if s["kind"] == "text" and s["id"] == e["contact_id"] and s["link"] == e["link"]]
        marker_s = (shown[0][0]["t"] - onset_wall_ms) / 1e3 if shown else None
        label_s = (labels[0]["t"] - onset_wall_ms) / 1e3 if labels else None
        print(f"contact {e['contact_id']}: marker {marker_s and round(marker_s * 1e3)} ms"
              + (f" (at its {shown[0][1]['kind']}'s point)" if shown else "")
              + f", link {label_s and round(label_s * 1e3)} ms after the onset's sample")
        # the second viewer: every onset after it had loaded and settled (None: before, not asked of it)
        second = (any(s["kind"] == "text" and s["id"] == e["contact_id"] for s in seen[1])
                  if onset_wall_ms > live["second_ready_ms"] + SETTLE_MS else None)
        results.append((e, marker_s, label_s, labels, second, markers))
    sent = re.search(r"onsets sent to the browsers ([0-9, ]+) ms after their sample", " ".join(live["text"].split()))
    assert sent, live["text"][-2000:]
    sent_ms = [float(x) for x in sent.group(1).split(",")]
    assert len(sent_ms) == len(onsets) and max(sent_ms) < PAGE_SENT_WITHIN_S * 1e3, sent_ms
    for e, marker_s, label_s, labels, second, markers in results:
        assert marker_s is not None, ("no marker at the contact's points", e, markers)
        assert labels, ("the onset's link never shown", e["link"])
        assert marker_s < SHOWN_WITHIN_S and label_s < SHOWN_WITHIN_S, (e, marker_s, label_s)
        assert second is not False, "the second viewer shows it too"
    assert any(r[4] for r in results), "no onset after the second viewer had loaded: start the browsers sooner"


def _page_time(driver) -> float | None:
    found = re.search(r"t (\d+\.\d) s", driver.execute_script("return document.body.textContent"))
    return float(found.group(1)) if found else None


def _contact_markers(driver) -> dict[str, list[float]]:
    """The contact points in the scene now (nodes still attached), base frame."""
    return driver.execute_script("""
      const m = window.__viserMutable, inv = m.nodeRefFromName[""].matrixWorld.clone().invert(), out = {};
      for (const [name, o] of Object.entries(m.nodeRefFromName))
        if (o && o.parent && /^\\/contacts\\/\\d+\\/sphere0$/.test(name)) {
          o.updateWorldMatrix(true, false);
          const e = inv.clone().multiply(o.matrixWorld).elements;
          out[name] = [e[12], e[13], e[14]];
        }
      return out;""")


def _wait(predicate, timeout: float = 10.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.2)
    return predicate()


def test_the_replay_page_plays_pauses_and_seeks(live, browsers):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    port = _free_port()
    proc = subprocess.Popen([sys.executable, "-m", "ftc_hw", "replay", str(live["dir"] / "run.mcap"), "--view", "web",
                             "--port", str(port)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            bufsize=1)
    lines: list[str] = []
    b = browsers[0]
    try:
        url = _url(proc, lines, pattern="the replay's page: ")
        b.get(url)
        assert _wait(lambda: (_page_time(b) or 0) > 0.5), "the replay plays when a viewer comes"
        button = _wait(lambda: [x for x in b.find_elements(By.TAG_NAME, "button") if x.text.strip() == "pause"])
        button[0].click()
        time.sleep(0.5)
        paused_at = _page_time(b)
        time.sleep(1.0)
        assert _page_time(b) == paused_at, "paused"
        slider = b.find_elements(By.CSS_SELECTOR, "[role=slider]")[0]  # time, then speed
        slider.send_keys(Keys.END)
        end_s = float(slider.get_attribute("aria-valuemax"))
        assert _wait(lambda: abs((_page_time(b) or 0) - end_s) < 0.15), (_page_time(b), end_s)
        last = max(e["contact_id"] for e in live["events"] if "contact_id" in e)
        points = [e["point"] for e in live["events"] if e.get("contact_id") == last]
        def placed():
            at = _contact_markers(b).get(f"/contacts/{last}/sphere0")
            return at is not None and min(np.linalg.norm(np.subtract(at, p)) for p in points) < POINT_TOL_M

        assert _wait(placed), (_contact_markers(b), points[-1])
        slider.send_keys(Keys.HOME)
        assert _wait(lambda: _page_time(b) == 0.0 and not _contact_markers(b)), _contact_markers(b)
        errors = [e for e in b.get_log("browser") if e["level"] == "SEVERE"]
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    assert not [e for e in errors if "ws://127.0.0.1:" + str(live["port"]) not in e["message"]], errors
