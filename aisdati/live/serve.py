"""The live page: a small HTTP server in a thread (stdlib) serving one page on the package's
own Leaflet (no CDN, nothing fetched from outside) and a JSON state the page polls: the
vessels' last positions, the open and recent events, and the feed's summary."""

from __future__ import annotations

import http.server
import json
import threading
import time
from collections import deque
from importlib.resources import files
from typing import TYPE_CHECKING, Any

from aisdati.errors import UserError
from aisdati.events.kinds import KINDS

if TYPE_CHECKING:
    from aisdati.live.ledger import Change
    from aisdati.live.loop import Watch

REFRESH_S = 1.0
"""Wall seconds between two states built for the page (it polls every second)."""
RECENT_EVENTS = 200
"""Closed events the page shows, the latest first."""
MAX_VESSELS_SHOWN = 20_000
"""Vessels the page draws at most (the latest heard)."""
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
        "strength": f["strength"], "evidence": f["evidence"], "lon": f["lon"], "lat": f["lat"],
        "lons": list(f["lons"]), "lats": list(f["lats"]),
    }  # fmt: skip


class LiveState:
    """The page's JSON, rebuilt at most every `REFRESH_S` by the watch's thread and read by
    the server's."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.body = b'{"summary": {}, "vessels": [], "events": []}'
        self.built = 0.0
        self.closed: deque[dict[str, Any]] = deque(maxlen=RECENT_EVENTS)

    def record(self, changes: list[Change]) -> None:
        """The events that closed, kept for the page (the latest `RECENT_EVENTS`)."""
        for c in changes:
            if c.event.state == "closed":
                shown = [e for e in self.closed if e["id"] != c.event.event_id]
                self.closed = deque(shown, maxlen=RECENT_EVENTS)
                self.closed.append(event_json(c.event.event_id, "closed", c.event.fields))

    def refresh(self, w: Watch, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self.built < REFRESH_S:
            return
        self.built = now
        body = json.dumps(self.state(w), default=str).encode()
        with self.lock:
            self.body = body

    def state(self, w: Watch) -> dict[str, Any]:
        opened = [event_json(e.event_id, e.state, e.fields) for e in w.ledger.open_events()]
        recent = sorted(self.closed, key=lambda e: e["end"], reverse=True)
        last = sorted(w.last.values(), key=lambda r: r.time_s)[-MAX_VESSELS_SHOWN:]
        vessels = [
            [r.mmsi, round(r.lon, 6), round(r.lat, 6), w.vessels.recent[r.mmsi].identity.name,
             r.time_s]
            for r in last if r.mmsi in w.vessels.recent
        ]  # fmt: skip
        summary = {
            "messages_per_s": round(w.counters.rate(), 1), "lines": w.counters.lines,
            "reports": w.counters.reports, "vessels": len(w.vessels.recent),
            "forgotten": w.vessels.forgotten, "open_events": len(opened),
            "rejected": w.decoder.rejected, "clock": w.vessels.clock_us / 1e6,
        }  # fmt: skip
        return {"summary": summary, "vessels": vessels, "events": opened + recent}

    def json(self) -> bytes:
        with self.lock:
            return self.body


def handler(state: LiveState) -> type[http.server.BaseHTTPRequestHandler]:
    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            path = self.path.split("?")[0]
            if path == "/state.json":
                self.send(state.json(), "application/json")
            elif path in ASSETS:
                name, kind = ASSETS[path]
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
