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
    """One vessel's window (`rows`: one row of `FIELDS` per report, in time order), who it is,
    and how many reports arrived since it was last judged."""

    rows: np.ndarray = field(default_factory=lambda: np.zeros((0, len(FIELDS))))
    identity: Identity = field(default_factory=Identity)
    new: int = 0
    heard_us: int = 0
    """The feed's time when it was last heard of (a report's own time, or a static message's
    arrival)."""

    @classmethod
    def of(cls, columns: dict[str, np.ndarray], identity: Identity) -> Recent:
        """A window from its columns (e.g. as a database kept it)."""
        return cls(np.column_stack([np.asarray(columns[k], np.float64) for k in FIELDS]), identity)

    @property
    def columns(self) -> dict[str, np.ndarray]:
        """The window as arrays of `FIELDS` (times as integers)."""
        cols = {k: self.rows[:, i] for i, k in enumerate(FIELDS)}
        cols["time_us"] = cols["time_us"].astype(np.int64)
        return cols

    def nbytes(self) -> int:
        return self.rows.nbytes


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
        """Reports in, each vessel's window merged and trimmed to its bounds; the MMSIs that
        got some. All the chunk's vessels at once: one sort of their windows and the new
        reports together (by vessel, then time; a report arrived later goes after an earlier
        one of the same time), not a sort per vessel."""
        if table.num_rows == 0:
            return set()
        cols = columns_of(table)
        new = np.column_stack([np.asarray(cols[k], np.float64) for k in FIELDS])
        keys, group_new = np.unique(table.column("mmsi").to_numpy(), return_inverse=True)
        held = [self.recent.setdefault(k, Recent()) for k in keys.tolist()]
        sizes = np.array([len(r.rows) for r in held], np.int64)
        rows = np.concatenate([*(r.rows for r in held), new])
        group = np.concatenate([np.repeat(np.arange(len(keys)), sizes), group_new])
        order = np.lexsort((rows[:, 0], group))
        rows, group = rows[order], group[order]
        ends = np.searchsorted(group, np.arange(len(keys)), side="right")
        last_us = rows[ends - 1, 0]
        from_end = ends[group] - np.arange(len(group))
        keep = (rows[:, 0] >= last_us[group] - self.window_s * 1e6) & (from_end <= self.max_reports)
        rows, group = rows[keep], group[keep]
        bounds = np.searchsorted(group, np.arange(len(keys) + 1)).tolist()
        counts = np.bincount(group_new, minlength=len(keys)).tolist()
        newest = np.full(len(keys), np.iinfo(np.int64).min)
        np.maximum.at(newest, group_new, cols["time_us"])
        for k, one in enumerate(held):
            one.rows = rows[bounds[k] : bounds[k + 1]].copy()
            one.new += counts[k]
            one.heard_us = max(one.heard_us, int(newest[k]))
        self.clock_us = max(self.clock_us, int(cols["time_us"].max()))
        return set(keys.tolist())

    def identify(self, identities: dict[int, list]) -> None:
        """What static messages said (`Decoder.identities`), over what was known (a field not
        given is kept), each into the vessel's identity history at its time (the feed's time
        where its line gave none)."""
        for mmsi, messages in identities.items():
            one = self.recent.setdefault(mmsi, Recent())
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
        """A vessel's window as arrays, its reports now counted as judged."""
        one = self.recent[mmsi]
        one.new = 0
        return one.columns

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
