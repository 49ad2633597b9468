"""Port visits (`aisdati.events.kinds`: port-visit), as Global Fishing Watch defines them: a
vessel arrives when it comes within `port_entry_m` of an anchorage point
(`aisdati.events.anchorages`) and departs when it is next over `port_exit_m` from every one;
a stay is a visit when the vessel stopped in it (a report under `stopped_kn`) and it lasted
`port_min_s` or more. The visit folds the vessel's loitering in it (waiting at an anchorage is
not loitering at sea)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from aisdati.events.anchorages import Anchorages
from aisdati.events.record import event_row
from aisdati.events.reports import VesselReports
from aisdati.events.settings import EventSettings
from aisdati.events.stretch import runs

if TYPE_CHECKING:  # the fleet module registers this finder
    from aisdati.events.fleet import Fleet
    from aisdati.events.rules import EventRules


def stays(v: VesselReports, metres: np.ndarray, s: EventSettings) -> list[tuple[int, int, int]]:
    """Each stay of the vessel near an anchorage that is a visit (`metres`: each report's
    distance to the nearest anchorage point, `Anchorages.nearest`): (first report in, last
    report in, the report nearest an anchorage point while stopped)."""
    entered, left = metres <= s.port_entry_m, metres > s.port_exit_m
    said = np.maximum.accumulate(np.where(entered | left, np.arange(len(v)), -1))  # the last
    inside = entered[said] & (said >= 0)  # of them so far: between the two, a vessel stays
    out = []
    for a, b in runs(inside):
        stopped = np.flatnonzero(v.sog[a : b + 1] < s.stopped_kn)
        if stopped.size and v.time_s[b] - v.time_s[a] >= s.port_min_s:
            peak = a + int(stopped[np.argmin(metres[a + stopped])])
            out.append((int(a), int(b), peak))
    return out


def visit_row(
    fleet: Fleet, v: VesselReports, stay: tuple[int, int, int], ports: Anchorages, min_s: float
) -> dict[str, Any]:
    """One visit as an event: from arrival to departure, placed at the anchorage point nearest
    where the vessel stopped, its evidence the port (where named) and whether it was already
    in port when its reports begin, or still in at their end; its strength its length over
    `min_s`."""
    a, b, peak = stay
    _, point = ports.nearest(v.lon[peak : peak + 1], v.lat[peak : peak + 1])
    k = int(point[0])
    hours = (v.time_s[b] - v.time_s[a]) / 3600
    port = ports.port[k] or f"the anchorage at {ports.lat[k]:.4f},{ports.lon[k]:.4f}"
    said = f"at {port} for {hours:.1f} h"
    if a == 0:
        said += ", in port from its first report"
    if b == len(v) - 1:
        said += ", still in port at its last report"
    track = int(v.track_id[peak])
    return event_row(
        v.mmsi, "port-visit", (v.time_s[a], v.time_s[b]), b - a + 1,
        (float(ports.lon[k]), float(ports.lat[k])),
        (v.lon[a : b + 1].tolist(), v.lat[a : b + 1].tolist()), hours * 3600 / min_s, said,
        identity=fleet.who(v.mmsi), track_id=track if track >= 0 else None,
    )  # fmt: skip


def port_visits(fleet: Fleet, rules: EventRules) -> list[dict[str, Any]]:
    """Every port visit of the fleet's vessels."""
    ports, s = fleet.anchorages(rules), rules.settings
    if not len(ports):
        return []
    every = fleet.joined  # (a vessel never within `port_entry_m` or never stopped has none)
    metres, _ = ports.nearest(every.reports.lon, every.reports.lat)
    stopped = every.reports.sog < s.stopped_kn
    near = every.any_report(metres <= s.port_entry_m) & every.any_report(stopped)
    return [
        visit_row(fleet, v, stay, ports, s.port_min_s)
        for k, v in enumerate(fleet.vessels.values())
        if near[k]
        for stay in stays(v, metres[every.bounds[k] : every.bounds[k + 1]], s)
    ]
