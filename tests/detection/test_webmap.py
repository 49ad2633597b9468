"""The detection page works offline: rendered by a real headless Chromium whose every request
goes to a recording proxy on 127.0.0.1 (and whose host names resolve nowhere), the page draws
the coastline and the tracks, and asks the network for nothing."""

from __future__ import annotations

import http.server
import shutil
import subprocess
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from aisdati.detection.webmap import (
    COAST_COLOR,
    LAND_COLOR,
    LAYER_COAST,
    LAYER_FLAGGED,
    LAYER_TRACKS,
    WATER_COLOR,
    html_detection_map,
)

DATA = Path(__file__).parents[1] / "data" / "AIS_2018_07-08_Kitimat.csv.gz"
FLAG_RED = "#d62728"
BROWSER_SERVICES = ("google.com", "googleapis.com", "gvt1.com")
"""Chromium's own update, time and account services, which it calls whatever the page is (the
proxy refuses them too, so nothing leaves the machine); every other request is the page's."""


def browser() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if path := shutil.which(name):
            return path
    return None


pytestmark = pytest.mark.skipif(
    browser() is None,
    reason="no Chromium on this machine (make test installs Debian's chromium where it can)",
)


class _Recorder(http.server.BaseHTTPRequestHandler):
    """A proxy that forwards nothing: it records each request and answers 403."""

    seen: list[str]

    def _refuse(self) -> None:
        host = self.path.split("//")[-1].split("/")[0].split(":")[0]
        if not host.endswith(BROWSER_SERVICES):
            self.seen.append(f"{self.command} {self.path}")
        self.send_response(403)
        self.send_header("Content-Length", "0")
        self.end_headers()

    do_GET = do_POST = do_HEAD = do_CONNECT = do_OPTIONS = _refuse

    def log_message(self, *args: object) -> None:  # quiet
        pass


@pytest.fixture
def proxy() -> Iterator[tuple[str, list[str]]]:
    seen: list[str] = []
    handler = type("Recorder", (_Recorder,), {"seen": seen})
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}", seen
    finally:
        server.shutdown()
        server.server_close()


def screenshot(page: Path, out: Path, proxy_url: str) -> None:
    cmd = [
        str(browser()),
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--disable-default-apps",
        "--disable-domain-reliability",
        "--disable-client-side-phishing-detection",
        "--disable-breakpad",
        "--no-default-browser-check",
        "--no-pings",
        "--disable-features=Translate,OptimizationHints,MediaRouter,AutofillServerCommunication,"
        "CertificateTransparencyComponentUpdater,SignInProfileCreation,AccountConsistency,"
        "ChromeWhatsNewUI,InterestFeedContentSuggestions",
        f"--user-data-dir={out.parent / 'profile'}",
        f"--proxy-server={proxy_url}",
        "--proxy-bypass-list=<-loopback>",
        "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
        "--window-size=1200,900",
        "--virtual-time-budget=5000",
        f"--screenshot={out}",
        page.resolve().as_uri(),
    ]
    subprocess.run(cmd, check=True, capture_output=True, timeout=120)
    assert out.is_file(), "Chromium wrote no screenshot"


def _rgb(hex_colour: str) -> np.ndarray:
    return np.array([int(hex_colour[i : i + 2], 16) for i in (1, 3, 5)])


def share(image: np.ndarray, hex_colour: str, tol: int = 6) -> float:
    """Share of the pixels within `tol` of a colour."""
    return float(np.mean(np.all(np.abs(image - _rgb(hex_colour)) <= tol, axis=-1)))


def kitimat_tracks(n: int = 10) -> list[np.ndarray]:
    df = pd.read_csv(DATA, usecols=["MMSI", "BaseDateTime", "LAT", "LON"])
    df = df.sort_values(["MMSI", "BaseDateTime"])
    busiest = df["MMSI"].value_counts().index[:n]
    return [df.loc[df["MMSI"] == m, ["LON", "LAT"]].to_numpy()[:400] for m in busiest]


def test_the_page_renders_offline_with_coast_and_tracks(tmp_path, proxy):
    proxy_url, seen = proxy
    tracks = kitimat_tracks()
    props = [
        {"track_id": i, "mmsi": 100 + i, "score": 100.0 * i, "threshold": 150.0}
        for i in range(len(tracks))
    ]
    flagged = np.arange(len(tracks)) >= len(tracks) - 2
    page = tmp_path / "map.html"
    html_detection_map(tracks, [None] * len(tracks), props, flagged, [], page, title="offline")
    text = page.read_text()
    for name in (LAYER_COAST, LAYER_TRACKS, LAYER_FLAGGED):
        assert name in text
    assert "<script src" not in text and "<link" not in text  # nothing loaded from elsewhere

    shot = tmp_path / "map.png"
    screenshot(page, shot, proxy_url)
    from PIL import Image

    image = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert seen == [], f"the page asked the network for {seen}"
    assert share(image, LAND_COLOR) > 0.05, "no land drawn"
    assert share(image, WATER_COLOR) > 0.05, "no water drawn"
    assert share(image, COAST_COLOR, tol=20) > 0.0005, "no coastline drawn"
    assert share(image, FLAG_RED, tol=30) > 0.0005, "no flagged track drawn"


def test_the_recorder_sees_a_page_that_asks_the_network(tmp_path, proxy):
    """The harness itself: a page with one remote image is caught, so an empty record above
    means the map asked for nothing."""
    proxy_url, seen = proxy
    page = tmp_path / "remote.html"
    page.write_text('<html><body><img src="http://tiles.example.org/0/0/0.png"></body></html>')
    screenshot(page, tmp_path / "remote.png", proxy_url)
    assert any("tiles.example.org" in s for s in seen)


def test_detects_own_page_works_offline(kitimat, cli, tmp_path, proxy):
    """The map.html of a real `aisdati detect` run (a nearest model of Kitimat's route-1, the
    held-out tracks judged): rendered offline, it asks for nothing and draws coast and flags."""
    proxy_url, seen = proxy
    models, out = tmp_path / "models", tmp_path / "report"
    r = cli(
        "train", "--method", "nearest", "--cluster", "route-1", "--data", kitimat,
        "--out", models, "--max-tracks", 25,
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    r = cli(
        "detect", "--method", "nearest", "--cluster", "route-1", "--data", kitimat,
        "--models", models, "--top-percent", 30, "--out", out,
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    page = out / "map.html"
    assert '"judged by": "route-1-nearest"' in page.read_text()  # each track's popup says so
    shot = tmp_path / "map.png"
    screenshot(page, shot, proxy_url)
    from PIL import Image

    image = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert seen == [], f"the page asked the network for {seen}"
    assert share(image, LAND_COLOR) > 0.05 and share(image, WATER_COLOR) > 0.02
    assert share(image, FLAG_RED, tol=30) > 0.0005
