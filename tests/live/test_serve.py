"""The live page in a real headless Chromium (skipped where there is none, as the detection
map's test is): served by a watch reading FRIO's recording from a real TCP feed, drawn on the
package's own Leaflet with every other host unresolvable, it shows the vessel, the drift with
its popup's fields, and the feed's summary, polled without a reload."""

from __future__ import annotations

import json
import shutil
import subprocess
import urllib.request

import pytest

from tests.helpers.live import FRIO, Feed, free_port, poll, stopped, watch


def browser() -> str | None:
    return next(
        filter(None, map(shutil.which, ("chromium", "chromium-browser", "google-chrome"))), None
    )


pytestmark = pytest.mark.skipif(
    browser() is None,
    reason="no Chromium on this machine (make test installs Debian's chromium where it can)",
)


def dom(url: str, profile) -> str:
    """The page's DOM after Chromium ran it for a few (virtual) seconds, offline but for
    127.0.0.1."""
    cmd = [
        str(browser()), "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        f"--user-data-dir={profile}", "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
        "--virtual-time-budget=4000", "--dump-dom", url,
    ]  # fmt: skip
    return subprocess.run(cmd, check=True, capture_output=True, text=True, timeout=120).stdout


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
    assert "closed drift: FRIO since 2014-09-28 16:37:54" in page
    assert "data-polled" in page and "data-error" not in page
    assert (drift["name"], drift["label"], drift["start"]) == (
        "FRIO",
        "drift",
        "2014-09-28T16:37:54.051000+00:00",
    )
    assert drift["evidence"].startswith("course 54 deg off heading")
