"""What the commands print (`aisdati.commands.tables`): paths that hold rich markup are printed
as they are (issue 27, item 14); every figure whole at 80 and 120 columns (issue 69, item 3)."""

from __future__ import annotations

import io
from pathlib import Path

import pandas as pd
import pytest
from rich.console import Console

from aisdati.commands.tables import detection_table, event_metrics_table, events_table
from tests.helpers.cli import run
from tests.helpers.models import INGEST, detect_args, evaluate_args, train_ny_nearest

NY_HOUR = Path(__file__).parents[1] / "data" / "NYHarbor_2020_06_30_first_hour.csv"


def printed(result, text: str) -> bool:
    """Whether `text` (a path) is in what the command printed, however rich wrapped it."""
    return text in result.output.replace("\n", "")


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """The NY hour ingested (tracks of >= 30 reports) and a `nearest` model of its `down`."""
    return train_ny_nearest(tmp_path_factory.mktemp("outputs"))


# --------------------------------------------------------------------------------- item 14
@pytest.mark.parametrize("name", ["a[/]b", "r[x]", "[bold]c"])
def test_paths_with_rich_markup_are_printed_as_they_are(world, tmp_path, name):
    out = tmp_path / name
    result = run(*detect_args(world, out))
    assert result.exit_code == 0, result.output
    assert printed(result, str(out)), result.output
    models = tmp_path / f"models{name}"
    result = run(
        "train", "--cluster", "down", "--method", "nearest", "--data", world["proc"],
        "--out", models,
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert printed(result, str(models / "down-nearest")), result.output
    proc = tmp_path / f"proc{name}"
    result = run("ingest", "--input", NY_HOUR, *INGEST, "--out", proc)
    assert result.exit_code == 0, result.output
    assert printed(result, str(proc / "points.parquet")), result.output


def test_an_evaluate_folder_with_rich_markup_is_printed_as_it_is(kitimat, tmp_path):
    out = tmp_path / "e[/]v[x]"
    result = run(*evaluate_args(kitimat, out))
    assert result.exit_code == 0, result.output
    assert printed(result, str(out)), result.output


# ------------------------------------------------------------------ issue 69, item 3: 80 columns
KINDS = ["position-jump", "course-inconsistent", "sudden-speed-change", "gap", "off-traffic"]


def _scores() -> pd.DataFrame:
    """Ranked tracks at their widest: 9-digit MMSIs and long names, several models, reports
    ashore, two kinds on a track."""
    n = 6
    return pd.DataFrame(
        {
            "track_id": range(100, 100 + n),
            "mmsi": [100001468 + 7 * k for k in range(n)],
            "name": ["NORTHERN EXPEDITION", None, "SEASPAN RELIANT", "", "X", "CAPE FLATTERY"],
            "model": ["all-bc", "route-2-bc", "all-bc", "route-12-nearest", "all-bc", "all-bc"],
            "score": [12345.6, 9876.5, 5000.0, 4200.0, 3100.0, 100.0],
            "threshold": [3680.0] * n,
            "flagged": [True] * 5 + [False],
            "rank": range(1, n + 1),
            "max_dev_m": [14310.0, 20570.0, 2880.0, 4470.0, 900.0, 10.0],
            "max_dev_lat": [52.7576, 52.9652, -33.9176, 53.7077, 0.5, 1.25],
            "max_dev_lon": [-128.77, -129.9391, 151.2698, -129.7231, -0.5, 179.999],
            "ashore_reports": [0, 12, 0, 0, 0, 0],
            "event_kinds": [", ".join(KINDS[:2]), "position-jump", "", KINDS[2], "gap", ""],
        }
    )


def _events() -> pd.DataFrame:
    n = len(KINDS)
    return pd.DataFrame(
        {
            "kind": KINDS,
            "class": ["alert"] * 3 + ["activity", "alert"],
            "mmsi": [100001468 + 7 * k for k in range(n)],
            "name": ["NORTHERN EXPEDITION", None, "SEASPAN RELIANT", "", "X"],
            "start": pd.to_datetime(
                ["2018-08-19 06:21:00", "2018-08-31 05:09:07", "2018-08-01 22:57:00"] * 2, utc=True
            )[:n],
            "duration_s": [9360.0, 7200.0, 360.0, 71000.0, 59.0],
            "lat": [53.0713, 52.6576, -33.9176, 53.4294, 0.5],
            "lon": [-129.2469, -128.9719, 151.2698, -128.5055, -179.9999],
            "strength": [2.05, 1.44, 1.11, 23.6, 1.02],
            "rarity_days": [900.0, 400.0, 120.0, None, 50.0],
            "evidence": ["moved 3,160 m off its reported motion for 32 reports (107 min), and back"]
            * n,
        }
    )


def _rendered(table, width: int) -> list[str]:
    console = Console(width=width, record=True, file=io.StringIO())
    console.print(table)
    lines = console.export_text().splitlines()
    assert max(map(len, lines)) <= width, "\n".join(lines)
    return lines


def _places(lat: pd.Series, lon: pd.Series) -> list[str]:
    return [f"{a:.4f}, {o:.4f}" for a, o in zip(lat, lon, strict=True)]


def _whole(lines: list[str], figures: list[str]) -> None:
    """Every figure on one line of the table as printed."""
    missing = [f for f in figures if not any(f in line for line in lines)]
    assert not missing, f"split or cut: {missing}\n" + "\n".join(lines)


@pytest.mark.parametrize("width", [80, 120])
def test_the_ranked_tracks_print_every_figure_whole(width):
    scores = _scores()
    lines = _rendered(detection_table(scores, "lane", width=width), width)
    scores = scores[scores.flagged]  # what the table shows
    places = _places(scores.max_dev_lat, scores.max_dev_lon)
    scored = [f"{s / 1000:,.2f}" for s in scores.score]
    _whole(lines, [*map(str, scores.mmsi), *places, *scored, *map(str, scores.track_id)])
    _whole(lines, KINDS[:3])
    if width == 120:
        _whole(lines, ["3.68", "route-12-nearest"])
    else:  # left out whole, in the stated order, and said so
        assert "left out at 80 columns: max km, threshold, rank, model" in " ".join(
            " ".join(lines).split()
        )


@pytest.mark.parametrize("width", [80, 120])
def test_the_events_print_every_figure_whole(width):
    events = _events()
    lines = _rendered(events_table(events, width=width), width)
    times = [f"{t:%Y-%m-%d %H:%M:%S}" for t in events.start]
    places = _places(events.lat, events.lon)
    _whole(lines, [str(m) for m in events.mmsi] + times + places + KINDS + ["2.6 h", "19.7 h"])
    _whole(lines, ["3,160", "(107"])  # the evidence wraps at spaces, each word whole
    if width == 120:
        _whole(lines, ["23.60", "2.05"])


@pytest.mark.parametrize("width", [80, 120])
def test_evaluate_event_intervals_are_never_cut(width):
    shares = ("overlapped_any", "overlapped", "roc_auc", "false_events_per_100")
    row = {name: 0.875 for name in shares} | {f"{s}_ci": [0.8125, 0.9375] for s in shares}
    frame = pd.DataFrame(
        [
            {"detector": detector, "kind": kind, "anomalies": 120, **row,
             "median_start_error": 3.0, "median_start_error_ci": [1.0, 12.0]}
            for detector in ("bc", "nearest") for kind in ("course-noise", "detour+jump+loiter")
        ]
    )  # fmt: skip
    lines = _rendered(event_metrics_table(frame, width), width)
    text = "\n".join(lines)
    assert "..." not in text and "…" not in text
    _whole(lines, ["120", "[0.81-0.94]", "detour+jump+loiter", "course-noise"])
    if width == 120:
        _whole(lines, ["[0.8-0.9]", "[1-12]"])
    else:
        assert "left out at 80 columns: start err, false/100;" in " ".join(text.split())
