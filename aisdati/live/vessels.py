"""Each vessel's recent reports, in bounded memory: a window of its last `window_s` seconds and
at most `max_reports` reports, and at most `max_vessels` vessels; a vessel silent for
`forget_s` (by the feed's clock), or the longest silent when there are too many, is forgotten
and counted."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pyarrow as pa

from aisdati.live.decode import Identity

FIELDS = ("time_us", "lon", "lat", "sog", "cog", "heading", "status")
"""A report as a vessel's window keeps it (64-bit numbers; status -1 where not given)."""


@dataclass
class Recent:
    """One vessel's window (arrays of `FIELDS`, in arrival order until `merged`), who it is,
    and how many reports arrived since it was last judged."""

    columns: dict[str, np.ndarray]
    identity: Identity = field(default_factory=Identity)
    pending: list[dict[str, np.ndarray]] = field(default_factory=list)
    new: int = 0
    heard_us: int = 0
    """The feed's time when it was last heard of (a report's own time, or a static message's
    arrival)."""

    def merged(self, window_s: float, max_reports: int) -> dict[str, np.ndarray]:
        """The window with the pending reports in, sorted by time, trimmed to its bounds."""
        if self.pending:
            parts = [self.columns, *self.pending]
            cols = {k: np.concatenate([p[k] for p in parts]) for k in FIELDS}
            order = np.argsort(cols["time_us"], kind="stable")
            t = cols["time_us"][order]
            keep = order[max(np.searchsorted(t, t[-1] - window_s * 1e6), len(t) - max_reports) :]
            self.columns = {k: v[keep] for k, v in cols.items()}
            self.pending = []
        return self.columns

    def nbytes(self) -> int:
        return sum(v.nbytes for v in self.columns.values()) + sum(
            v.nbytes for p in self.pending for v in p.values()
        )


def empty_columns() -> dict[str, np.ndarray]:
    return {k: np.zeros(0, np.int64 if k == "time_us" else np.float64) for k in FIELDS}


def columns_of(table: pa.Table) -> dict[str, np.ndarray]:
    """Reports (`convert.PARTITION_SCHEMA`) as a window's arrays."""
    status = table.column("status").to_numpy(zero_copy_only=False)
    return {
        "time_us": table.column("time").to_numpy().view(np.int64),
        "lon": table.column("lon").to_numpy(),
        "lat": table.column("lat").to_numpy(),
        "sog": table.column("sog").to_numpy(),
        "cog": table.column("cog").to_numpy(),
        "heading": table.column("heading").to_numpy(zero_copy_only=False).astype(np.float64),
        "status": np.nan_to_num(np.asarray(status, np.float64), nan=-1.0),
    }


@dataclass
class Vessels:
    """The vessels heard, each its `Recent`; `clock_us` the feed's time (its newest report)."""

    window_s: float = 3 * 3600.0
    max_reports: int = 2000
    max_vessels: int = 50_000
    forget_s: float = 86400.0
    recent: dict[int, Recent] = field(default_factory=dict)
    clock_us: int = 0
    forgotten: int = 0

    def add(self, table: pa.Table) -> set[int]:
        """Reports in; the MMSIs that got some."""
        if table.num_rows == 0:
            return set()
        cols = columns_of(table)
        mmsi = table.column("mmsi").to_numpy()
        order = np.argsort(mmsi, kind="stable")
        keys, starts = np.unique(mmsi[order], return_index=True)
        for key, rows in zip(keys.tolist(), np.split(order, starts[1:]), strict=True):
            one = self.recent.setdefault(key, Recent(empty_columns()))
            one.pending.append({k: v[rows] for k, v in cols.items()})
            one.new += len(rows)
            one.heard_us = max(one.heard_us, int(cols["time_us"][rows].max()))
        self.clock_us = max(self.clock_us, int(cols["time_us"].max()))
        return set(keys.tolist())

    def identify(self, identities: dict[int, list]) -> None:
        """What static messages said (`Decoder.identities`), over what was known (a field not
        given is kept), each into the vessel's identity history at its time (the feed's time
        where its line gave none)."""
        for mmsi, messages in identities.items():
            one = self.recent.setdefault(mmsi, Recent(empty_columns()))
            one.heard_us = max(one.heard_us, self.clock_us)
            for (name, ship_type, length_m), time_us in messages:
                old = one.identity
                at = self.clock_us if time_us == np.iinfo(np.int64).min else time_us
                one.identity = replace(
                    old.heard((name, ship_type, length_m), at),
                    name=name or old.name,
                    ship_type=ship_type or old.ship_type,
                    length_m=old.length_m if np.isnan(length_m) else length_m,
                )

    def window(self, mmsi: int) -> dict[str, np.ndarray]:
        one = self.recent[mmsi]
        one.new = 0
        return one.merged(self.window_s, self.max_reports)

    def forget(self) -> list[int]:
        """Forget the vessels silent for `forget_s`, and the longest silent beyond
        `max_vessels`; their MMSIs."""
        heard = {m: r.heard_us for m, r in self.recent.items()}
        gone = [m for m, t in heard.items() if self.clock_us - t > self.forget_s * 1e6]
        extra = len(self.recent) - len(gone) - self.max_vessels
        if extra > 0:
            rest = sorted(
                (t, m) for m, t in heard.items() if self.clock_us - t <= self.forget_s * 1e6
            )
            gone += [m for _, m in rest[:extra]]
        for m in gone:
            del self.recent[m]
        self.forgotten += len(gone)
        return gone

    def nbytes(self) -> int:
        return sum(r.nbytes() for r in self.recent.values())
