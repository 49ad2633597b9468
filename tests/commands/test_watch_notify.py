"""`aisdati watch --notify URL` against a real HTTP server on 127.0.0.1: FRIO's drift alert is
posted as it opens and as it closes, one JSON object each with the event's fields; a 500 is
tried again; a dead endpoint is counted as failures while the watch ends normally with its
events in the database; a URL that is not http(s) is one line."""

from __future__ import annotations

import http.server
import json
import threading
from collections.abc import Iterator

import pytest

from tests.helpers.cli import one_line_error, run
from tests.helpers.live import FRIO, events, free_port


class Hook:
    """A webhook on 127.0.0.1 answering `statuses` in turn (then 200), keeping each request's
    path, content type and JSON body."""

    def __init__(self, statuses: list[int]) -> None:
        self.statuses, self.requests = list(statuses), []
        hook = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                body = self.rfile.read(int(self.headers["Content-Length"]))
                hook.requests.append((self.path, self.headers["Content-Type"], json.loads(body)))
                self.send_response(hook.statuses.pop(0) if hook.statuses else 200)
                self.send_header("Content-Length", "0")
                self.end_headers()

            def log_message(self, *args: object) -> None:
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/hooks/watch"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()


@pytest.fixture
def hook() -> Iterator[Hook]:
    one = Hook([])
    yield one
    one.server.shutdown()


def watched(tmp_path, url: str):
    got = run("watch", "--input", FRIO, "--notify", url, "--db", tmp_path / "w.sqlite")
    assert got.exit_code == 0, got.output
    return got


def test_the_drift_alert_is_posted_as_it_opens_and_closes(tmp_path, hook):
    got = watched(tmp_path, hook.url)
    posted = [body for path, kind, body in hook.requests]
    assert {(path, kind) for path, kind, _ in hook.requests} == {
        ("/hooks/watch", "application/json")
    }
    assert [(p["change"], p["state"], p["kind"], p["class"]) for p in posted] == [
        ("opened", "open", "drift", "alert"),
        ("closed", "closed", "drift", "alert"),
    ]
    for p in posted:
        assert (p["mmsi"], p["name"], p["start"]) == (
            538004030,
            "FRIO",
            "2014-09-28T16:37:54.051000+00:00",
        )
        assert p["evidence"].startswith("course 54 deg off heading")
        assert {"end", "lon", "lat", "strength", "rarity_days", "event_id"} <= set(p)
    assert posted[1]["end"] == "2014-09-28T16:57:24.744000+00:00"  # the drift's last report
    assert "stopped; 0 open event(s)" in got.stderr
    assert f"notify http://127.0.0.1:{hook.server.server_address[1]}: 2 sent (0 retried), " \
        "0 failed, 0 dropped" in got.stderr  # fmt: skip
    assert "/hooks/watch" not in got.stderr  # a webhook's path is its secret


def test_a_500_is_tried_again(tmp_path, hook):
    hook.statuses = [500]
    got = watched(tmp_path, hook.url)
    changes = [body["change"] for _, _, body in hook.requests]
    assert changes == ["opened", "opened", "closed"]  # the first try answered 500
    assert "2 sent (1 retried), 0 failed, 0 dropped" in got.stderr


def test_a_dead_endpoint_is_counted_never_fatal(tmp_path):
    got = watched(tmp_path, f"http://127.0.0.1:{free_port()}/")
    assert "0 sent (0 retried), 2 failed, 0 dropped" in got.stderr.splitlines()[-1]
    stored = events(tmp_path / "w.sqlite")
    assert list(stored["kind"]) == ["drift"] and list(stored["state"]) == ["closed"]


def test_a_url_not_http_is_one_line(tmp_path):
    db = tmp_path / "w.sqlite"
    for url in ("ftp://example.org/", "hooks.example.org", "http://", "http://h:port/"):
        one_line_error(run("watch", "--input", FRIO, "--notify", url, "--db", db), "--notify")
    assert not db.exists()
