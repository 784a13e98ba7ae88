from __future__ import annotations

import json
from pathlib import Path

import pytest

from detector.results_table import cell, main, markdown_table


@pytest.mark.parametrize(("value", "column", "expected"), [
    (None, "AP50", "–"), (float("nan"), "mPE", "–"), (0.91234, "AP50", "0.912"), (0.1549, "mPE", "0.15"),
])
def test_cells(value: object, column: str, expected: str) -> None:
    assert cell(value, column) == expected


def test_table_rows_follow_the_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    first, second = tmp_path / "a.json", tmp_path / "b.json"
    first.write_text(json.dumps({"AP50": 0.5, "mPE": 0.31}))
    second.write_text(json.dumps({"AP50": 0.75, "mPE": None}))
    assert main(["--columns", "AP50,mPE", f"base={first}", str(second)]) == 0
    assert capsys.readouterr().out.splitlines() == [
        "| model | AP50 | mPE (m) |", "|---|---|---|", "| base | 0.500 | 0.31 |", "| b | 0.750 | – |"]
    assert markdown_table([], ("AP50",)).count("\n") == 1
