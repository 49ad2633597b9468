"""Alerts pushed to a webhook: each record POSTed as one JSON object to an HTTP(S) endpoint from
a thread of its own, behind a bounded queue, so that the watch never waits on the network; a
record is tried `TRIES` times (`TIMEOUT_S` each, backing off between), and what could not be
delivered is counted, never raised."""

from __future__ import annotations

import contextlib
import http.client
import json
import queue
import threading
import time
import urllib.request
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit

from aisdati.errors import UserError

TRIES = 3
"""Tries of one record before it counts as failed."""
TIMEOUT_S = 10.0
"""Seconds one try may take (connecting and the reply)."""
BACKOFF_S = 0.5
"""Seconds before the second try, doubled before each next one."""
QUEUE = 1_000
"""Records waiting at most; one more is dropped (counted), the watch never waits."""
DRAIN_S = 15.0
"""Seconds the watch's end waits for the records still queued (all endpoints together);
those left are dropped."""


@dataclass
class Counts:
    sent: int = 0
    retried: int = 0
    """Records delivered after a failed try."""
    failed: int = 0
    """Records given up on after `TRIES` tries."""
    dropped: int = 0
    """Records never tried: the queue full, or still queued when the watch ended."""


def endpoint(url: str) -> str:
    """`url` if it is an http(s) URL with a host; a one-line error otherwise."""
    parts = urlsplit(url)
    try:
        ok = parts.scheme in ("http", "https") and bool(parts.hostname) and parts.port != 0
    except ValueError:  # a port that is not a number
        ok = False
    if not ok:
        raise UserError(f"--notify {url!r}: expected an http:// or https:// URL with a host")
    return url


class Notifier:
    """One endpoint's queue, thread and counts; `post` never blocks."""

    def __init__(self, url: str) -> None:
        self.url = endpoint(url)
        parts = urlsplit(url)  # shown without its path or credentials (a webhook's secret)
        self.shown = f"{parts.scheme}://{parts.hostname}" + (f":{parts.port}" if parts.port else "")
        self.counts = Counts()
        self.accepted = 0
        """Records queued: each ends sent, failed, or (left at the end) dropped."""
        self.queue: queue.Queue[bytes | None] = queue.Queue(maxsize=QUEUE)
        self.thread = threading.Thread(target=self.deliver, daemon=True, name="notify")
        self.thread.start()

    def post(self, record: dict[str, Any]) -> None:
        try:
            self.queue.put_nowait(json.dumps(record, default=str).encode())
        except queue.Full:
            self.counts.dropped += 1
        else:
            self.accepted += 1

    def deliver(self) -> None:
        while (body := self.queue.get()) is not None:
            self.send(body)

    def send(self, body: bytes) -> None:
        for attempt in range(TRIES):
            if attempt:
                time.sleep(BACKOFF_S * 2 ** (attempt - 1))
            request = urllib.request.Request(
                self.url, data=body, method="POST",
                headers={"Content-Type": "application/json", "User-Agent": "aisdati-watch"},
            )  # fmt: skip
            try:
                with urllib.request.urlopen(request, timeout=TIMEOUT_S):
                    pass
            except (OSError, http.client.HTTPException):
                continue
            self.counts.sent += 1
            self.counts.retried += int(attempt > 0)
            return
        self.counts.failed += 1

    @property
    def pending(self) -> int:
        """Records queued or on their way."""
        return self.accepted - self.counts.sent - self.counts.failed

    def close(self, deadline: float) -> None:
        """The queued records delivered by `deadline` (`time.monotonic()`); those still queued
        or on their way then are counted as dropped (the thread dies with the process)."""
        with contextlib.suppress(queue.Full):
            self.queue.put(None, timeout=max(0.0, deadline - time.monotonic()))
        self.thread.join(max(0.0, deadline - time.monotonic()))
        self.counts.dropped += self.pending

    def summary(self) -> str:
        c = self.counts
        return (
            f"notify {self.shown}: {c.sent} sent ({c.retried} retried), {c.failed} failed, "
            f"{c.dropped} dropped"
        )
