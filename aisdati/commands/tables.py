"""Every rich table the commands print, one builder per table: the computing modules return plain
data, and only this module decides how it looks on a terminal. Rich reads every string in a table
as markup, so each name that comes from the user or the data (clusters, routes, models, paths)
goes through `escape`: `a[/]b` and `[x]` are printed as they are."""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Any

import pandas as pd
from rich import box
from rich.markup import escape
from rich.table import Table
from rich.text import Text

from aisdati.commands.columns import Column, fitted_table, width_needed
from aisdati.events.kinds import ALERT
from aisdati.events.table import ranked
from aisdati.preprocess.report import REASONS, IngestCounts
from aisdati.scores import score as score_named

if TYPE_CHECKING:
    from aisdati.detectors.train import Trained
    from aisdati.evaluation.run import Evaluation, RoutesEvaluation


# ----------------------------------------------------------------------------------- ingest
def summary_table(counts: IngestCounts) -> Table:
    """The per-stage summary: rows read, rejected per stage and reason, kept (the tracks' points,
    and every report judged), tracks per cluster."""
    table = Table(title="aisdati ingest", show_lines=False)
    table.add_column("stage")
    table.add_column("reason")
    table.add_column("rows", justify="right")
    table.add_column("what", style="dim")
    table.add_row("read", "rows read", f"{counts.rows_read:,}", f"{len(counts.files)} file(s)")
    for code, (stage, reason, description) in REASONS.items():
        n = int(counts.rejected[code])
        if n:
            table.add_row(stage, reason, f"-{n:,}", description)
    table.add_row("[bold]kept", "points", f"[bold]{counts.kept_points:,}", "in tracks")
    table.add_row(
        "[bold]kept",
        "reports",
        f"[bold]{counts.reports_kept:,}",
        "judged, slow or not (reports.parquet)",
    )
    if shared := counts.two_transmitters:
        table.add_row(
            "vessel",
            "two_transmitters",
            f"{len(shared):,}",
            escape(
                f"MMSIs heard from two transmitters, each kept: {', '.join(map(str, shared[:5]))}"
            )
            + ("..." if len(shared) > 5 else ""),
        )
    total = sum(counts.tracks.values())
    table.add_row(
        "[bold]cluster",
        "tracks",
        f"[bold]{total:,}",
        escape(", ".join(f"{name} {n:,}" for name, n in counts.tracks.items())),
    )
    return table


def routes_table(summary: dict[str, Any], limit: int = 25) -> Table:
    """The routes found by ingest: size, entry, exit and median length, largest first."""
    rows = summary["routes"]
    table = Table(
        title=f"{len(rows)} routes ({summary['routed_tracks']:,} tracks; "
        f"{summary['unrouted_tracks']:,} fit no route)"
    )
    for col in ("route", "tracks", "entry (lat, lon)", "exit (lat, lon)", "median length"):
        table.add_column(col, justify="right" if col in ("tracks", "median length") else "left")
    for r in rows[:limit]:
        table.add_row(
            escape(str(r["route"])),
            f"{r['n_tracks']:,}",
            f"{r['entry_lat']:.4f}, {r['entry_lon']:.4f}",
            f"{r['exit_lat']:.4f}, {r['exit_lon']:.4f}",
            f"{r['median_length_km']:,.1f} km",
        )
    if len(rows) > limit:
        table.caption = f"... and {len(rows) - limit} more in routes.parquet"
    return table


# --------------------------------------------------------------------------------- selftest
def _ours(value: float, paper: float | None, sd: float = float("nan")) -> str:
    """Our number, green where it is at or below the paper's; `± sd` over repeats when known."""
    style = "green" if paper is not None and value <= paper else "yellow"
    spread = "" if math.isnan(sd) else f" ± {sd:.3f}"  # NaN: a single repeat
    return f"[{style}]{value:.3f}{spread}[/]"


def _best_label(rows: list[dict[str, Any]], what: str) -> str:
    repeats = max((r.get("repeats", 1) for r in rows), default=1)
    return what if repeats == 1 else f"{what}, mean ± sd of {repeats} repeats"


def _paper(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


def _method_label(method: str) -> str:
    from aisdati.selftest.settings import METHODS  # here: it loads torch, which ingest needs not

    return METHODS.get(method, method)


def selftest_table(rows: list[dict[str, Any]], wall_seconds: float) -> Table:
    """Ours beside the paper's Table 1 (lower is better); one row per method x family."""
    methods = list(dict.fromkeys(r.get("method", "dati") for r in rows))
    name = "DATI" if methods == ["dati"] else "Table 1"
    table = Table(
        title=f"{name} self-test: normalised smoothed DTW (wall time {wall_seconds / 60:.1f} min)"
    )
    cols = (
        "method",
        "family",
        _best_label(rows, "best (paper's metric)"),
        "paper",
        "median",
        "IQM [95% CI]",
        "episodes",
    )
    for col in cols:
        table.add_column(col, justify="left" if col in ("method", "family") else "right")
    for r in rows:
        table.add_row(
            _method_label(r.get("method", "dati")),
            r["family"],
            _ours(r["best"], r["paper_best"], r.get("best_sd", float("nan"))),
            _paper(r["paper_best"]),
            f"{r['median']:.3f}",
            f"{r['iqm']:.3f} [{r['iqm_ci_low']:.3f}, {r['iqm_ci_high']:.3f}]",
            f"{r['mean_episodes']:.1f}",
        )
    return table


def ablation_table(rows: list[dict[str, Any]], wall_seconds: float) -> Table:
    """Ours beside the paper's Table 2: top-1 and top-2 per DATI variant (lower is better)."""
    table = Table(
        title=f"DATI ablation: normalised smoothed DTW (wall time {wall_seconds / 60:.1f} min)"
    )
    cols = (
        "variant",
        "family",
        _best_label(rows, "top-1"),
        "paper",
        _best_label(rows, "top-2"),
        "paper",
        "median",
        "IQM [95% CI]",
        "episodes",
    )
    for col in cols:
        table.add_column(col, justify="left" if col in ("variant", "family") else "right")
    for r in rows:
        table.add_row(
            _method_label(r["method"]),
            r["family"],
            _ours(r["best"], r["paper_best"], r.get("best_sd", float("nan"))),
            _paper(r["paper_best"]),
            _ours(r["second_best"], r["paper_second_best"], r.get("second_best_sd", float("nan"))),
            _paper(r["paper_second_best"]),
            f"{r['median']:.3f}",
            f"{r['iqm']:.3f} [{r['iqm_ci_low']:.3f}, {r['iqm_ci_high']:.3f}]",
            f"{r['mean_episodes']:.1f}",
        )
    return table


# ------------------------------------------------------------------------------------ train
def dati_model_table(cluster: str, result: Trained) -> Table:
    """One trained DATI model: its data, episodes, last reward and DTW, speed and wall time."""
    card = result.card
    tr = card["training"]
    used = card["data"]["tracks_used"]
    table = Table(title=f"DATI model of cluster {escape(repr(cluster))}")
    table.add_column("item")
    table.add_column("value", justify="right")
    rows = [
        ("resumed after episode", str(result.resumed_from)) if result.resumed_from else None,
        ("training tracks", f"{used} of {card['data']['tracks_in_cluster']}"),
        ("episodes run", f"{tr['episodes_run']} (best: {tr['best_episode']})"),
        ("mean reward, last episode", f"{tr['mean_reward'][-1]:+.3f}"),
        ("smoothed DTW at horizon, last", f"{tr['final_dtw_m'][-1]:,.0f} m"),
        ("steps/s", f"{tr['steps_per_second']}"),
        ("wall time", f"{result.wall_seconds:.1f} s"),
    ]
    for row in rows:
        if row:
            table.add_row(*row)
    return table


def route_models_table(method: str, routes: list[str], trained: list[Trained]) -> Table:
    """The models of `train --cluster routes`: one row per route."""
    table = Table(title=f"{method} models of {len(routes)} routes")
    for col in ("route", "tracks", "episodes", "model"):
        table.add_column(col, justify="left" if col in ("route", "model") else "right")
    for route, t in zip(routes, trained, strict=True):
        runs = t.card.get("training", {}).get("episodes_run", "-")
        used = str(t.card["data"]["tracks_used"])
        table.add_row(escape(route), used, str(runs), escape(str(t.model)))
    return table


# --------------------------------------------------------------------------------- evaluate
def results_table(ev: Evaluation, width: int = 120) -> Table:
    """The table; on a terminal narrower than 100 columns, without AP, P and R (they stay in
    evaluation.json)."""
    title = (
        f"Detection of injected anomalies: cluster {escape(repr(ev.settings.cluster))}, "
        f"{len(ev.split.train_ids)} training / {len(ev.split.heldout_ids)} held-out tracks "
        f"({int(ev.split.labels['label'].sum())} altered)"
    )
    caption = (
        "AUC (ROC) and AP (average precision) rank altered against normal held-out tracks; "
        "P/R/F1 at each detector's calibrated threshold; normal/altered: median scores in km "
        "(stepspread: multiples of the model's spread)"
    )
    return _evaluation_table(ev.table, title, caption, width)


def pooled_table(rev: RoutesEvaluation, width: int = 120) -> Table:
    """The pooled table of `--cluster routes` (scores in multiples of each route's threshold)."""
    held = sum(len(ev.split.heldout_ids) for ev in rev.routes)
    altered = sum(int(ev.split.labels["label"].sum()) for ev in rev.routes)
    names = escape(", ".join(ev.settings.cluster for ev in rev.routes))
    title = (
        f"Detection of injected anomalies over {len(rev.routes)} routes ({names}): "
        f"{held} held-out tracks ({altered} altered), each judged by its route's model"
    )
    caption = (
        "Pooled: each score divided by its route model's calibrated threshold, then ranked "
        "together; normal/altered: median multiples of the threshold (above 1 is flagged)"
    )
    if rev.skipped:
        caption += f"; skipped (too few tracks to split): {escape(', '.join(rev.skipped))}"
    return _evaluation_table(rev.table, title, caption, width)


def _distance(value: float | None, unit: str) -> str:
    """A median of the table: km for metres, else the ratio itself."""
    if value is None or value != value:
        return "-"
    return f"{value / 1000 if unit == 'm' else value:.2f}"


def _figure(v: float | None, digits: int = 3) -> str:
    return "-" if v is None or v != v else f"{v:.{digits}f}"


def _evaluation_table(frame: pd.DataFrame, title: str, caption: str, width: int) -> Table:
    t = Table(title=title, box=box.SIMPLE_HEAD)
    cols = ["detector", "score", "kind", "n", "AUC", "AP", "P", "R", "F1", "normal", "altered"]
    narrow = width < 100
    if narrow:
        cols = [c for c in cols if c not in ("AP", "P", "R")]
    for c in cols:
        left = c in ("detector", "score", "kind")
        t.add_column(c, justify="left" if left else "right", no_wrap=True)
    last = None
    for r in frame.itertuples():
        if last is not None and (r.detector, r.score) != last:
            t.add_section()
        last = (r.detector, r.score)
        auc = _figure(r.roc_auc)
        if r.roc_auc is not None and r.roc_auc == r.roc_auc:
            style = "green" if r.roc_auc >= 0.9 else "yellow" if r.roc_auc >= 0.7 else "red"
            auc = f"[{style}]{auc}[/]"
        cells = {
            "detector": r.detector,
            "score": "dtw" if r.score == "nearest" else r.score,
            "kind": "d+j+l" if narrow and "+" in r.kind else r.kind,
            "n": str(r.anomalies),
            "AUC": auc,
            "AP": _figure(r.average_precision),
            "P": _figure(r.precision, 2),
            "R": _figure(r.recall, 2),
            "F1": _figure(r.f1, 2),
            "normal": _distance(r.median_normal, r.unit),
            "altered": _distance(r.median_anomalous, r.unit),
        }
        t.add_row(*(cells[c] for c in cols))
    t.caption = caption
    return t


# ----------------------------------------------------------------------------------- detect
RULE_CAPTIONS = {
    "calibrated": "flagged: score above its model's calibrated threshold",
    "relative": "flagged by the paper's rule: score above --threshold x the batch's largest",
    "top": "flagged: the --top-percent highest scores of the batch",
}


DETECTION_DROPS = ("max km", "threshold", "rank", "model", "events")
"""What the ranked tracks' table leaves out, in this order, where the terminal is too narrow for
every figure whole (all of it is in scores.parquet)."""
EVENT_DROPS = ("x thr", "for")
"""What the events table leaves out, in this order, once the evidence is beneath the kind (all
of it is in events.parquet)."""


def detection_table(
    scores: pd.DataFrame,
    score: str = "lane",
    rule: str = "calibrated",
    limit: int = 15,
    width: int = 120,
) -> Table:
    """The flagged tracks (or, if none, the top of the ranking) with where they deviate most;
    the score and its threshold in km, or in the unit of `score` where it is not metres
    (`aisdati.scores.Score`); the caption names the flagging rule. Every figure whole at
    `width` columns (`aisdati.commands.columns`), `DETECTION_DROPS` left out where needed."""
    flagged = scores[scores["flagged"]].sort_values("rank")
    shown = flagged if len(flagged) else scores.sort_values("rank")
    title = (
        f"{len(flagged)} of {len(scores)} test tracks flagged"
        if len(flagged)
        else f"no track flagged among {len(scores)}; the highest scores"
    )
    kind = score_named(score)
    rows = list(shown.head(limit).itertuples())
    cells = {
        "rank": [str(r.rank) for r in rows],
        "track": [str(r.track_id) for r in rows],
        "vessel": [_vessel(r.mmsi, r.name) for r in rows],
        "model": [str(r.model) for r in rows],
        f"score ({kind.readable_unit})": [f"{kind.readable(r.score):,.2f}" for r in rows],
        "threshold": [f"{kind.readable(r.threshold):,.2f}" for r in rows],
        "max km": [f"{r.max_dev_m / 1000:,.2f}" for r in rows],
        "at (lat, lon)": [_place(r.max_dev_lat, r.max_dev_lon) for r in rows],
        "ashore": [str(r.ashore_reports) for r in rows],
        "events": [r.event_kinds or "-" for r in rows],
    }
    if scores["model"].nunique() <= 1:
        del cells["model"]
    if not (scores["ashore_reports"] > 0).any():
        del cells["ashore"]
    styles = {f"score ({kind.readable_unit})": ["red" if r.flagged else "white" for r in rows]}
    free = ("vessel", "model", "events")
    columns = [
        Column(
            name,
            [Text(v, style=styles.get(name, [""] * len(rows))[k]) for k, v in enumerate(values)],
            right=name not in (*free, "at (lat, lon)"),
            wraps=name in free,
        )
        for name, values in cells.items()
    ]
    table = fitted_table(title, columns, width, DETECTION_DROPS)
    more = f"... and {len(shown) - limit} more in scores.parquet" if len(shown) > limit else ""
    table.caption = "; ".join(filter(None, [RULE_CAPTIONS[rule], table.caption, more]))
    return table


def events_table(events: pd.DataFrame, limit: int = 20, width: int = 120) -> Table:
    """The events found, what to look at first (`ranked`: alerts, rarest first, then activity):
    which vessel did what, from when, for how long, where, and how far over its threshold
    (strength 1 = at it). Every figure whole at `width` columns: where the evidence has no room
    of its own it goes beneath the kind, then `EVENT_DROPS` are left out."""
    alerts = int((events["class"] == ALERT).sum()) if len(events) else 0
    title = (
        f"{alerts} alert(s), {len(events) - alerts} activity event(s)"
        if len(events)
        else "no events"
    )
    rows = list((ranked(events) if len(events) else events).head(limit).itertuples())
    kinds = [Text(_kind(e)) for e in rows]
    evidence = [Text(str(e.evidence), style="dim") for e in rows]
    figures = [
        Column("vessel", [Text(_vessels(e)) for e in rows], wraps=True),
        Column("start (UTC)", [Text(f"{e.start:%Y-%m-%d %H:%M:%S}") for e in rows]),
        Column("for", [Text(_duration(e.duration_s)) for e in rows]),
        Column("at (lat, lon)", [Text(_place(e.lat, e.lon)) for e in rows]),
        Column("x thr", [Text(f"{e.strength:.2f}") for e in rows], right=True),
    ]
    columns = [Column("kind", kinds), *figures, Column("evidence", evidence, wraps=True)]
    if width_needed(columns) > width:
        beneath = [Text("\n").join([k, e]) for k, e in zip(kinds, evidence, strict=True)]
        columns = [Column("kind, evidence", beneath, wraps=True), *figures]
    table = fitted_table(title, columns, width, EVENT_DROPS)
    judged = "coverage" in events.columns and events["coverage"].notna().any()
    covered = COVERAGE_CAPTION if judged else ""
    more = f"... and {len(events) - limit} more in events.parquet" if len(events) > limit else ""
    table.caption = "; ".join(filter(None, [table.caption, covered, more]))
    return table


COVERAGE_CAPTION = (
    "gap (heard): other vessels near it kept reporting, it likely stopped transmitting; "
    "gap (quiet): they went silent too (coverage)"
)


def _kind(e: Any) -> str:
    """An event's kind as the table names it: a gap with its coverage, where judged."""
    coverage = getattr(e, "coverage", None)
    return f"{e.kind} ({coverage})" if isinstance(coverage, str) else str(e.kind)


def _vessels(e: Any) -> str:
    """The vessel an event names, and how many others (a fleet event's)."""
    named = getattr(e, "others", None)
    others = len(json.loads(named)) if isinstance(named, str) else 0
    return _vessel(e.mmsi, e.name) + (f" and {others} other(s)" if others else "")


METRICS_CAPTION = (
    "overlapped: stretches an event of any / the right kind overlaps; false/100: right events "
    "per 100 normal tracks (any: every event); start err: median reports from the right event's "
    "start to the stretch's; \\[low-high]: 95 % bootstrap intervals"
)
METRICS_DROPS = ("start err", "false/100", "AUC")
"""What `evaluate`'s events table leaves out, in this order, where the terminal is too narrow
(all of it is in evaluation.json)."""


def event_metrics_table(table: pd.DataFrame, width: int = 120) -> Table:
    """`evaluate`'s event metrics (`aisdati.evaluation.metrics.event_metrics`) per detector and
    kind: each share with its 95 % bootstrap interval, the interval beneath its value where the
    width needs it, never cut; `METRICS_DROPS` left out where still needed."""
    rows = table.replace({float("nan"): None}).to_dict("records")
    shares = {
        "any event": ("overlapped_any", "{:.2f}"),
        "right event": ("overlapped", "{:.2f}"),
        "AUC": ("roc_auc", "{:.2f}"),
        "false/100": ("false_events_per_100", "{:.1f}"),
        "start err": ("median_start_error", "{:.0f}"),
    }
    columns = [
        Column("detector", [Text(str(r["detector"])) for r in rows]),
        Column("kind", [Text(str(r["kind"])) for r in rows]),
        Column("n", [Text(str(r["anomalies"])) for r in rows], right=True),
        *(
            Column(name, [Text(_with_ci(r, key, fmt)) for r in rows], right=True, wraps=True)
            for name, (key, fmt) in shares.items()
        ),
    ]
    out = fitted_table("Events on the injected stretches", columns, width, METRICS_DROPS)
    out.caption = "; ".join(filter(None, [out.caption, METRICS_CAPTION]))
    return out


def fleet_table(fleet: dict[str, Any], width: int = 120) -> Table:
    """`evaluate`'s fleet kinds (`aisdati.evaluation.fleet.summary`): per kind (and area), the
    cases found with recall's 95 % interval, and the kind's events per 1,000 vessel-days of
    the untouched later traffic, false or the traffic's own."""
    rows = fleet["rows"]
    columns = [
        Column("kind", [Text(str(r["kind"])) for r in rows]),
        Column("area", [Text(str(r["area"])) for r in rows]),
        Column("cases", [Text(str(r["cases"])) for r in rows], right=True),
        Column("found", [Text(str(r["found"])) for r in rows], right=True),
        Column("recall", [Text(_with_ci(r, "recall", "{:.3f}")) for r in rows], right=True,
               wraps=True),
        Column("per 1,000 vd", [Text(_with_ci(r, "per_1000")) for r in rows], right=True,
               wraps=True),
        Column("events are", [Text("false" if r["false"] else "own") for r in rows]),
    ]  # fmt: skip
    out = fitted_table("Fleet cases constructed in untouched later traffic", columns, width, ())
    words = (
        f"{fleet['cases_asked']} cases asked per kind and seed; per 1,000 vd: the kind's events "
        "on the untouched traffic per 1,000 vessel-days (false: none was written; own: the "
        "traffic's real calls and gaps); [95 % bootstrap interval]"
    )
    out.caption = "; ".join(filter(None, [out.caption, words]))
    return out


def _with_ci(row: dict[str, Any], name: str, fmt: str = "{:.2f}") -> str:
    """`value [low-high]`, '-' where the row has no value."""
    value = row.get(name)
    if value is None:
        return "-"
    low, high = row.get(f"{name}_ci") or (None, None)
    interval = f" [{fmt.format(low)}-{fmt.format(high)}]" if low is not None else ""
    return fmt.format(value) + interval


def _place(lat: float, lon: float) -> str:
    return f"{lat:.4f}, {lon:.4f}"


def _vessel(mmsi: int, name: object) -> str:
    """A vessel as a table names it: its MMSI, and its name where known."""
    return f"{mmsi}" + (f" {name}" if isinstance(name, str) and name else "")


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.0f} min" if seconds < 7200 else f"{seconds / 3600:.1f} h"
