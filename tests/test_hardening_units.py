"""Hardening (issue 13), piece by piece: the option ranges, the line guard against pyarrow's own
CSV reader, numeric times in every unit, and the model card validator."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pyarrow as pa
import pyarrow.csv as pcsv
import pytest

from aisdati.ais.card import training_mask, validate_ais_card
from aisdati.errors import UserError
from aisdati.options import check_option
from aisdati.preprocess.read import LineGuard, _to_time

ROWS = b"".join(b"%d,x%d,z\n" % (i, i) for i in range(200))


@pytest.mark.parametrize(
    "name, value, ok",
    [
        ("--near-km", 10.0, True),
        ("--near-km", float("nan"), False),
        ("--near-km", 0.0, False),
        ("--threshold", 1.0, True),
        ("--threshold", 1.0000001, False),
        ("--min-sog", -1.0, True),  # negative keeps every SOG, even 0, as before
        ("--min-sog", float("-inf"), False),
        ("--top-percent", None, True),  # an option left unset
        ("--seed", 0, True),
        ("--seed", 2**32, False),
        ("--anything-else", float("inf"), False),  # any float must at least be finite
    ],
)
def test_option_ranges(name, value, ok):
    if ok:
        check_option(name, value)
    else:
        with pytest.raises(UserError, match=f"^{name} must be"):
            check_option(name, value)


def _pyarrow_rows(data: bytes) -> tuple[int, int]:
    """(rows, malformed rows) as pyarrow reads `data` (three columns, no header)."""
    bad: list[str] = []

    def skip(row):
        bad.append(row.text)
        return "skip"

    table = pcsv.read_csv(
        io.BytesIO(data),
        read_options=pcsv.ReadOptions(column_names=["a", "b", "c"]),
        parse_options=pcsv.ParseOptions(invalid_row_handler=skip),
        convert_options=pcsv.ConvertOptions(column_types={k: pa.string() for k in "abc"}),
    )
    return table.num_rows, len(bad)


TRICKY = [
    b'1,"unterminated,z',
    b'1,"a""b,z',  # an escaped quote, then no closing one
    b'1,"a"",z',
    b'1,x"y,"z',  # a literal quote, then one that opens the last field
    b'"a"x","b',  # after a closing quote, a quote is literal
    b'1,"ok""",z',
    b'1,"ab"c"d,z',
    b'1,"x,y",z',
    b'1,ab"c,z',
    b'1,"",z',
    b'1,""",z',
]


@pytest.mark.parametrize("line", TRICKY)
def test_the_guard_cuts_exactly_the_lines_pyarrow_would_run_on_with(line):
    """pyarrow carries an open quote over the following lines (rows vanish); the guard must cut
    those lines, and only those, so that every other row stays."""
    data = line + b"\n" + ROWS
    rows, malformed = _pyarrow_rows(data)
    swallows = rows + malformed < 201
    cut: list[str] = []
    guard = LineGuard(io.BytesIO(b"h1,h2,h3\n" + data), cut.append)
    cleaned = b"".join(iter(lambda: guard.read(1 << 16), b""))
    assert (cut == [line.decode()]) == swallows
    rows_after, malformed_after = _pyarrow_rows(cleaned)
    assert rows_after + malformed_after + len(cut) == 201
    assert rows_after >= 200


def test_the_guard_passes_clean_files_unchanged(data):
    raw = (data / "noaa_2023-01-11_1000rows.csv").read_bytes()
    guard = LineGuard(io.BytesIO(raw), pytest.fail)
    assert b"".join(iter(lambda: guard.read(4096), b"")) == raw.split(b"\n", 1)[1]


def test_numeric_times_in_every_unit():
    t = 1_593_475_200  # 2020-06-30T00:00:00Z
    arr = pa.array([t, t * 1_000, t * 1_000_000, t * 1_000_000_000, 5, None], pa.int64())
    us, bad = _to_time(arr)
    assert list(us[:4]) == [t * 1_000_000] * 4
    assert list(bad) == [False, False, False, False, True, False]  # 1970 is no AIS time
    us, bad = _to_time(pa.array([str(t), "2020-06-30T00:00:00", "20200630", "soon"]))
    assert list(us[:3]) == [t * 1_000_000] * 3 and list(bad) == [False, False, False, True]
    us, bad = _to_time(pa.array([t + 0.5, float("nan")]))
    assert us[0] == t * 1_000_000 + 500_000 and list(bad) == [False, True]


def _card() -> dict:
    return {
        "format": "aisdati-dati/1", "kind": "ais", "state_dim": 2, "decision_dim": 3,
        "seeds": [0], "cluster": "up", "seed": 0, "epsilon_m": 500.0,
        "config": {"noise": "gaussian", "noise_sigma": 0.3, "ou_theta": 0.15, "ou_dt": 0.01,
                   "network": {"latent_dim": 64}},
        "rule": {"max_sog_kn": 20.0, "max_dt_h": 0.1, "cog_center_deg": 10.0},
        "region": {"lon": [-80.0, -79.0], "lat": [25.0, 26.0]},
        "data": {"track_ids": [4, 7], "points": 900, "start_points": [[-79.5, 25.5], [-79.6, 25.4]],
                 "track_keys": [[366000001, "2015-01-01T00:00:00+00:00",
                                 "2015-01-01T05:00:00+00:00"],
                                [366000002, "2015-01-02T00:00:00+00:00",
                                 "2015-01-02T04:00:00+00:00"]]},
        "training": {"finished": True, "episodes_run": 3},
    }  # fmt: skip


def test_a_valid_card_passes_and_keys_match_by_vessel_and_overlap():
    import pandas as pd

    card = validate_ais_card(_card(), Path("up.json"))
    tracks = pd.DataFrame(
        {
            "track_id": [0, 1, 2, 3],
            "mmsi": [366000001, 366000001, 366000002, 366000003],
            "start": pd.to_datetime(
                ["2015-01-01T00:10", "2015-01-01T06:00", "2015-01-01T23:00", "2015-01-02T01:00"],
                utc=True,
            ),
            "end": pd.to_datetime(
                ["2015-01-01T04:50", "2015-01-01T09:00", "2015-01-02T02:00", "2015-01-02T03:00"],
                utc=True,
            ),
        }
    )
    # ids 4 and 7 are nowhere; by vessel and time: track 0 (inside the first training track's
    # span) and track 2 (overlaps the second's); not the later voyage 1, nor another vessel's 3
    assert list(training_mask(card, tracks)) == [True, False, True, False]
    del card["data"]["track_keys"]
    tracks["track_id"] = [4, 5, 6, 7]
    assert list(training_mask(card, tracks)) == [True, False, False, True]


def test_the_state_width_must_match_the_lane_configuration():
    card = _card()
    card["lane_config"] = {"state": "motion", "fourier": 3}
    with pytest.raises(UserError, match="state_dim must be one of 17, got 2"):
        validate_ais_card(json.loads(json.dumps(card)), Path("up.json"))
    card["state_dim"] = 17
    validate_ais_card(json.loads(json.dumps(card)), Path("up.json"))
    card["lane_config"]["fourier"] = 2.5
    with pytest.raises(UserError, match=r"lane_config\.fourier must be an integer"):
        validate_ais_card(json.loads(json.dumps(card)), Path("up.json"))


@pytest.mark.parametrize(
    "path, value, message",
    [
        (
            ("rule", "max_sog_kn"),
            -3,
            "rule.max_sog_kn must be a finite number in (0, 1000], got -3",
        ),
        (("rule", "max_dt_h"), True, "rule.max_dt_h must be a finite number"),
        (("seeds",), [0, 1], "seeds must be a list of 1, got 2 items"),
        (("kind",), "synthetic", "is not an AIS model card"),
    ],
)
def test_card_errors_name_the_field(path, value, message):
    card = _card()
    node = card
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    with pytest.raises(UserError) as err:
        validate_ais_card(json.loads(json.dumps(card)), Path("models/up.json"))
    assert message in str(err.value) and "\n" not in str(err.value)
