"""The per-stage counts (`aisdati.preprocess.report`): a run that keeps no report fails and says
where every row went (issue 13, item 6); one that keeps reports but no track writes them to
judge and warns."""

from __future__ import annotations

import re

import pandas as pd

from tests.helpers.cli import one_line_error
from tests.helpers.ingest import NY_HOUR, NY_ROWS, ingest, leftovers


# ------------------------------------------------------------------------ 6: zero tracks
def test_a_run_that_keeps_no_report_fails_and_says_where_the_rows_went(cli, data, tmp_path):
    out = tmp_path / "out"
    result, _ = ingest(cli, out, data / NY_HOUR, extra=("--min-points", "20"))  # Florida Straits
    one_line_error(result, f"no track kept: {NY_ROWS:,} rows read, rejected: outside_roi ")
    where = re.search(r"rejected: (.*); nothing written", result.stderr.replace("\n", " "))[1]
    counts = {r: int(n.replace(",", "")) for r, n in (p.split() for p in where.split(", "))}
    assert sum(counts.values()) == NY_ROWS  # every row, by reason
    assert not (out / "points.parquet").exists() and not (out / "tracks.parquet").exists()
    assert leftovers(out) == []


def test_a_run_that_keeps_reports_but_no_track_writes_them_to_judge(cli, data, tmp_path):
    out = tmp_path / "out"
    result, report = ingest(
        cli, out, data / NY_HOUR, extra=("--roi", "none", "--min-points", "100000")
    )
    assert result.exit_code == 0, result.output
    said = " ".join(result.stderr.split())
    assert "no track kept" in said and "detect --models none" in said
    assert report["tracks"]["total"] == 0 and report["rejected"]["short_segment"] > 0
    kept = pd.read_parquet(out / "reports.parquet")
    assert len(kept) == report["reports_kept"] > 0 and kept["track_id"].isna().all()
    assert len(pd.read_parquet(out / "tracks.parquet")) == 0
