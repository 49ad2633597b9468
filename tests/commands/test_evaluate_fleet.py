"""`aisdati evaluate` measures the fleet kinds on the real Kitimat traffic, forward in time:
cases constructed in the untouched traffic from `--before` on are found, and the kinds' events
on that traffic are counted per 1,000 vessel-days, with intervals, in evaluation.json and the
printed table."""

from __future__ import annotations

import json

KINDS = ("encounter", "identity-conflict", "identity-change", "gap-heard")


def test_evaluate_finds_fleet_cases_and_counts_the_untouched_events(cli, kitimat, tmp_path):
    out = tmp_path / "ev"
    r = cli("evaluate", "--data", kitimat, "--cluster", "other", "--detectors", "nearest",
            "--kinds", "detour", "--before", "2018-08-01", "--fleet-kinds", ",".join(KINDS),
            "--fleet-cases", "4", "--out", out)  # fmt: skip
    assert r.exit_code == 0, r.output
    assert "Fleet cases constructed in untouched later traffic" in r.output
    assert "kitimat" in r.stderr and "seed 0:" in r.stderr  # the progress, per seed
    fleet = json.loads((out / "evaluation.json").read_text())["fleet"]
    assert fleet["kinds"] == list(KINDS) and fleet["seeds"] == [0]
    rows = {row["kind"]: row for row in fleet["rows"]}
    assert set(rows) == set(KINDS)
    for kind, row in rows.items():
        assert 1 <= row["cases"] <= 4 and row["found"] >= 1, row  # real traffic offers each
        low, high = row["recall_ci"]
        assert low <= row["recall"] <= high and row["recall"] == row["found"] / row["cases"]
        assert row["vessel_days"] > 0
        per = 1000 * row["events"] / row["vessel_days"]
        assert abs(row["per_1000"] - per) < 1e-9, row  # every event, over every vessel-day
        low, high = row["per_1000_ci"]
        assert low <= row["per_1000"] <= high
        assert row["false"] == (kind != "gap-heard"), kind  # a gap is the traffic's own
    assert len({row["vessel_days"] for row in rows.values()}) == 1  # one untouched traffic

