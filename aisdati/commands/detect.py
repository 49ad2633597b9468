"""`aisdati detect`: score test tracks against trained models, write the report, print the
flagged tracks (and, with hand labels, how well they were found)."""

from __future__ import annotations

import json
from dataclasses import replace
from datetime import datetime
from pathlib import Path

from rich.markup import escape

from aisdati.ais.card import unfinished_models
from aisdati.commands.common import console, shows_progress, spinner, warn
from aisdati.commands.options import DetectOptions
from aisdati.commands.tables import detection_table, events_table
from aisdati.detection.outputs import (
    OUTPUTS,
    REPORT,
    report_dict,
    write_event_outputs,
    write_outputs,
)
from aisdati.detection.run import (
    Coverage,
    Detection,
    DetectSettings,
    check_settings,
    detect,
    events_only,
    with_own_method,
)
from aisdati.detectors import parse_detectors
from aisdati.detectors.registry import check_model_names
from aisdati.errors import UserError
from aisdati.execution import Execution, open_runner, resolve_device
from aisdati.options import check_options
from aisdati.outdir import removed_if_left_empty, same_folder, staged_outputs
from aisdati.storage import fetched_models, is_url, shown_folder
from aisdati.tracks.ashore import AshoreCheck


def run(o: DetectOptions) -> None:
    """`aisdati detect` with its options (`aisdati.commands.options.DetectOptions`)."""
    if o.models_dir.strip().lower() == NO_MODEL:
        run_events_only(o)
        return
    settings = detect_settings(o)
    execution = Execution.parse(o.workers)
    with (
        removed_if_left_empty(settings.out_dir),
        fetched_models(o.models_dir, settings.models, "--models") as local,  # a URL: a copy
        open_runner(execution) as runner,  # before the outputs: a cluster out of reach
        staged_outputs(settings.out_dir, OUTPUTS, REPORT) as outputs,
    ):
        shown = shown_folder(o.models_dir)
        settings = with_own_method(replace(settings, models_dir=local, models_shown=shown))
        for message in unfinished_models(local, settings.models, settings.method):
            warn(message)
        where = f"scoring on {execution.describe()}" if execution.distributed else "scoring"
        with spinner(console, where, show=shows_progress(o.as_json)):
            result = detect(settings, runner)
            for note in result.notes:
                warn(note)
            files = [outputs.final(f) for f in write_outputs(result, outputs.folder, runner)]
        outputs.commit()
    if o.as_json:
        doc = {**report_dict(result), "files": [str(f) for f in files]}
        print(json.dumps(doc, default=str))
    else:
        print_detection(result, files, settings.out_dir)


NO_MODEL = "none"
"""`--models none`: the events that need no model, over every report."""


def run_events_only(o: DetectOptions) -> None:
    """`detect --models none`: the model-free events of every report of --data."""
    out = o.out or Path("reports") / f"{datetime.now():%Y%m%d-%H%M%S}"
    with (
        removed_if_left_empty(out),
        staged_outputs(out, OUTPUTS, REPORT) as outputs,
    ):
        with spinner(console, "finding events", show=shows_progress(o.as_json)):
            result = events_only(o.data, o.ports)
            files = [outputs.final(f) for f in write_event_outputs(result, outputs.folder)]
        outputs.commit()
    if o.as_json:
        print(json.dumps({**report_dict(result), "files": [str(f) for f in files]}, default=str))
        return
    console.print(events_table(result.events, width=console.width))
    console.print(
        f"{result.reports_judged:,} reports judged, no model (--models none: the kinds that "
        f"need one are left out); wrote {escape(', '.join(f.name for f in files))} to "
        f"[bold]{escape(str(out))}[/]",
        highlight=False,
    )


def detect_settings(o: DetectOptions) -> DetectSettings:
    """The library's settings of the command's options, checked before any work."""
    check_model_names(o.model or ())
    if o.out is not None and not is_url(o.models_dir) and same_folder(o.out, o.models_dir):
        raise UserError(f"--out {o.out} is the model folder: give the report a folder of its own")
    check_options(
        {
            "--threshold": o.threshold,
            "--top-percent": o.top_percent,
            "--contamination": o.contamination,
            "--near-km": o.near_km,
        }
    )
    settings = DetectSettings(
        data_dir=o.data,
        models_dir=Path(o.models_dir),
        out_dir=o.out or Path("reports") / f"{datetime.now():%Y%m%d-%H%M%S}",
        models=tuple(o.model or ()),
        method=parse_detectors(o.method)[0] if o.method else None,
        cluster=o.cluster.strip().lower(),
        track_ids=tuple(o.track or ()),
        score=o.score.strip().lower() if o.score is not None else None,
        ashore=o.ashore,
        threshold=o.threshold,
        top_percent=o.top_percent,
        contamination=o.contamination,
        near_km=o.near_km,
        alerts_per_1000=o.alerts_per_1000,
        ports=o.ports,
        labels=o.labels,
        device=resolve_device(o.device),
    )
    check_settings(settings)
    return settings


SHOWN_IDS = 8
"""Ids of tracks not judged named on the terminal (all are in report.json)."""


def coverage_line(coverage: Coverage) -> str:
    """`all 24 tracks judged (all-bc: 24); 134 training tracks of the models left out`, or
    `judged 221 of 225 tracks (...); not judged: 4, no model covers its start and end (...):
    tracks 17, 19, ...`: what judged each track, or why none did."""
    by = ", ".join(f"{escape(k)}: {v}" for k, v in coverage.judged_by.items())
    if coverage.judged == coverage.candidates:
        text = f"all {coverage.judged} tracks judged ({by})"
    else:
        text = f"judged {coverage.judged} of {coverage.candidates} tracks ({by})"
    if coverage.training:
        text += f"; {len(coverage.training)} training tracks of the models left out"
    for reason, ids in coverage.not_judged.items():
        shown = ", ".join(str(i) for i in ids[:SHOWN_IDS]) + (
            ", ..." if len(ids) > SHOWN_IDS else ""
        )
        text += f"; [yellow]not judged: {len(ids)}, {escape(reason)}[/]: tracks {shown}"
    return text


def print_detection(result: Detection, files: list[Path], out: Path) -> None:
    """The flagged tracks, the scores against hand labels if given, and what was written."""
    rule = result.settings.rule if result.settings else "calibrated"
    console.print(detection_table(result.scores, result.score, rule, width=console.width))
    console.print(events_table(result.events, width=console.width))
    if result.coverage is not None:
        console.print(coverage_line(result.coverage), highlight=False)
    check = AshoreCheck()
    ashore = int(check.flags(result.scores["ashore_reports"]).sum())
    if ashore:
        console.print(
            f"{ashore} flagged for reports ashore (at least {check.min_reports} reports "
            f"{check.margin_m:g} m or more inland, whatever the score; lakes and rivers above "
            "the tidal limit count as land unless the training tracks sailed there; "
            "--no-ashore: the model alone)",
            highlight=False,
        )
    if result.metrics is not None:
        m = result.metrics
        auc = "n/a (one class only)" if m["roc_auc"] is None else f"{m['roc_auc']:.3f}"
        console.print(
            f"against {m['labelled_tracks']} labelled tracks ({m['anomalies_labelled']} "
            f"anomalies): precision {m['precision']:.3f}, recall {m['recall']:.3f}, "
            f"weighted F1 {m['f1_weighted']:.3f} (paper: 0.78), ROC AUC {auc}",
            highlight=False,
        )
    t = result.timings
    console.print(
        f"scoring {t['score_s']:.1f} s; "
        f"wrote {escape(', '.join(f.name for f in files if f.parent == out))}"
        f"{' and evidence/' if any(f.parent != out for f in files) else ''} "
        f"to [bold]{escape(str(out))}[/]",
        highlight=False,
    )
