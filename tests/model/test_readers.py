"""Reading a model's JSON files trusting nothing in them (`aisdati.model.readers`): a card
nested too deeply or too large is refused in one line before it is read (issue 27, item 12)."""

from __future__ import annotations

import re

from tests.helpers.cli import one_line_error
from tests.helpers.models import card_text, copy_of, detect_with


def test_a_deeply_nested_card_is_one_line(ny_models, tmp_path):
    models = copy_of(ny_models, tmp_path)
    text = card_text(models, "down")
    deep = '"preset": ' + "[" * 100_000 + "]" * 100_000
    (models / "down.json").write_text(re.sub(r'"preset": "[^"]*"', deep, text, count=1))
    result = detect_with(ny_models, models, tmp_path / "r", "dati")
    one_line_error(result, r"model card .*down\.json is nested too deeply")
    (models / "down.json").write_text(re.sub(r'"preset": "[^"]*"', '"preset": ' + "[" * 40
                                             + "]" * 40, text, count=1))  # fmt: skip
    result = detect_with(ny_models, models, tmp_path / "r", "dati")
    one_line_error(result, r"model card .*down\.json is nested more than 32 levels deep")


def test_a_huge_card_is_refused_before_it_is_read(ny_models, tmp_path):
    models = copy_of(ny_models, tmp_path)
    with (models / "down.json").open("a") as fh:
        fh.truncate(65 << 20)  # 65 MiB: a sparse file of NUL bytes after the card
    result = detect_with(ny_models, models, tmp_path / "r", "dati")
    one_line_error(result, r"model card .*down\.json is 68,157,440 bytes, more than any holds")
