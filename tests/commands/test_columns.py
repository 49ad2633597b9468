"""Tables fitted to the terminal (`aisdati.commands.columns`): figures never wrap, free text
wraps at spaces, whole columns are left out in the stated order (issue 69, item 3)."""

from __future__ import annotations

from rich.text import Text

from aisdati.commands.columns import Column, fitted, widths


def _column(header: str, cells: list[str], wraps: bool = False) -> Column:
    return Column(header, [Text(c) for c in cells], wraps=wraps)


def test_a_figure_needs_its_widest_cell_free_text_its_longest_word():
    assert _column("mmsi", ["100001468", "7"]).min_width == 9
    text = _column("evidence", ["moved 3,160 m off", "a b"], wraps=True)
    assert (text.min_width, text.max_width) == (len("evidence"), len("moved 3,160 m off"))


def test_columns_are_left_out_in_the_stated_order_until_the_rest_fit():
    columns = [_column(h, ["x" * 10]) for h in ("a", "b", "c", "d")]  # 4 x 10 + 3 gaps of 2
    assert fitted(columns, 46, ("c", "b"))[1] == []
    kept, dropped = fitted(columns, 40, ("c", "b"))
    assert dropped == ["c"] and [c.header for c in kept] == ["a", "b", "d"]
    assert fitted(columns, 20, ("c", "b"))[1] == ["c", "b"]


def test_free_text_shares_what_the_figures_leave():
    figure = _column("time", ["2018-08-01 06:21:00"])
    text = _column("evidence", ["moved 3,160 m off its reported motion for 32 reports"], wraps=True)
    assert widths([figure, text], 50) == [19, 50 - 19 - 2]
    assert widths([figure, text], 200) == [19, text.max_width]
