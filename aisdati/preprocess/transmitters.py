"""One MMSI heard from two transmitters at once: two vessels configured with the same MMSI (a
copied or default number), or a spoofer. Their reports alternate between places no vessel
could join in the time between them. The implied-speed check (`aisdati.preprocess.clean`)
would keep one transmitter and drop the other's reports as position outliers; instead they are
told apart here, before it, and the second transmitter's reports are kept under a vessel id of
their own (`aisdati.tracks.schema.TRANSMITTER_STEP`), so each transmitter's track is whole and
no track jumps between them. Global Fishing Watch's segmenter splits such MMSIs the same way
(a report joins the segment it can be reached from); `aisdati.events.identity` raises the
`identity-conflict` alert from the split.

The rule, per MMSI in time order: a report joins the transmitter whose last report it can be
reached from at `max_speed_kn` (plus the GPS tolerance; the nearer one where both could); one
that neither can reach starts the second transmitter (replacing a second transmitter of one
report, which was an outlier). The MMSI is split only where each transmitter has at least
`MIN_REPORTS` reports, the reports switch between them at least `MIN_SWITCHES` times out of
reach of the other's last report (two transmitters interleave; a vessel whose first fix was
wrong, or that jumped once, does not; two vessels within reach of each other prove nothing),
each has `MIN_REPORTS` reports heard within `AT_ONCE_S` of one of the other's (both on the air
at once: one vessel's stale or mistimed report, or its own track handed from one transmitter
to the other after a silence, gives a few at most), and the second's reports are not copies
of the vessel's own at other times (`COPY_S`: a receiver's clock gone wrong, as in the DMA's
recording of FRIO); else nothing changes and the implied-speed check judges the reports as
before."""

from __future__ import annotations

import numba
import numpy as np
import pyarrow as pa

from aisdati.geo import haversine_one_m
from aisdati.tracks.schema import TRANSMITTER_STEP

MIN_REPORTS = 10
"""Reports each transmitter needs: fewer is an outlier or two, for the implied-speed check."""
MIN_SWITCHES = 4
"""Switches between the two in time order: A B A B A at least, so that both report at once."""
AT_ONCE_S = 180.0
"""The longest interval at which a vessel's transmitter reports (ITU-R M.1371: a Class A
moored or at anchor, a Class B under 2 kn; more often under way): two transmitters on the air
at once are each heard within it of the other. A feed that keeps fewer reports (one a few
minutes) is judged as it holds them."""
COPY_S = 3600.0
"""A second transmitter whose reports are mostly copies of the vessel's own (the same
position, speed and course) from within this of them is the vessel relayed with wrong times (a
receiver's clock off: the DMA's recording of FRIO has reports again 17 minutes late), not a
second vessel: nothing is split. Two vessels never send the same report."""


@numba.njit(cache=True)
def _reach(i, j, time_us, lon, lat, max_mps, tolerance_m, reset_us):
    """How far report j is from report i, and whether a vessel could have sailed it (after a
    silence of `reset_us`, anywhere: it may have sailed out of hearing and back)."""
    dist = haversine_one_m(lon[i], lat[i], lon[j], lat[j])
    dt_us = abs(time_us[j] - time_us[i])
    return dist, dt_us > reset_us or dist <= max_mps * dt_us / 1e6 + tolerance_m


@numba.njit(cache=True)
def _chains(time_us, lon, lat, max_mps, tolerance_m, reset_us):
    """One vessel's reports (time order) as two chains: 0, 1, or -1 (reached by neither); and
    whether each is out of reach of the other chain's last report (a switch to it is forced).
    A report both could reach joins the nearer (after a silence, each transmitter goes on
    where it stopped); a stretch between silences of `reset_us` in which only the second
    reports is the first's (its MMSI's own)."""
    n = time_us.shape[0]
    chain = np.full(n, -1, np.int8)
    forced = np.zeros(n, np.bool_)
    if n == 0:
        return chain, forced
    head0, head1, size1 = 0, -1, 0
    chain[0] = 0
    for i in range(1, n):
        d0, in0 = _reach(head0, i, time_us, lon, lat, max_mps, tolerance_m, reset_us)
        d1, in1 = np.inf, False
        if head1 >= 0:
            d1, in1 = _reach(head1, i, time_us, lon, lat, max_mps, tolerance_m, reset_us)
        if in0 and (not in1 or d0 <= d1):
            chain[i], head0, forced[i] = 0, i, not in1
        elif in1:
            chain[i], head1, forced[i] = 1, i, not in0
            size1 += 1
        elif size1 <= 1:
            if head1 >= 0:
                chain[head1] = -1
            chain[i], head1, size1, forced[i] = 1, i, 1, True
    lo = 0
    for hi in range(1, n + 1):
        if hi == n or time_us[hi] - time_us[hi - 1] > reset_us:
            if not (chain[lo:hi] == 0).any():
                chain[lo:hi] = np.where(chain[lo:hi] == 1, 0, chain[lo:hi])
            lo = hi
    return chain, forced


@numba.njit(cache=True)
def _at_once(chain, time_us):
    """How many reports of each chain are heard within `AT_ONCE_S` of one of the other's."""
    n = chain.shape[0]
    near = np.zeros(n, np.bool_)
    window = AT_ONCE_S * 1e6
    last = np.array([-np.inf, -np.inf])
    for k in range(n):  # the other's latest report before, then its earliest after
        if chain[k] >= 0:
            near[k] = time_us[k] - last[1 - chain[k]] <= window
            last[chain[k]] = time_us[k]
    last = np.array([np.inf, np.inf])
    for k in range(n - 1, -1, -1):
        if chain[k] >= 0:
            near[k] |= last[1 - chain[k]] - time_us[k] <= window
            last[chain[k]] = time_us[k]
    return (near & (chain == 0)).sum(), (near & (chain == 1)).sum()


@numba.njit(cache=True)
def _copies(chain, time_us, lon, lat, sog, cog):
    """Whether most of chain 1's reports are copies of other reports of the vessel (the same
    position, speed and course, at another time within `COPY_S`)."""
    second = np.flatnonzero(chain == 1)
    copied = 0
    for j in second:
        lo = np.searchsorted(time_us, time_us[j] - COPY_S * 1e6)
        hi = np.searchsorted(time_us, time_us[j] + COPY_S * 1e6, side="right")
        for i in range(lo, hi):
            if (
                time_us[i] != time_us[j]
                and lon[i] == lon[j]
                and lat[i] == lat[j]
                and (sog[i] == sog[j] or (np.isnan(sog[i]) and np.isnan(sog[j])))
                and (cog[i] == cog[j] or (np.isnan(cog[i]) and np.isnan(cog[j])))
            ):
                copied += 1
                break
    return 2 * copied >= len(second)


@numba.njit(cache=True)
def second_transmitter(mmsi, time_us, lon, lat, sog, cog, max_mps, tolerance_m, reset_us):
    """Which reports (sorted by MMSI, then time) are a second transmitter's: those of chain 1
    of each MMSI below `TRANSMITTER_STEP` that is split (see the module's rule)."""
    n = mmsi.shape[0]
    second = np.zeros(n, np.bool_)
    lo = 0
    while lo < n:
        hi = lo
        while hi < n and mmsi[hi] == mmsi[lo]:
            hi += 1
        if hi - lo >= 2 * MIN_REPORTS and 0 < mmsi[lo] < TRANSMITTER_STEP:
            chain, forced = _chains(
                time_us[lo:hi], lon[lo:hi], lat[lo:hi], max_mps, tolerance_m, reset_us
            )
            n0, n1, switches, prev = 0, 0, 0, -1
            for k in range(hi - lo):
                c = chain[k]
                if c < 0:
                    continue
                if c == 0:
                    n0 += 1
                else:
                    n1 += 1
                if prev >= 0 and c != prev and forced[k]:
                    switches += 1
                prev = c
            apart = n0 >= MIN_REPORTS and n1 >= MIN_REPORTS and switches >= MIN_SWITCHES
            if apart:
                near0, near1 = _at_once(chain, time_us[lo:hi])
                apart = near0 >= MIN_REPORTS and near1 >= MIN_REPORTS
            if apart and not _copies(
                chain, time_us[lo:hi], lon[lo:hi], lat[lo:hi], sog[lo:hi], cog[lo:hi]
            ):
                for k in range(hi - lo):
                    second[lo + k] = chain[k] == 1
        lo = hi
    return second


def split_transmitters(
    table: pa.Table, max_mps: float, tolerance_m: float, reset_us: int
) -> pa.Table:
    """The table (sorted by MMSI, then time) with each second transmitter's reports under its
    own id (MMSI + `TRANSMITTER_STEP`), sorted again; the same table where none is found."""
    mmsi = table.column("mmsi").to_numpy()
    time_us = table.column("time").to_numpy().view(np.int64)
    lon, lat, sog, cog = (table.column(c).to_numpy() for c in ("lon", "lat", "sog", "cog"))
    second = second_transmitter(mmsi, time_us, lon, lat, sog, cog, max_mps, tolerance_m, reset_us)
    if not second.any():
        return table
    ids = np.where(second, mmsi + TRANSMITTER_STEP, mmsi)
    order = np.lexsort((time_us, ids))
    table = table.set_column(0, table.schema.field(0), pa.array(ids, pa.int64()))
    return table.take(pa.array(order))
