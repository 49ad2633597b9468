"""Options are checked before any work (`aisdati.options`): every float finite and in its
range, every count in its range, one line naming the option; through the real command line
(issue 13, items 5 and 18) and piece by piece."""

from __future__ import annotations

import re

import pytest

from aisdati.errors import UserError
from aisdati.options import check_option, parse_time
from tests.helpers.cli import one_line_error, run
from tests.helpers.ingest import NY_HOUR, ingest
from tests.helpers.models import detect_dati


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


# ------------------------------------------------------------------ 5, 18: float options
@pytest.mark.parametrize(
    "option, value, needle",
    [
        ("--min-sog", "nan", "--min-sog must be a finite number < 102.2, got nan"),
        ("--min-sog", "inf", "--min-sog must be a finite number"),
        ("--max-speed", "nan", "--max-speed must be a finite number > 0, got nan"),
        ("--max-speed", "-5", "--max-speed must be a finite number > 0, got -5"),
        ("--stop-gap", "9" * 400 + "h", "--stop-gap must be a finite number"),
    ],
)
def test_float_options_must_be_finite_and_in_range(cli, data, tmp_path, option, value, needle):
    out = tmp_path / "out"
    result, _ = ingest(cli, out, data / NY_HOUR, extra=("--roi", "none", option, value))
    one_line_error(result, re.escape(needle))
    assert not out.exists()  # checked before any work


# ----------------------------------------------------------------------------- items 5, 18
@pytest.mark.parametrize(
    "extra, needle",
    [
        (("--near-km", "nan"), "--near-km must be a finite number in \\(0, 20037.5\\], got nan"),
        (("--near-km", "inf"), "--near-km must be a finite number .*got inf"),
        (("--threshold", "nan"), "--threshold must be a finite number in \\(0, 1\\], got nan"),
        (("--top-percent", "inf"), "--top-percent must be a finite number .*got inf"),
        (("--top-percent", "-1"), "--top-percent must be a finite number .*got -1"),
    ],
)
def test_detect_float_options(ny_dati, tmp_path, extra, needle):
    result = detect_dati(ny_dati, ny_dati["models"], tmp_path / "r", *extra)
    one_line_error(result, needle)
    assert not (tmp_path / "r").exists()


def test_train_seed_out_of_range(ny_dati, tmp_path):
    result = run("train", "--cluster", "down", "--data", ny_dati["proc"], "--out", tmp_path / "m",
                 "--seed", -1)  # fmt: skip
    one_line_error(result, "--seed must be an integer in \\[0, 4294967295\\], got -1")


@pytest.mark.parametrize(
    "text, expected",
    [
        ("2018-08-01", "2018-08-01T00:00:00+00:00"),
        (" 2018-08-01T06:30 ", "2018-08-01T06:30:00+00:00"),
        ("2018-08-01 06:30:00+02:00", "2018-08-01T04:30:00+00:00"),
        ("2018-08-01T00:00:00Z", "2018-08-01T00:00:00+00:00"),
    ],
)
def test_parse_time_reads_dates_and_iso_times_in_utc(text, expected):
    assert parse_time(text, "--since").isoformat() == expected


@pytest.mark.parametrize("text", ["now", "07/08/2018", "2018-13-01", "2018-02-30", "", "2018"])
def test_parse_time_refuses_what_is_no_iso_time(text):
    with pytest.raises(UserError, match=r"--until .*expected a date or an ISO 8601 time"):
        parse_time(text, "--until")
