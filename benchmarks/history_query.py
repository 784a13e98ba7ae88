"""How fast the counts history answers over a year of a site's minutes.

    python -m benchmarks.history_query [--days 365] [--zones 2] [--lines 1] [--runs 30]
                                       [--database URL_OR_PATH] [--json OUT]

Fills a fresh registry database (SQLite file by default; any SQLAlchemy URL, e.g. PostgreSQL) with
`--days` of one site's minute rows and their hour and day roll-ups, as the history sink writes them
(people, each zone and each line: one row per figure and bucket), then times
`HistoryStore.query` (what `GET /v1/sites/{site}/history` runs) for typical ranges, `--runs` times each:
the whole year per day, a month per hour, a week per 15 minutes, a day per minute. Wall time, and
the thread's own CPU time (SQLite runs in it; other processes on a busy machine do not inflate it).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import insert

from benchmarks.stats import summarize
from service.cameras import CameraRegistry
from service.outputs.history import RESOLUTIONS_S, HistoryStore
from service.outputs.tables import history_table, migrate

END_S = 1_767_225_600  # 2026-01-01T00:00Z
QUERIES = {"year per day": (365 * 86400, 86400), "month per hour": (30 * 86400, 3600),
           "week per 15 min": (7 * 86400, 900), "day per minute": (86400, 60)}


def fill(store: HistoryStore, site: str, days: int, zones: int, lines: int, seed: int = 0) -> int:
    """`days` of minutes (people ~ a daily cycle, zones a share of them, crossings ~ Poisson) and
    their roll-ups, written in bulk; the number of rows."""
    rng = np.random.default_rng(seed)
    starts = END_S - days * 86400 + 60 * np.arange(days * 1440)
    daily = 0.5 + 0.5 * np.sin(2 * np.pi * (starts % 86400) / 86400 - np.pi / 2)
    samples = np.full(len(starts), 300)  # 5 frames a second
    figures: list[tuple[str, str, np.ndarray, np.ndarray]] = []
    people = rng.poisson(20 * daily + 0.5).astype(float)
    figures.append(("people", "", people * samples, people + rng.integers(0, 3, len(starts))))
    for zone in range(zones):
        inside = np.floor(people * rng.uniform(0.2, 0.6))
        figures.append(("zone", f"zone-{zone}", inside * samples, inside + 1))
    for line in range(lines):
        figures.append(("line", f"line-{line}", rng.poisson(3 * daily).astype(float),
                        rng.poisson(3 * daily).astype(float)))
    written = 0
    with store.engine.begin() as connection:
        for step in RESOLUTIONS_S:
            bucket = starts - starts % step
            keys, first = np.unique(bucket, return_index=True)
            for kind, key, total, peak in figures:
                totals = np.add.reduceat(total, first)
                peaks = np.add.reduceat(peak, first) if kind == "line" else np.maximum.reduceat(peak, first)
                counts = np.add.reduceat(samples if kind != "line" else np.zeros_like(samples), first)
                rows = [{"site": site, "step_s": step, "start": int(s), "kind": kind, "key": key,
                         "total": float(t), "peak": float(p), "samples": int(c)}
                        for s, t, p, c in zip(keys, totals, peaks, counts, strict=True)]
                for at in range(0, len(rows), 20_000):
                    connection.execute(insert(history_table), rows[at:at + 20_000])
                written += len(rows)
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--days", type=int, default=365)
    parser.add_argument("--zones", type=int, default=2)
    parser.add_argument("--lines", type=int, default=1)
    parser.add_argument("--runs", type=int, default=30)
    parser.add_argument("--database", help="SQLAlchemy URL or SQLite path (default: a temporary file)")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        registry = CameraRegistry(args.database or str(Path(folder) / "history.db"))
        migrate(registry.engine)
        store = HistoryStore(registry.engine, retention_days=args.days + 30)
        started = time.perf_counter()
        rows = fill(store, "bench", args.days, args.zones, args.lines)
        print(f"filled {rows} rows ({args.days} days of minutes with roll-ups) in "
              f"{time.perf_counter() - started:.1f} s")
        report: dict[str, Any] = {"days": args.days, "zones": args.zones, "lines": args.lines,
                                  "rows": rows, "database": registry.engine.dialect.name, "queries": {}}
        for name, (span_s, step_s) in QUERIES.items():
            span_s = min(span_s, args.days * 86400)
            times_ms, cpu_ms, answered = [], [], 0
            for _ in range(args.runs):
                begin, begin_cpu = time.perf_counter(), time.thread_time()
                answered = len(store.query("bench", END_S - span_s, END_S, step_s))
                times_ms.append(1000 * (time.perf_counter() - begin))
                cpu_ms.append(1000 * (time.thread_time() - begin_cpu))
            wall, cpu = summarize(times_ms), summarize(cpu_ms)
            report["queries"][name] = {"rows": answered, "wall_ms": wall.as_dict(), "cpu_ms": cpu.as_dict()}
            print(f"{name:>16}: {answered:5d} rows  wall p50 {wall.p50:.1f} ms  p95 {wall.p95:.1f} ms"
                  f"  (CPU p50 {cpu.p50:.1f} ms  p95 {cpu.p95:.1f} ms)")
        registry.close()
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
