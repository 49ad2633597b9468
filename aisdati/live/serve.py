"""The live page: a small HTTP server in a thread (stdlib) serving one page on the package's
own Leaflet (no CDN, nothing fetched from outside), the offline coastline of the box it shows
(`aisdati.live.coast`), and a JSON state the page polls: the vessels' last positions and
courses, the open and recent events, the feed's health, and the last reports of the vessels
the page asked about (`?vessel=MMSI`)."""

from __future__ import annotations

import http.server
import json
import math
import threading
import time
from collections import deque
from importlib.resources import files
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs, urlsplit

from aisdati.errors import UserError
from aisdati.events.kinds import KINDS
from aisdati.live.coast import land_json, snapped
from aisdati.live.decode import QUIET

if TYPE_CHECKING:
    from aisdati.live.ledger import Change
    from aisdati.live.loop import Watch

REFRESH_S = 1.0
"""Wall seconds between two states built for the page (it polls every second)."""
RECENT_EVENTS = 200
"""Closed events the page shows, the latest first."""
MAX_VESSELS_SHOWN = 20_000
"""Vessels the page draws at most (the latest heard)."""
LAST_REPORTS = 12
"""Reports of a vessel the page lists when it is clicked, the latest first."""
ASKED = 4
"""Vessels whose last reports the state carries: the latest the page asked about."""
ASSETS = {
    "/": ("live/page.html", "text/html; charset=utf-8"),
    "/page.js": ("live/page.js", "text/javascript"),
    "/leaflet/leaflet.js": ("data/leaflet/leaflet.js", "text/javascript"),
    "/leaflet/leaflet.css": ("data/leaflet/leaflet.css", "text/css"),
    **{
        f"/leaflet/images/{name}": (f"data/leaflet/{name}", "image/png")
        for name in ("layers.png", "layers-2x.png", "marker-icon.png", "marker-icon-2x.png",
                     "marker-shadow.png")
    },
}  # fmt: skip


def event_json(event_id: int, state: str, f: dict[str, Any]) -> dict[str, Any]:
    """An event as the page reads it."""
    return {
        "id": event_id, "state": state, "kind": f["kind"], "label": KINDS[f["kind"]].label,
        "class": KINDS[f["kind"]].cls,
        "mmsi": int(f["mmsi"]), "name": f["name"], "ship_type": f["ship_type"],
        "start": f["start"].isoformat(), "end": f["end"].isoformat(),
        "duration_s": (f["end"] - f["start"]).total_seconds(),
        "strength": f["strength"], "evidence": f["evidence"], "lon": f["lon"], "lat": f["lat"],
        "lons": [_coordinate(x) for x in f["lons"]], "lats": [_coordinate(y) for y in f["lats"]],
        "area": KINDS[f["kind"]].area, "others": json.loads(f.get("others") or "[]"),
    }  # fmt: skip


def _coordinate(value: float) -> float | None:
    """A stretch's coordinate for JSON: None where NaN parts a fleet event's vessels."""
    return None if math.isnan(value) else value


def number(value: float, digits: int) -> float | None:
    """A report's value for JSON: rounded, None where not given (NaN)."""
    return None if math.isnan(value) else round(float(value), digits)


def last_reports(columns: dict[str, Any], n: int) -> list[list[float | None]]:
    """A vessel window's last `n` reports, the latest first, each time once (the window keeps
    another receiver's copy until it is cleaned): time (s), lon, lat, speed (kn), course and
    heading (degrees)."""
    keys, out = ("lon", "lat", "sog", "cog", "heading"), []
    for i in range(len(columns["time_us"]) - 1, -1, -1):
        t = columns["time_us"][i] / 1e6
        if not out or out[-1][0] != t:
            out.append([t, *(number(columns[k][i], 6) for k in keys)])
        if len(out) == n:
            break
    return out


class LiveState:
    """The page's JSON, rebuilt at most every `REFRESH_S` by the watch's thread and read by
    the server's."""

    def __init__(self, shown: bool = True) -> None:
        self.shown = shown
        """Whether a page reads it (`--serve`): else building it is skipped (0.5 s at 10,000
        vessels)."""
        self.lock = threading.Lock()
        self.body = b'{"summary": {}, "vessels": [], "events": [], "reports": {}}'
        self.built = 0.0
        self.closed: deque[dict[str, Any]] = deque(maxlen=RECENT_EVENTS)
        self.asked: deque[int] = deque(maxlen=ASKED)

    def ask(self, mmsi: int) -> None:
        """The page wants this vessel's last reports (from the server's thread)."""
        with self.lock:
            if mmsi in self.asked:
                self.asked.remove(mmsi)
            self.asked.append(mmsi)

    def record(self, changes: list[Change]) -> None:
        """The events that closed, kept for the page (the latest `RECENT_EVENTS`); one
        withdrawn is no longer shown."""
        for c in changes:
            if c.event.state == "closed" or c.what == "withdrawn":
                shown = [e for e in self.closed if e["id"] != c.event.event_id]
                self.closed = deque(shown, maxlen=RECENT_EVENTS)
            if c.event.state == "closed" and c.what != "withdrawn":
                self.closed.append(event_json(c.event.event_id, "closed", c.event.fields))

    def refresh(self, w: Watch, force: bool = False) -> None:
        now = time.monotonic()
        if not self.shown or (not force and now - self.built < REFRESH_S):
            return
        self.built = now
        body = json.dumps(self.state(w), default=str).encode()
        with self.lock:
            self.body = body

    def state(self, w: Watch) -> dict[str, Any]:
        opened = [event_json(e.event_id, e.state, e.fields) for e in w.ledger.open_events()]
        recent = sorted(self.closed, key=lambda e: e["end"], reverse=True)
        last = sorted(w.last.values(), key=lambda r: r.time_s)[-MAX_VESSELS_SHOWN:]
        vessels = []
        for r in last:
            if (one := w.vessels.recent.get(r.mmsi)) is None:
                continue
            motion = last_reports(one.columns, 1)[0][3:] if len(one.columns["time_us"]) else []
            vessels.append([r.mmsi, round(r.lon, 6), round(r.lat, 6), one.identity.name,
                            r.time_s, one.identity.ship_type, *motion])  # fmt: skip
        with self.lock:
            asked = [m for m in self.asked if m in w.vessels.recent]
        details = {m: last_reports(w.vessels.recent[m].columns, LAST_REPORTS) for m in asked}
        clock = w.vessels.clock_us / 1e6
        summary = {
            "messages_per_s": round(w.counters.rate(), 1), "lines": w.counters.lines,
            "reports": w.counters.reports, "vessels": len(w.vessels.recent),
            "forgotten": w.vessels.forgotten, "open_events": len(opened),
            "rejected": w.decoder.rejected, "clock": clock,
            "lag_s": round(time.time() - clock, 1) if clock else None,
        }  # fmt: skip
        rejected = {k: n for k, n in w.decoder.skipped.most_common() if k not in QUIET}
        kinds = {name: {"label": k.label, "class": k.cls} for name, k in KINDS.items()}
        return {
            "summary": summary, "rejected": rejected, "vessels": vessels,
            "events": opened + recent, "reports": details, "kinds": kinds,
        }  # fmt: skip

    def json(self) -> bytes:
        with self.lock:
            return self.body


def handler(state: LiveState) -> type[http.server.BaseHTTPRequestHandler]:
    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            url = urlsplit(self.path)
            query = {k: v[-1] for k, v in parse_qs(url.query).items()}
            if url.path == "/state.json":
                if query.get("vessel", "").isdigit():
                    state.ask(int(query["vessel"]))
                self.send(state.json(), "application/json")
            elif url.path == "/land.json":
                box = snapped(query.get("bbox", ""))
                if box is None:
                    self.send_error(400, "bbox: west,south,east,north in degrees")
                else:
                    self.send(land_json(box), "application/json")
            elif url.path in ASSETS:
                name, kind = ASSETS[url.path]
                self.send(files("aisdati").joinpath(name).read_bytes(), kind)
            else:
                self.send_error(404)

        def send(self, body: bytes, kind: str) -> None:
            self.send_response(200)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: object) -> None:  # the watch's stderr is its own
            pass

    return Handler


def start_server(address: str, state: LiveState) -> http.server.ThreadingHTTPServer:
    """The page served at HOST:PORT from a daemon thread (stopped by `shutdown`)."""
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise UserError(f"--serve {address!r}: expected HOST:PORT, e.g. 127.0.0.1:8080")
    try:
        server = http.server.ThreadingHTTPServer((host, int(port)), handler(state))
    except OSError as exc:
        raise UserError(f"--serve {address}: {exc.strerror or exc}") from None
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server
