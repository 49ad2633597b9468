"""The alert budget: how many alerts an analyst is asked to open, as a rate per 1,000
vessel-days (a vessel reporting on a UTC day is one vessel-day), and the thresholds that keep
each alert kind within its share of it.

Each alert kind's finder looks at its floor (`aisdati.events.settings`); a model records the
strengths of the events its training period's reports raise at the floors and that period's
vessel-days (`aisdati.events.calibrate`); detection raises an alert of a kind only where its
strength beats all but the budget's share of them, so that, traffic being alike from one
month to the next, the next month's rate lands near the budget. The budget is shared by the
kinds it governs (`aisdati.events.kinds.BUDGETED`, `thresholds_for`); the learned kinds are
bounded by their model's track-level contamination instead. Each alert's rarity says how
rare it is on the training traffic: one in so many vessel-days, comparable across kinds, so
the report can rank. Activity kinds (loitering, gaps) follow their fixed definitions and are
not budgeted.

Where no model is (`detect --models none`), `DEFAULT_MINIMUM` holds: thresholds set by the
rule in docs/results/events.md, written before their numbers."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from aisdati.events.kinds import BUDGETED, is_alert
from aisdati.events.stretch import Found

ALERTS_PER_1000 = 10.0
"""The default budget: alerts of the budgeted kinds together per 1,000 vessel-days."""
DEFAULT_MINIMUM: dict[str, float] = {
    "position-jump": 3.8,
    "speed-inconsistent": 4.6,
    "course-inconsistent": 2.4,
}
"""Without a model: each budgeted kind's threshold in strength over its floor (kinds not named:
1, the floor, which for drift and sudden speed change is AisAbnormal's definition). The rule,
written before the defaults were judged (docs/results/events.md): per kind, the largest
threshold the default budget calibrates on the earlier period of a shipped area of at least 500
vessel-days with its vessels' own reported motion (Kitimat's July), rounded up to 0.1."""


@dataclass(frozen=True)
class Thresholds:
    """Each alert kind's threshold (strength over its floor an event must reach) and, where
    calibrated, the training period's strengths of each kind (largest first) and its
    vessel-days, which give an alert's rarity."""

    minimum: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_MINIMUM))
    seen: dict[str, tuple[float, ...]] = field(default_factory=dict)
    vessel_days: float | None = None
    budget: float | None = None
    """The alerts per 1,000 vessel-days calibrated to (None: the defaults)."""

    def of(self, kind: str) -> float:
        return self.minimum.get(kind, 1.0)

    def over(self, e: Found) -> Found | None:
        """An alert found at its floor as raised (its strength now over its threshold), or
        None where it does not reach it; an activity as it is."""
        if not is_alert(e.kind):
            return e
        t = self.of(e.kind)
        return replace(e, strength=e.strength / t) if e.strength >= t else None

    def rarity_days(self, e: Found) -> float | None:
        """One in how many vessel-days of the training period an alert at least as strong as
        `e` (raised, `over`) came; None for an activity or where not calibrated."""
        if not is_alert(e.kind) or self.vessel_days is None or e.kind not in self.seen:
            return None
        floor_strength = e.strength * self.of(e.kind)
        as_strong = int(np.sum(np.asarray(self.seen[e.kind]) >= floor_strength))
        return round(self.vessel_days / (as_strong + 1), 1)


def thresholds_for(
    strengths: dict[str, list[float]], vessel_days: float, budget: float = ALERTS_PER_1000
) -> Thresholds:
    """The thresholds that would have raised at most `budget` alerts per 1,000 of
    `vessel_days` on the period whose floor strengths are `strengths` (kind -> values). The
    budget is shared by water-filling: every budgeted kind is allowed the same number of
    alerts, the largest that keeps the total within the budget, and a kind that raises fewer
    at its floor leaves the rest to the others; so an alert at its kind's threshold is about
    equally rare whatever its kind."""
    values = {k: sorted(strengths.get(k, []), reverse=True) for k in BUDGETED}
    total = int(np.floor(budget / 1000.0 * vessel_days))
    each = 0
    while each < total and sum(min(len(v), each + 1) for v in values.values()) <= total:
        if all(len(v) <= each for v in values.values()):
            break
        each += 1
    minimum = {}
    for kind, v in values.items():
        minimum[kind] = max(1.0, float(np.nextafter(v[each], np.inf))) if len(v) > each else 1.0
    seen = {k: tuple(v) for k, v in values.items()}
    return Thresholds(minimum, seen, float(vessel_days), budget)
