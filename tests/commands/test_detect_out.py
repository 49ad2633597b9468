"""`detect --out` given a URL (`memory://r`): one line, and no local folder named `memory:`
(a report folder is local; `train --out` is the one output that copies to a URL)."""

from __future__ import annotations

import pytest

from tests.helpers.cli import one_line_error, run


@pytest.mark.parametrize("url", ["memory://r", "s3://bucket/reports"])
def test_a_url_for_the_report_folder_is_one_line(tmp_path, monkeypatch, url):
    monkeypatch.chdir(tmp_path)
    scheme = url.split(":")[0]
    got = run("detect", "--data", tmp_path, "--models", "none", "--out", url)
    one_line_error(got, f"--out {scheme}://...: a URL")
    assert list(tmp_path.iterdir()) == []
