"""Labels for `aisdati detect --labels`: reading and checking the CSV, matching its rows to the
scored tracks, and the metrics of the flags and scores against them, overall and per kind.

Three layouts, told apart by their columns (names are case-insensitive; other columns are
ignored):

- `track_id,label[,kind]`: one row per track of the ingest (as `aisdati evaluate` writes).
- `mmsi,start,label[,kind]`: the track of that vessel whose first report is within `MATCH_S`
  of `start`.
- `mmsi,start,end[,kind][,label]`: an incident list (e.g. coast-guard reports of route
  deviations or loss of propulsion: vessel, incident window, type). A scored track is positive
  where its time span, first to last report, overlaps a window of its vessel; every other scored
  track counts as normal (an incident list names what went wrong, so the rest is taken as
  normal). `label` defaults to 1; a window with label 0 marks a known-normal stretch.

Times are ISO 8601; one without a zone is read as UTC. With a `kind` column, the metrics are
also given per kind (the positives of that kind against every normal track). A track matched by
rows with different labels is refused (naming both rows), never decided by row order.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from aisdati.errors import UserError
from aisdati.metrics import flagging, ranking, weighted_f1
from aisdati.options import ISO_TIME
from aisdati.tracks.ashore import AshoreCheck
from aisdati.tracks.store import Track

MATCH_S = 60
"""A label given by MMSI and start matches the track of that vessel starting within this many
seconds."""

LAYOUTS = {
    "track_id": "track_id,label[,kind]",
    "mmsi_start": "mmsi,start,label[,kind]",
    "window": "mmsi,start,end[,kind][,label]",
}


@dataclass(frozen=True)
class Labels:
    """The checked rows of a labels file: the key columns of its layout, `label` (0/1) and
    `kind` ('' where none is given)."""

    rows: pd.DataFrame
    layout: str
    path: Path


@dataclass(frozen=True)
class Matched:
    """Per scored track its label (-1: none) and kinds; per label row whether it matched."""

    label: np.ndarray
    kinds: list[frozenset[str]]
    row_matched: np.ndarray


def _layout(columns: set[str], path: Path) -> str:
    if "track_id" in columns:
        layout = "track_id"
    elif {"mmsi", "start", "end"} <= columns:
        layout = "window"
    elif {"mmsi", "start"} <= columns:
        layout = "mmsi_start"
    else:
        raise UserError(
            f"{path}: needs a 'track_id' column, or 'mmsi' and 'start' (and 'end' for incident "
            f"windows) columns; expected {' or '.join(LAYOUTS.values())}"
        )
    if layout != "window" and "label" not in columns:
        raise UserError(f"{path}: no 'label' column (expected {LAYOUTS[layout]})")
    return layout


def read_labels(path: Path) -> Labels:
    """Every value is checked here, before any work, and the first bad one is named with its row:
    ids must be integers (track ids >= 0 and within int64, MMSIs positive), times times (a
    window's end not before its start), labels 0 or 1, and one key may not get two labels."""
    if not path.is_file():
        raise UserError(f"labels file not found: {path}")
    try:
        raw = pd.read_csv(path, dtype=str, keep_default_na=False, encoding="utf-8")
    except (ValueError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read labels {path}: {str(exc).splitlines()[0]}") from None
    raw.columns = [str(c).strip().lower() for c in raw.columns]
    layout = _layout(set(raw.columns), path)
    if raw.empty:
        raise UserError(f"{path}: the file holds no labels")
    rows = pd.DataFrame(index=raw.index)
    if layout == "track_id":
        rows["track_id"] = _label_ints(raw["track_id"], "track_id", 0, 2**63 - 1, path)
    else:
        rows["mmsi"] = _label_ints(raw["mmsi"], "mmsi", 1, 2**53, path)
        rows["start"] = _label_times(raw["start"], "start", path)
    if layout == "window":
        rows["end"] = _label_times(raw["end"], "end", path)
        before = rows["end"] < rows["start"]
        if before.any():
            row = int(np.flatnonzero(before.to_numpy())[0])
            raise UserError(f"{path}: row {row + 1}: the window ends before it starts")
    rows["label"] = _label_values(raw["label"], path) if "label" in raw else 1
    rows["kind"] = raw["kind"].str.strip() if "kind" in raw else ""
    if layout != "window":
        _refuse_conflicts(rows, ["track_id"] if layout == "track_id" else ["mmsi", "start"], path)
    return Labels(rows, layout, path)


def _refuse_conflicts(rows: pd.DataFrame, keys: list[str], path: Path) -> None:
    conflict = rows.groupby(keys)["label"].nunique() > 1
    if conflict.any():
        key = conflict.index[np.flatnonzero(conflict.to_numpy())[0]]
        raise UserError(f"{path}: {'/'.join(keys)} {key} has both labels 0 and 1")


def _shown(value: Any) -> str:
    text = repr(str(value))
    return text if len(text) <= 40 else text[:37] + "..."


def _label_values(values: pd.Series, path: Path) -> pd.Series:
    text = values.str.strip()
    bad = ~text.isin(["0", "1", "0.0", "1.0"])
    if bad.any():
        row = int(np.flatnonzero(bad.to_numpy())[0])
        raise UserError(
            f"{path}: row {row + 1}: label must be 0 or 1, got {_shown(values.iloc[row])}"
        )
    return text.str[0].astype(int)


def _label_ints(values: pd.Series, column: str, low: int, high: int, path: Path) -> pd.Series:
    """A column of integer ids (written as 12 or 12.0) within [low, high], or a `UserError`
    naming the first row that is not one."""
    out = np.zeros(len(values), dtype=np.int64)
    for row, value in enumerate(values.to_numpy()):
        match = re.fullmatch(r"\s*\+?(\d{1,30})(?:\.0*)?\s*", value)
        number = int(match[1]) if match else None
        if number is None or not low <= number <= high:
            raise UserError(
                f"{path}: row {row + 1}: {column} must be an integer in [{low}, {high}], "
                f"got {_shown(value)}"
            )
        out[row] = number
    return pd.Series(out, index=values.index)


def _label_times(values: pd.Series, column: str, path: Path) -> pd.Series:
    """A column of times (ISO 8601; with a zone, or UTC), or a `UserError` naming the first row
    that is not one."""
    text = values.astype(str).str.strip()
    times = pd.to_datetime(text, utc=True, errors="coerce", format="ISO8601")
    times[~text.str.fullmatch(ISO_TIME)] = pd.NaT
    if times.isna().any():
        row = int(np.flatnonzero(times.isna().to_numpy())[0])
        raise UserError(
            f"{path}: row {row + 1}: {column} must be a time (ISO 8601, UTC unless a zone is "
            f"given), got {_shown(values.iloc[row])}"
        )
    return times


def _utc(stamp: Any) -> pd.Timestamp:
    t = pd.Timestamp(stamp)
    return t.tz_localize("UTC") if t.tzinfo is None else t.tz_convert("UTC")


def _span(track: Track) -> tuple[pd.Timestamp, pd.Timestamp]:
    start = _utc(track.start)
    return start, start + pd.to_timedelta(float(np.sum(track.dts)), unit="h")


def _candidates(labels: Labels, track: Track) -> np.ndarray:
    """Positions of the label rows that name this track."""
    rows = labels.rows
    if labels.layout == "track_id":
        return np.flatnonzero(rows["track_id"].to_numpy() == track.track_id)
    same = rows["mmsi"].to_numpy() == track.mmsi
    start, end = _span(track)
    if labels.layout == "mmsi_start":
        near = (rows["start"] - start).abs().dt.total_seconds().to_numpy() <= MATCH_S
        return np.flatnonzero(same & near)
    overlap = (rows["start"] <= end).to_numpy() & (rows["end"] >= start).to_numpy()
    return np.flatnonzero(same & overlap)


def match_labels(scores: pd.DataFrame, tracks: Sequence[Track], labels: Labels) -> Matched:
    """The label and kinds of every scored track (in `scores`' order). Rows with different
    labels for one track are refused; an incident list labels every track (0 where no window
    overlaps it)."""
    by_id = {t.track_id: t for t in tracks}
    values = labels.rows["label"].to_numpy()
    kinds_of = labels.rows["kind"].to_numpy()
    out = np.full(len(scores), 0 if labels.layout == "window" else -1)
    kinds: list[frozenset[str]] = []
    matched = np.zeros(len(labels.rows), dtype=bool)
    for i, tid in enumerate(scores["track_id"].to_numpy()):
        hits = _candidates(labels, by_id[int(tid)])
        matched[hits] = True
        found = sorted(set(values[hits].tolist()))
        if len(found) > 1:
            a, b = (int(hits[values[hits] == v][0]) + 1 for v in found)
            raise UserError(
                f"{labels.path}: rows {a} and {b} both match track {int(tid)} with labels 0 and 1"
            )
        if found:
            out[i] = found[0]
        kinds.append(
            frozenset(k for k, v in zip(kinds_of[hits], values[hits], strict=True) if k and v)
        )
    if not (out >= 0).any() or (labels.layout == "window" and not matched.any()):
        raise UserError(
            f"the labels match no test track (check {LAYOUTS[labels.layout].split('[')[0]})"
        )
    return Matched(out, kinds, matched)


def label_metrics(y: np.ndarray, flagged: np.ndarray, score: np.ndarray) -> dict[str, Any]:
    """Precision and recall of the anomaly class, weighted F1 (the paper's metric: per-class F1
    weighted by class support), the share of normal tracks flagged (the false-alarm rate a
    calibrated threshold promises) and ROC AUC of the normalised score (tracks ashore first)."""
    y, p = np.asarray(y, int), np.asarray(flagged, int)
    anomaly = flagging(y, p)
    return {
        "labelled_tracks": len(y),
        "anomalies_labelled": int(y.sum()),
        "flagged": anomaly["flagged"],
        "precision": anomaly["precision"],
        "recall": anomaly["recall"],
        "f1_weighted": weighted_f1(y, p),
        "false_alarm_rate": anomaly["false_alarm_rate"],
        "roc_auc": ranking(y, score)["roc_auc"],
    }


def kind_metrics(
    y: np.ndarray, kinds: Sequence[frozenset[str]], flagged: np.ndarray, score: np.ndarray
) -> dict[str, dict[str, Any]]:
    """Per kind: how many labelled anomalies of that kind, how many of them were flagged
    (recall), and how well the score ranks them above the normal tracks (ROC AUC, average
    precision of that kind against the normal tracks only)."""
    y, flagged, score = np.asarray(y, int), np.asarray(flagged, bool), np.asarray(score, float)
    normal = y == 0
    out = {}
    for kind in sorted({k for ks in kinds for k in ks}):
        mine = np.array([kind in ks for ks in kinds]) & (y == 1)
        keep = mine | normal
        out[kind] = {
            "anomalies": int(mine.sum()),
            "flagged": int((flagged & mine).sum()),
            "recall": float((flagged & mine).sum() / max(int(mine.sum()), 1)),
            **ranking(mine[keep].astype(int), score[keep]),
        }
    return out


def evaluate_labels(scores: pd.DataFrame, tracks: Sequence[Track], path: Path) -> dict[str, Any]:
    """metrics.json: `label_metrics` of the scored tracks that the labels in `path` name, per
    kind where the file gives kinds, and how many label rows matched no scored track."""
    labels = read_labels(path)
    matched = match_labels(scores, tracks, labels)
    keep = matched.label >= 0
    flagged = scores["flagged"].to_numpy()[keep]
    ranked = AshoreCheck().ranked(scores["score"], scores["ashore_reports"], scores["n_points"])
    score = ranked[keep]
    metrics = label_metrics(matched.label[keep], flagged, score)
    kept_kinds = [k for k, m in zip(matched.kinds, keep, strict=True) if m]
    if (labels.rows["kind"] != "").any():
        metrics["by_kind"] = kind_metrics(matched.label[keep], kept_kinds, flagged, score)
    metrics["labels_file"] = str(path)
    metrics["labels_layout"] = LAYOUTS[labels.layout]
    metrics["label_rows"] = len(labels.rows)
    metrics["labels_unmatched"] = int((~matched.row_matched).sum())
    return metrics
