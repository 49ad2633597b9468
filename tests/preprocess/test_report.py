"""The per-stage counts (`aisdati.preprocess.report`): a run that keeps no track fails and says
where every row went (issue 13, item 6)."""

from __future__ import annotations

import re

from tests.helpers.cli import one_line_error
from tests.helpers.ingest import NY_HOUR, NY_ROWS, ingest, leftovers


# ------------------------------------------------------------------------ 6: zero tracks
def test_a_run_that_keeps_no_track_fails_and_says_where_the_rows_went(cli, data, tmp_path):
    out = tmp_path / "out"
    result, _ = ingest(cli, out, data / NY_HOUR, extra=("--roi", "none", "--min-points", "100000"))
    one_line_error(result, f"no track kept: {NY_ROWS:,} rows read, rejected: slow 6,954, ")
    where = re.search(r"rejected: (.*); nothing written", result.stderr.replace("\n", " "))[1]
    counts = {r: int(n.replace(",", "")) for r, n in (p.split() for p in where.split(", "))}
    assert sum(counts.values()) == NY_ROWS and "short_segment" in counts  # every row, by reason
    assert not (out / "points.parquet").exists() and not (out / "tracks.parquet").exists()
    assert leftovers(out) == []
