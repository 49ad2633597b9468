"""The live page in a real headless Chromium (skipped where there is none, as the detection
map's test is): served by a watch reading FRIO's recording from a real TCP feed, drawn on the
package's own Leaflet with every other host unresolvable, it shows the vessel, the drift with
its popup's fields, and the feed's summary, polled without a reload; a vessel's name is shown
as text, never run as HTML. A replay keeps its final page until Ctrl-C: the coastline, the
vessel chosen with its last reports and events, the drift's row, which the class filter hides;
its screenshot is docs/live_page.png (`AISDATI_DOCS_SCREENSHOTS=1` rewrites it)."""

from __future__ import annotations

import html
import http.server
import json
import os
import re
import shutil
import signal
import subprocess
import threading
import urllib.request
from collections.abc import Callable

import pytest
from pyais.encode import encode_dict

from tests.helpers.live import FRIO, ROOT, Feed, free_port, poll, stopped, watch

DOCS_SHOTS = "AISDATI_DOCS_SCREENSHOTS"
"""Set (to anything) to write the page's screenshot to docs/live_page.png, as the docs show it;
otherwise it goes to the test's own folder and the work tree is left as it was."""


def browser() -> str | None:
    return next(
        filter(None, map(shutil.which, ("chromium", "chromium-browser", "google-chrome"))), None
    )


pytestmark = pytest.mark.skipif(
    browser() is None,
    reason="no Chromium on this machine (make test installs Debian's chromium where it can)",
)


def chromium(profile, *args: str) -> str:
    """Chromium run on the page for a few (virtual) seconds, offline but for 127.0.0.1; what
    it printed."""
    cmd = [
        str(browser()), "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        f"--user-data-dir={profile}", "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
        "--virtual-time-budget=6000", *args,
    ]  # fmt: skip
    return subprocess.run(cmd, check=True, capture_output=True, text=True, timeout=120).stdout


def dom(url: str, profile) -> str:
    """The page's DOM after Chromium ran it."""
    return chromium(profile, "--dump-dom", url)


def dom_when(url: str, profile, ready: Callable[[str], bool], what: str) -> str:
    """The page's DOM once `ready` holds of it: a loaded machine may give Chromium's few
    virtual seconds less real time than the page's fetches need, so it is dumped again."""

    def page() -> str | None:
        text = dom(url, profile)
        return text if ready(text) else None

    return str(poll(page, 90, what))


def reports_rows(page: str) -> int:
    """The rows of the chosen vessel's reports table (its heading included)."""
    table = re.search(r'<table id="reports">(.*?)</table>', page)
    return table[1].count("<tr>") if table else 0


def row(page: str, kind: str) -> str:
    """The events list's row of the (only) event of this kind, as the DOM has it."""
    listed = page[page.index('<table id="events">') :]
    (found,) = re.findall(rf'<tr class="event [^"]*"[^>]*data-kind="{kind}"[^>]*>.*?</tr>', listed)
    return found


def state(url: str) -> dict:
    with urllib.request.urlopen(url + "state.json", timeout=5) as reply:
        return json.load(reply)


def test_the_live_page_shows_vessels_events_and_the_feed(tmp_path):
    feed, port = Feed(FRIO.read_bytes().splitlines()), free_port()
    url = f"http://127.0.0.1:{port}/"
    proc = watch("--input", f"tcp://127.0.0.1:{feed.port}", "--db", tmp_path / "w.sqlite",
                 "--serve", f"127.0.0.1:{port}", out=tmp_path / "watch")  # fmt: skip
    try:
        poll(lambda: "live page" in (tmp_path / "watch" / "stderr").read_text(), 60, "the page")
        poll(lambda: state(url)["summary"].get("reports", 0) >= 900, 60, "the feed read")
        page = dom(url, tmp_path / "profile")
        (drift,) = state(url)["events"]  # what the drift's popup shows
    finally:
        stopped(proc)
        feed.stop()
    assert "leaflet-container" in page  # the package's Leaflet ran
    assert 'data-vessels="1"' in page and 'data-open_events="0"' in page
    assert 'data-rejected="5332"' in page  # the tag blocks on lines of their own
    assert "<td>not_ais</td><td>5,332</td>" in page  # the rejected lines by reason
    drift_row = row(page, "drift")
    assert "closed" in drift_row and ">FRIO<" in drift_row and "09-28 16:37:54" in drift_row
    assert "data-polled" in page and "data-error" not in page
    assert (drift["name"], drift["label"], drift["start"]) == (
        "FRIO",
        "drift",
        "2014-09-28T16:37:54.051000+00:00",
    )
    assert drift["evidence"].startswith("course 54 deg off heading")


HOVER = b"""<script>
setInterval(() => {  // a user's pointer over every vessel: each tooltip open, what it holds noted
  vesselLayer.eachLayer(marker => marker.openTooltip());
  const tips = [...document.querySelectorAll('.leaflet-tooltip')];
  if (tips.length) document.body.dataset.tooltips = JSON.stringify(
    tips.map(t => [t.textContent, t.querySelectorAll('img').length]));
}, 300);
</script>"""


def hovered(page: str) -> http.server.ThreadingHTTPServer:
    """The watch's page at `page` as a user hovering its vessels sees it: served from another
    port (the page with `HOVER` in it; every other path, state.json too, the watch's own)."""

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            with urllib.request.urlopen(page + self.path.lstrip("/"), timeout=5) as reply:
                body, kind = reply.read(), reply.headers["Content-Type"]
            if self.path == "/":
                body = body.replace(b"</body>", HOVER + b"</body>")
            self.send_response(200)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: object) -> None:
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


NAME = "<IMG SRC=//X.IO/A>"
"""A vessel's name as a type 5 message can spell it (AIS's six-bit text has no lower case)."""


def named_vessel() -> list[bytes]:
    """A vessel calling itself `NAME` (type 5), and one report of it near FRIO, at FRIO's
    time (28 September 2014, 16:00 UTC)."""
    static = {"type": 5, "mmsi": 219000009, "shipname": NAME, "ship_type": 70, "to_bow": 50,
              "to_stern": 20}  # fmt: skip
    report = {"type": 1, "mmsi": 219000009, "lon": 10.6, "lat": 57.6, "speed": 8.0,
              "course": 90.0, "heading": 90, "status": 0}  # fmt: skip
    lines = encode_dict(static, talker_id="AI", seq_id=1)
    lines.append(f"\\c:1411920000*00\\{encode_dict(report, talker_id='AI')[0]}")
    return [line.encode() for line in lines]


def test_a_vessel_name_is_shown_as_text_never_run(tmp_path):
    """The name reached state.json raw and the vessel's tooltip was built as HTML from it:
    hovering made an <img> that loaded a foreign URL (an ONERROR= would run)."""
    feed, port = Feed(FRIO.read_bytes().splitlines() + named_vessel()), free_port()
    url = f"http://127.0.0.1:{port}/"
    proc = watch("--input", f"tcp://127.0.0.1:{feed.port}", "--db", tmp_path / "w.sqlite",
                 "--serve", f"127.0.0.1:{port}", out=tmp_path / "watch")  # fmt: skip
    try:
        poll(lambda: "live page" in (tmp_path / "watch" / "stderr").read_text(), 60, "the page")
        poll(lambda: any(v[3] == NAME for v in state(url)["vessels"]), 60, "the named vessel")
        proxy = hovered(url)
        try:
            page = dom(f"http://127.0.0.1:{proxy.server_address[1]}/", tmp_path / "profile")
        finally:
            proxy.shutdown()
    finally:
        stopped(proc)
        feed.stop()
    found = re.search(r'data-tooltips="([^"]*)"', page)
    assert found, page[-2000:]
    tips = dict(json.loads(html.unescape(found[1])))
    assert tips == {f"{NAME} 219000009 · Cargo": 0, "FRIO 538004030 · Tanker": 0}  # no <img>
    assert "data-error" not in page


def test_a_replay_keeps_its_final_page_until_ctrl_c(tmp_path):
    port = free_port()
    url = f"http://127.0.0.1:{port}/"
    proc = watch("--input", FRIO, "--db", tmp_path / "w.sqlite", "--serve", f"127.0.0.1:{port}",
                 out=tmp_path / "watch")  # fmt: skip
    err = tmp_path / "watch" / "stderr"
    try:
        poll(lambda: "keeps the final state" in err.read_text(), 60, "the replay's end")
        chosen = dom_when(
            f"{url}#vessel=538004030",
            tmp_path / "profile",
            lambda page: reports_rows(page) == 1 + 12,
            "the vessel's reports",
        )
        filtered = dom(f"{url}#class=activity", tmp_path / "profile")
        shot = (ROOT / "docs" if os.environ.get(DOCS_SHOTS) else tmp_path) / "live_page.png"
        chromium(tmp_path / "profile", "--window-size=1400,850", f"--screenshot={shot}",
                 f"{url}#vessel=538004030")  # fmt: skip
        assert proc.poll() is None  # still serving
    finally:
        code = stopped(proc, signal.SIGINT)
    assert code == 130 and "stopped; 0 open event(s)" in err.read_text()
    assert shot.stat().st_size > 10_000  # a picture of the page, not a blank
    assert "data-error" not in chosen and "data-error" not in filtered
    coast = re.search(r'data-coast="(\d+)"', chosen)
    assert coast and int(coast[1]) >= 1  # the coastline layer drawn around FRIO
    assert 'data-vessels="1"' in chosen and "FRIO · MMSI 538004030" in chosen
    assert "Tanker · last heard 2014-09-28 18:29:54 UTC" in chosen
    reports = re.search(r'<table id="reports">(.*?)</table>', chosen)[1]
    assert reports_rows(chosen) == 1 + 12  # the heading and the last 12 reports
    assert "<td>18:29:54</td><td>57.755N 11.387E</td>" in reports
    drift_row = row(chosen, "drift")
    assert "hidden" not in drift_row and "20 min" in drift_row and "57.817N 11.309E" in drift_row
    assert "hidden" in row(filtered, "drift")  # the filter (class activity) hides it
    assert shot.stat().st_size > 50_000
