"""A Markdown table of `fishloc eval` JSON files, one row each (how the README's tables are made).

    python -m detector.results_table baseline=b.json rotaug=r.json equivariance=e.json
    python -m detector.results_table --columns AP50,recall,precision fp32=a.json int8=b.json
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

DEFAULT_COLUMNS = ("AP50", "mAP", "AP75", "AP_near", "AP_mid", "AP_far", "mPE", "PE_near", "PE_mid",
                   "PE_far", "mPE_center", "precision", "recall")
METRE_COLUMNS = frozenset(c for c in DEFAULT_COLUMNS if c.startswith(("mPE", "PE_")))


def cell(value: Any, column: str) -> str:
    """A metric as the table shows it: AP/precision/recall to 3 places, errors in m to 2, '–' if none."""
    if not isinstance(value, int | float) or not math.isfinite(value):
        return "–"
    return f"{value:.2f}" if column in METRE_COLUMNS else f"{value:.3f}"


def markdown_table(rows: list[tuple[str, dict[str, Any]]], columns: tuple[str, ...]) -> str:
    header = "| model | " + " | ".join(f"{c} (m)" if c in METRE_COLUMNS else c for c in columns) + " |"
    lines = [header, "|---" * (len(columns) + 1) + "|"]
    for name, metrics in rows:
        lines.append(f"| {name} | " + " | ".join(cell(metrics.get(c), c) for c in columns) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", help="NAME=EVAL.json (or EVAL.json, named by its file)")
    parser.add_argument("--columns", default=",".join(DEFAULT_COLUMNS), help="comma-separated metrics")
    args = parser.parse_args(argv)
    rows = []
    for item in args.results:
        name, _, path = item.rpartition("=") if "=" in item else (Path(item).stem, "", item)
        rows.append((name, dict(json.loads(Path(path).read_text(encoding="utf-8")))))
    print(markdown_table(rows, tuple(c.strip() for c in args.columns.split(",") if c.strip())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
