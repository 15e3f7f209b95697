"""``ftc report``: a recording of a typical world's pokes, judged against a cell's low limit, as one HTML page
that Debian's headless Chromium opens without a console error, one figure per contact, the summary's
exceedances the recording's; the recording's limits reproduce its events on replay."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from ftc_hw.app.monitor.run_report import ReportError, write_report
from ftc_hw.bus import EVENTS_CONTACT, Bus
from ftc_hw.model import ArmModel
from ftc_hw.monitor import LiveMonitor, PipelineInput
from ftc_hw.pipeline import PipelineSettings
from ftc_hw.record.reader import read_recording
from ftc_hw.record.replay import replay
from ftc_hw.record.writer import McapRecorder
from ftc_hw.scene import load_scene
from ftc_hw.scene.limits import load_limits
from ftc_hw.sim_devices.world import World, build_scenario, with_reality

pytestmark = pytest.mark.compute  # the world stepped as fast as it goes; the browser only loads a file

CHROMIUM, DRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")
UR5E = load_scene("ur5e")
CELL = """[limits]
default_region = "chest"

[regions.chest]
quasi_static_n = 30.0
"""


def record_pokes(path: Path, cell: Path, seconds: float = 2.5) -> None:
    """ur5e's monitor on a typical world's static pokes, its inputs and events written as ftc monitor records them."""
    limits = load_limits(cell)
    settings = PipelineSettings().with_level("dynamics")
    world = World(with_reality(UR5E, "typical", seed=5),
                  build_scenario("static-pokes", UR5E, ArmModel(UR5E), seed=5, duration=seconds), seed=5)
    bus = Bus()
    events = bus.subscribe(EVENTS_CONTACT, maxsize=None)
    monitor = LiveMonitor(bus, UR5E, settings=settings, limits=limits)
    rec = McapRecorder(bus, path, metadata={"scene": {"name": UR5E.name}, "monitor": {
        "pipeline": settings.to_json(), "limits": limits.to_json(), "tare_s": "0.1"}})
    rec.open()
    for seq, (state, reading) in enumerate(world.run(seconds)):
        t_ns = 1_000_000_000 + int(round(state.t * 1e9))
        inp = PipelineInput(t_ns, t_ns, seq, "ft", reading.wrench, state.q, state.qd, world.read_current(state),
                            bool(np.any(reading.saturated)), tare=not monitor.tared)
        rec.write(inp)
        monitor.consume(inp)
        for ev in events.drain():
            rec.write(ev)
    rec.finish()


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("report")
    (d / "cell.toml").write_text(CELL, encoding="utf-8")
    record_pokes(d / "run.mcap", d / "cell.toml")
    return d / "run.mcap"


def _browser():
    from selenium import webdriver  # the test extra's
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    if not (CHROMIUM.is_file() and DRIVER.is_file()):
        pytest.fail("no /usr/bin/chromium or /usr/bin/chromedriver: scripts/bootstrap.sh installs Debian's")
    opts = Options()
    opts.binary_location = str(CHROMIUM)
    for arg in ("--headless=new", "--no-sandbox", "--window-size=1200,900", "--force-device-scale-factor=1"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(str(DRIVER)), options=opts)


def test_the_recorded_limits_reproduce_the_events(recording):
    rec = read_recording(recording)
    result = replay(rec)
    assert result.identical and any(e.kind == "exceedance" for e in result.events)


def test_the_report_opens_offline_in_chromium_without_errors(recording, tmp_path):
    page = write_report(recording, tmp_path / "run.html")
    text = page.read_text(encoding="utf-8")
    assert not re.search(r"(src|href)=['\"]?(https?:)?//", text)  # nothing fetched from elsewhere
    events = [m.frame for m in read_recording(recording).messages if m.topic == EVENTS_CONTACT]
    contacts = {e.contact_id for e in events}
    exceeded = {e.contact_id for e in events if e.kind == "exceedance"}
    assert exceeded and f"{len(exceeded)} exceeded" in text
    browser = _browser()
    try:
        browser.get(page.as_uri())
        figures = browser.execute_script("return document.querySelectorAll('h2 + svg').length")
        rows = browser.execute_script("return document.querySelectorAll('tbody tr').length")
        yes = browser.execute_script("return [...document.querySelectorAll('tbody tr td:last-child')]"
                                     ".filter(td => td.textContent === 'yes').length")
        logs = [e for e in browser.get_log("browser") if e["level"] in ("SEVERE", "WARNING")]
    finally:
        browser.quit()
    assert figures == rows == len(contacts) and yes == len(exceeded)
    assert not logs, logs


def test_a_file_that_is_no_recording_is_a_report_error(tmp_path):
    bad = tmp_path / "run.mcap"
    bad.write_bytes(b"not an mcap")
    with pytest.raises(ReportError):
        write_report(bad)
