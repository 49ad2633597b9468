"""The watch's database: one table of events (every version of an event overwrites the last:
one row per event, open or closed), one of vessels (last known position and identity, and the
recent window kept when the watch stops, to resume from). SQLite by default (a file), or
PostgreSQL (`postgresql://...`, through psycopg), with a PostGIS geometry column where the
extension is installed. docs/usage/watch.md prints the schema.

Event ids come from the database (SQLite: an AUTOINCREMENT table; PostgreSQL: a sequence), never
from what one watch has seen: two watches on one database, or a watch restarted after its
recent events were dropped from memory, never number two events alike. A database that cannot
be opened, or that another writer keeps locked longer than `LOCK_WAIT_S`, is one line
(`UserError`), naming it without its password."""

from __future__ import annotations

import contextlib
import json
import sqlite3
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import shapely

from aisdati.errors import UserError
from aisdati.events.kinds import KINDS
from aisdati.events.table import shape
from aisdati.live.decode import Identity
from aisdati.live.ledger import Change, LiveEvent
from aisdati.live.vessels import FIELDS
from aisdati.storage import first_line, without_password

EVENT_FIELDS = (
    "event_id", "mmsi", "name", "ship_type", "kind", "class", "start_time", "end_time",
    "duration_s", "n_reports", "lon", "lat", "strength", "rarity_days", "evidence", "model",
    "others", "coverage", "state", "stopped_at", "updated_at", "stretch",
)  # fmt: skip
"""events.parquet's fields (`aisdati.events.record`) as the live database keeps them, with the
event's state; `stretch` its positions as JSON."""
VESSEL_FIELDS = (
    "mmsi", "name", "ship_type", "length_m", "time", "lon", "lat", "sog", "cog", "heading",
    "status", "recent",
)  # fmt: skip
START_WAIT_S = 5.0
"""How long opening the database waits for another writer's lock before it says so."""
LOCK_WAIT_S = 60.0
"""How long a write waits for another writer's lock (SQLite) before the watch stops."""
RESUME_S = 86400.0
"""Closed events this recent (by their end, before the newest) are read back on a restart, so
that a replay of the same stretch finds them again rather than twice."""


@dataclass(frozen=True)
class Dialect:
    """What differs between SQLite and PostgreSQL here: the placeholder and the column types."""

    mark: str
    time: str
    real: str
    geometry: bool = False


SQLITE = Dialect("?", "TEXT", "REAL")
POSTGRES = Dialect("%s", "TIMESTAMPTZ", "DOUBLE PRECISION")


def schema(d: Dialect) -> list[str]:
    """The CREATE TABLE statements (idempotent)."""
    return [
        f"""CREATE TABLE IF NOT EXISTS events (
            event_id BIGINT PRIMARY KEY, mmsi BIGINT NOT NULL, name TEXT, ship_type TEXT,
            kind TEXT NOT NULL, class TEXT, start_time {d.time} NOT NULL,
            end_time {d.time} NOT NULL, duration_s {d.real}, n_reports BIGINT, lon {d.real},
            lat {d.real}, strength {d.real}, rarity_days {d.real}, evidence TEXT, model TEXT,
            others TEXT, coverage TEXT, state TEXT NOT NULL CHECK (state IN ('open', 'closed')),
            stopped_at {d.time}, updated_at {d.time} NOT NULL, stretch TEXT)""",
        "CREATE INDEX IF NOT EXISTS events_state ON events (state, end_time)",
        f"""CREATE TABLE IF NOT EXISTS vessels (
            mmsi BIGINT PRIMARY KEY, name TEXT, ship_type TEXT, length_m {d.real},
            time {d.time}, lon {d.real}, lat {d.real}, sog {d.real}, cog {d.real},
            heading {d.real}, status BIGINT, recent TEXT)""",
        "CREATE TABLE IF NOT EXISTS event_ids (id INTEGER PRIMARY KEY AUTOINCREMENT)"
        if d is SQLITE
        else "CREATE SEQUENCE IF NOT EXISTS event_ids",
    ]


ADDED = {"class": "TEXT", "rarity_days": "{real}", "others": "TEXT", "coverage": "TEXT"}
"""Columns a database written before them lacks: added when it is opened."""


def added(conn: Any, d: Dialect) -> list[str]:
    """The ALTER TABLE statements that give an older events table the columns it lacks."""
    have = {c[0] for c in conn.execute("SELECT * FROM events LIMIT 0").description}
    return [
        f"ALTER TABLE events ADD COLUMN {name} {kind.format(real=d.real)}"
        for name, kind in ADDED.items()
        if name not in have
    ]


def id_floor(d: Dialect) -> str:
    """The statement that moves the id allocator past every event the table holds (a database
    written before ids came from the allocator); it never moves it back."""
    if d is SQLITE:
        return (
            "INSERT OR IGNORE INTO event_ids (id) "
            "SELECT event_id FROM events ORDER BY event_id DESC LIMIT 1"
        )
    return (
        "SELECT setval('event_ids', e.top) FROM event_ids s, "
        "(SELECT max(event_id) AS top FROM events) e "
        "WHERE e.top >= s.last_value + s.is_called::int"
    )


def upsert(d: Dialect, table: str, columns: Sequence[str], key: str) -> str:
    marks = ", ".join([d.mark] * len(columns))
    sets = ", ".join(f"{c} = excluded.{c}" for c in columns if c != key)
    return (
        f"INSERT INTO {table} ({', '.join(columns)}) VALUES ({marks}) "
        f"ON CONFLICT ({key}) DO UPDATE SET {sets}"
    )


def _number(x: Any) -> Any:
    """A value a driver takes: None for NaN, plain Python numbers."""
    if x is None or (isinstance(x, float) and np.isnan(x)):
        return None
    return x.item() if isinstance(x, np.generic) else x


class Store:
    """A connection and its dialect; every write is one transaction. `name`: the database as
    messages show it; `failures`: the driver's errors of the database rather than of this code
    (locked, unreachable, full), each turned into one line."""

    def __init__(
        self, conn: Any, dialect: Dialect, name: str, failures: tuple[type[Exception], ...]
    ) -> None:
        self.conn, self.d, self.name, self.failures = conn, dialect, name, failures
        with self.transaction():
            for statement in schema(dialect):
                self.conn.execute(statement)
            for statement in [*added(self.conn, dialect), id_floor(dialect)]:
                self.conn.execute(statement)

    @contextlib.contextmanager
    def transaction(self) -> Iterator[None]:
        """A block committed whole (SQLite's connection as a context; psycopg's transaction);
        a failure of the database is one line."""
        try:
            with self.conn if self.d is SQLITE else self.conn.transaction():
                yield
        except self.failures as exc:
            raise UserError(f"{self.name}: {first_line(exc)}") from None

    def new_id(self) -> int:
        """A new event's id, allocated by the database (never given twice)."""
        with self.transaction():
            if self.d is SQLITE:
                return int(self.conn.execute("INSERT INTO event_ids DEFAULT VALUES").lastrowid)
            return int(self.conn.execute("SELECT nextval('event_ids')").fetchone()[0])

    def when(self, t: pd.Timestamp | datetime | None) -> Any:
        """A time as the database takes it (SQLite: ISO 8601 text)."""
        if t is None:
            return None
        return t.isoformat() if self.d is SQLITE else t

    def times(self, us: Sequence[int]) -> list[Any]:
        """Times in microseconds since the epoch as the database takes them, all at once (as
        `when` gives each: SQLite's ISO 8601 text leaves out a fraction of zero)."""
        if not len(us):
            return []
        stamps = pd.to_datetime(np.asarray(us, np.int64), unit="us", utc=True)
        if self.d is not SQLITE:
            return list(stamps.to_pydatetime())
        text = np.datetime_as_string(np.asarray(us, np.int64).astype("datetime64[us]"))
        return [t.removesuffix(".000000") + "+00:00" for t in text.tolist()]

    def _event_row(self, e: LiveEvent, now: datetime) -> list[Any]:
        f = e.fields
        stretch = json.dumps([np.round(f["lons"], 6).tolist(), np.round(f["lats"], 6).tolist()])
        return [
            e.event_id, int(f["mmsi"]), f["name"], f["ship_type"], f["kind"], f["class"],
            self.when(f["start"]), self.when(f["end"]), _number(f["duration_s"]),
            int(f["n_reports"]), _number(f["lon"]), _number(f["lat"]),
            _number(f["strength"]), _number(f["rarity_days"]), f["evidence"], f["model"],
            f.get("others"), f.get("coverage"), e.state, None, self.when(now), stretch,
        ]  # fmt: skip

    def write(self, changes: Sequence[Change], vessels: Sequence[tuple]) -> None:
        """The events changed and the vessels' last positions (rows of `VESSEL_FIELDS` less
        `recent`, times in microseconds since the epoch), in one transaction. An event
        withdrawn (`Change`) is deleted: detect never raises it, and the database ends with
        detect's events (its id is never given again)."""
        now = datetime.now(timezone.utc)
        last = {c.event.event_id: c for c in changes}
        events = [c.event for c in last.values() if c.what != "withdrawn"]
        gone = [(i,) for i, c in last.items() if c.what == "withdrawn"]
        with self.transaction():
            cur = self.conn.cursor()
            if gone:
                cur.executemany(f"DELETE FROM events WHERE event_id = {self.d.mark}", gone)
            if events:
                cur.executemany(
                    upsert(self.d, "events", EVENT_FIELDS, "event_id"),
                    [self._event_row(e, now) for e in events],
                )
            if vessels:
                times = self.times([v[4] for v in vessels])
                cur.executemany(
                    upsert(self.d, "vessels", VESSEL_FIELDS[:-1], "mmsi"),
                    [
                        (*v[:3], _number(v[3]), t, *v[5:])
                        for v, t in zip(vessels, times, strict=True)
                    ],
                )
            if self.d.geometry and events:
                cur.executemany(
                    "UPDATE events SET geom = ST_SetSRID(ST_GeomFromGeoJSON(%s), 4326) "
                    "WHERE event_id = %s",
                    [(_geojson(e.fields), e.event_id) for e in events],
                )

    def resume(self) -> list[LiveEvent]:
        """The events to pick up: every open one (no longer marked stopped) and the closed ones
        of the last `RESUME_S` before the newest."""
        m = self.d.mark
        cur = self.conn.execute("SELECT max(end_time) FROM events")
        newest = cur.fetchone()[0]
        if newest is None:
            return []
        since = pd.Timestamp(newest) - pd.Timedelta(seconds=RESUME_S)
        cur = self.conn.execute(
            f"SELECT {', '.join(EVENT_FIELDS)} FROM events WHERE state = 'open' OR end_time >= {m}",
            (self.when(since),),
        )
        found = [_event_of(dict(zip(EVENT_FIELDS, row, strict=True))) for row in cur.fetchall()]
        with self.transaction():
            self.conn.execute("UPDATE events SET stopped_at = NULL WHERE state = 'open'")
        return found

    def windows(self) -> dict[int, tuple[dict[str, np.ndarray], Identity]]:
        """The vessels' windows kept when the watch last stopped (then cleared)."""
        cur = self.conn.execute(
            "SELECT mmsi, name, ship_type, length_m, recent FROM vessels WHERE recent IS NOT NULL"
        )
        out = {}
        for mmsi, name, ship_type, length, recent in cur.fetchall():
            cols = json.loads(recent)
            arrays = {k: np.asarray(cols[k], np.int64 if k == "time_us" else np.float64)
                      for k in FIELDS}  # fmt: skip
            out[int(mmsi)] = (
                arrays,
                Identity(name, ship_type, np.nan if length is None else length),
            )
        with self.transaction():
            self.conn.execute("UPDATE vessels SET recent = NULL")
        return out

    def stop(self, windows: dict[int, dict[str, np.ndarray]]) -> int:
        """The watch stops: open events stay open, marked with the time it stopped; each
        vessel's window is kept to resume from. The number of events left open."""
        now = self.when(datetime.now(timezone.utc))
        m = self.d.mark
        with self.transaction():
            cur = self.conn.cursor()
            cur.execute(f"UPDATE events SET stopped_at = {m} WHERE state = 'open'", (now,))
            left = cur.rowcount
            cur.executemany(
                f"UPDATE vessels SET recent = {m} WHERE mmsi = {m}",
                [(json.dumps({k: v.tolist() for k, v in cols.items()}), mmsi)
                 for mmsi, cols in windows.items()],
            )  # fmt: skip
        return left

    def close(self) -> None:
        self.conn.close()


def _event_of(row: dict[str, Any]) -> LiveEvent:
    lons, lats = json.loads(row["stretch"])
    fields = {
        "mmsi": int(row["mmsi"]), "name": row["name"], "ship_type": row["ship_type"],
        "kind": row["kind"], "class": KINDS[row["kind"]].cls,
        "start": _timestamp(row["start_time"]),
        "end": _timestamp(row["end_time"]), "duration_s": row["duration_s"],
        "n_reports": row["n_reports"], "lon": row["lon"], "lat": row["lat"], "track_id": None,
        "strength": row["strength"], "rarity_days": row["rarity_days"],
        "evidence": row["evidence"], "model": row["model"],
        "others": row["others"], "coverage": row["coverage"], "lons": lons, "lats": lats,
    }  # fmt: skip
    return LiveEvent(int(row["event_id"]), fields, row["state"])


def _timestamp(value: Any) -> pd.Timestamp:
    t = pd.Timestamp(value)
    return t.tz_localize("UTC") if t.tzinfo is None else t.tz_convert("UTC")


def _geojson(f: dict[str, Any]) -> str:
    """The event's geometry as events.geojson draws it (`aisdati.events.table.shape`: an area
    kind's outline a polygon)."""
    return json.dumps(shapely.geometry.mapping(shape(f["kind"], f["lons"], f["lats"])))


def open_store(url: str) -> Store:
    """The database at `url`: postgresql://... (psycopg), else a SQLite file's path. One that
    cannot be opened (locked, not a database, unreachable) is one line, and nothing written."""
    if url.startswith(("postgresql://", "postgres://")):
        return _postgres(url)
    path = Path(url)
    if path.parent and not path.parent.is_dir():
        raise UserError(f"{path.parent}: no such folder for the database")
    try:
        conn = sqlite3.connect(path, timeout=START_WAIT_S, check_same_thread=False)
    except sqlite3.Error as exc:
        raise UserError(f"{path}: {exc}") from None
    try:
        conn.execute("PRAGMA journal_mode=WAL")
        conn.execute("PRAGMA synchronous=NORMAL")  # WAL: a crash of the watch loses nothing
        store = Store(conn, SQLITE, str(path), (sqlite3.OperationalError,))
    except sqlite3.Error as exc:
        conn.close()
        raise UserError(f"{path}: {exc}") from None
    except UserError:
        conn.close()
        raise
    conn.execute(f"PRAGMA busy_timeout = {int(LOCK_WAIT_S * 1000)}")
    return store


def _postgres(url: str) -> Store:
    try:
        import psycopg
    except ImportError:
        raise UserError("PostgreSQL needs psycopg: pip install 'psycopg[binary]'") from None
    shown = without_password(url)
    try:
        conn = psycopg.connect(url)
    except psycopg.Error as exc:
        raise UserError(f"{shown}: {first_line(exc)}") from None
    conn.autocommit = True  # each block is its own transaction (`Store.transaction`)
    try:
        store = Store(conn, POSTGRES, shown, (psycopg.OperationalError,))
        cur = conn.execute("SELECT 1 FROM pg_available_extensions WHERE name = 'postgis'")
        if cur.fetchone() is not None:
            with store.transaction():
                conn.execute("CREATE EXTENSION IF NOT EXISTS postgis")
                conn.execute(
                    "ALTER TABLE events ADD COLUMN IF NOT EXISTS geom geometry(Geometry, 4326)"
                )
            store.d = Dialect(POSTGRES.mark, POSTGRES.time, POSTGRES.real, geometry=True)
    except psycopg.Error as exc:
        conn.close()
        raise UserError(f"{shown}: {first_line(exc)}") from None
    except UserError:
        conn.close()
        raise
    return store
