"""The ingest outputs (`aisdati.preprocess.output`): a rerun without --keep-rejects leaves no
rejects of the earlier run (issue 13, item 16)."""

from __future__ import annotations

from pathlib import Path

from tests.helpers.ingest import NY_HOUR, SETTINGS, ingest


# ------------------------------------------------------------- 16: stale rejects.parquet
def test_rejects_of_an_earlier_run_do_not_stay(cli, data, tmp_path):
    out = tmp_path / "out"
    result, _ = ingest(cli, out, data / NY_HOUR, extra=(*SETTINGS, "--keep-rejects"))
    assert result.exit_code == 0 and (out / "rejects.parquet").is_dir()  # a Parquet dataset
    result, report = ingest(cli, out, data / NY_HOUR)
    assert result.exit_code == 0, result.output
    assert not (out / "rejects.parquet").exists()
    assert "rejects" not in report["outputs"]
    assert sorted(p.name for p in out.iterdir()) == sorted(
        Path(f).name for f in report["outputs"].values()
    )
