"""`aisdati watch`: a live feed (or a replayed recording) judged as it arrives, its events kept
in a database, printed, and shown on a live page (`aisdati.live`)."""

from __future__ import annotations

import contextlib
import json
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import replace
from typing import Any

from aisdati.commands.common import err_console
from aisdati.commands.options import WatchOptions
from aisdati.detection.events import event_rules, uncalibrated_note
from aisdati.detectors import load_detectors
from aisdati.errors import UserError
from aisdati.events.anchorages import read_ports
from aisdati.events.budget import ALERTS_PER_1000
from aisdati.events.kinds import ALERT, KINDS
from aisdati.events.rules import EventRules
from aisdati.live.area import AreaJudge
from aisdati.live.ledger import Change
from aisdati.live.loop import Watch
from aisdati.live.notify import DRAIN_S, Notifier
from aisdati.live.serve import REFRESH_S, LiveState, start_server
from aisdati.live.sources import Pacer, open_source
from aisdati.live.store import open_store
from aisdati.live.vessels import Vessels
from aisdati.options import Range
from aisdati.preprocess.settings import parse_duration
from aisdati.storage import fetched_models, without_password

PROGRESS_S = 5.0
"""Wall seconds between two progress lines on stderr."""
PUSHED = ("opened", "closed", "withdrawn")
"""The changes of an alert that `--notify` posts (one withdrawn was posted when it opened)."""


def say(message: str) -> None:
    """One line on stderr (a reconnection, the progress, the end)."""
    err_console.print(f"watch: {message}", highlight=False, markup=False, soft_wrap=True)


def change_record(change: Change) -> dict[str, Any]:
    """An event change as one JSON object: what changed, the event's id, state and fields."""
    e = change.event
    record = {"change": change.what, "event_id": e.event_id, "state": e.state}
    if change.into is not None:
        record["into"] = change.into
    for key, value in e.fields.items():
        record[key] = value.isoformat() if hasattr(value, "isoformat") else value
    record["label"] = KINDS[e.fields["kind"]].label
    return record


def printer(as_json: bool) -> Callable[[list[Change]], None]:
    """Where the changes go: JSON lines on stdout, or one readable line each."""

    def emit(changes: list[Change]) -> None:
        for c in changes:
            if as_json:
                print(json.dumps(change_record(c), default=str), flush=True)
                continue
            f = c.event.fields
            who = f["name"] or f["mmsi"]
            into = "" if c.into is None else f" (folded into #{c.into})"
            print(f"{c.what:8} #{c.event.event_id} {f['kind']} {who} since "
                  f"{f['start']:%Y-%m-%d %H:%M:%S} at {f['lat']:.4f},{f['lon']:.4f}: "
                  f"{f['evidence']}{into}", flush=True)  # fmt: skip

    return emit


def check(o: WatchOptions) -> float:
    """The options' mistakes as one line each; the window in seconds."""
    if o.speed is not None and not Range(low=0.0, low_open=True).accepts(o.speed):
        raise UserError(f"--speed must be a finite number > 0, got {o.speed}")
    if o.max_vessels < 1:
        raise UserError(f"--max-vessels must be an integer >= 1, got {o.max_vessels}")
    if not Range(low=0.0, low_open=True).accepts(o.alerts_per_1000):
        raise UserError(f"--alerts-per-1000 must be a finite number > 0, got {o.alerts_per_1000}")
    if o.speed is not None and (o.source == "-" or "://" in o.source):
        raise UserError("--speed replays a file or folder; a live source comes at its own pace")
    return parse_duration(o.window, "--window")


def judging(
    models_dir: str | None, budget: float = ALERTS_PER_1000
) -> tuple[EventRules, AreaJudge | None]:
    """What the watch judges by: the event rules (the defaults, or the alert budget the models
    of `models_dir` calibrated on their training period and the water their traffic sailed
    ashore, as `detect` judges with them; a model from before the budget says so and keeps the
    defaults), and its area models (`--cluster all`), which judge each vessel's window; route and
    cluster models give only the rules."""
    if models_dir is None:
        return EventRules(), None
    with fetched_models(models_dir, [], "--models") as local:
        models = load_detectors(local, [])
    if note := uncalibrated_note(models):
        say(note)
    area = AreaJudge.of(models)
    judged = f"; {len(area.models)} area model(s) judge the vessels' windows" if area else ""
    say(f"event thresholds of {len(models)} model(s) in {models_dir}{judged}")
    return event_rules(models, budget), area


def summary(w: Watch, notifiers: list[Notifier]) -> str:
    return "; ".join([
        f"{w.counters.lines:,} lines ({w.counters.rate():,.0f}/s), {w.counters.reports:,} "
        f"reports, {len(w.vessels.recent):,} vessels ({w.vessels.forgotten:,} forgotten), "
        f"{len(w.ledger.open_events())} open events, {w.decoder.rejected:,} rejected",
        *(n.summary() for n in notifiers),
    ])  # fmt: skip


def pusher(notifiers: list[Notifier]) -> Callable[[list[Change]], None]:
    """Where an alert's opening and closing go: each endpoint's queue (never waiting)."""

    def push(changes: list[Change]) -> None:
        for c in changes:
            if c.what in PUSHED and c.event.fields["class"] == ALERT:
                record = change_record(c)
                for n in notifiers:
                    n.post(record)

    return push


def run(o: WatchOptions) -> None:
    window_s = check(o)
    notifiers = [Notifier(url) for url in o.notify or []]
    rules, area = judging(o.models_dir, o.alerts_per_1000)
    if o.ports is not None:
        rules = replace(rules, ports=read_ports(o.ports))
    chunks = open_source(o.source, say, paced=o.speed is not None)
    state, show, db = LiveState(bool(o.serve)), printer(o.as_json), without_password(o.db)
    push = pusher(notifiers)

    def emit(changes: list[Change]) -> None:
        show(changes)
        state.record(changes)
        push(changes)

    with contextlib.ExitStack() as held:
        if o.serve:  # before the database: a port in use leaves no database file behind
            held.callback(start_server(o.serve, state).shutdown)
        store = open_store(o.db)
        held.callback(store.close)
        watch = Watch(
            store, Vessels(window_s=window_s, max_vessels=o.max_vessels), rules=rules,
            pacer=None if o.speed is None else Pacer(o.speed), emit=emit, area=area,
        )  # fmt: skip
        try:
            if resumed := watch.resume():
                say(f"resumed {resumed} open event(s) from {db}")
            if o.serve:
                say(f"live page at http://{o.serve}/")
            follow(watch, chunks, state, notifiers)
            if o.serve:
                say(f"the live page at http://{o.serve}/ keeps the final state; Ctrl-C stops")
                keep_serving(watch, state)
        finally:
            left = watch.stop()
            delivered(notifiers)
            say("; ".join([f"stopped; {left} open event(s) kept open in {db}",
                           *(n.summary() for n in notifiers)]))  # fmt: skip
    sys.stdout.flush()


def delivered(notifiers: list[Notifier]) -> None:
    """The alerts still queued given their bounded time to go out (said when there are some)."""
    if waiting := sum(n.pending for n in notifiers):
        say(f"waiting up to {DRAIN_S:.0f} s for {waiting} alert(s) to be posted")
    deadline = time.monotonic() + DRAIN_S
    for n in notifiers:
        n.close(deadline)


def keep_serving(watch: Watch, state: LiveState) -> None:
    """The feed ended (a replay, stdin closed): the page keeps its final state until Ctrl-C,
    still answering what it asks (a vessel's last reports)."""
    while True:
        time.sleep(REFRESH_S)
        state.refresh(watch, force=True)


def follow(
    watch: Watch, chunks: Iterator[list[bytes]], state: LiveState, notifiers: list[Notifier]
) -> None:
    """The feed through the watch, to its end, a progress line every `PROGRESS_S`."""
    shown = time.monotonic()
    for lines in chunks:
        watch.step(lines)
        state.refresh(watch)
        if time.monotonic() - shown >= PROGRESS_S:
            say(summary(watch, notifiers))
            shown = time.monotonic()
    watch.end()
    state.refresh(watch, force=True)
    say(f"feed ended: {summary(watch, notifiers)}")
