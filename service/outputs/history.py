"""Counts history: per site and per minute of capture time, people (mean and max), each zone's people
and each line's crossings in and out, in the registry's database.

The sink adds each update to the open minute of its site (in memory) and writes a minute when the
next one begins, or when the service stops; a minute is added at once to its quarter hour, hour and
day as well (`history` rows of step 900, 3600 and 86400), and a query reads the coarsest rows its
step allows: a year at a day's step reads 365 rows per figure, not half a million. All writes add
(sums, sample counts, peaks), so a minute written in two parts (a restart within it) is whole. A
crash loses the open minute. Rows older than `retention_days` before a site's newest minute are
deleted.
"""

from __future__ import annotations

import asyncio
import csv
import io
from dataclasses import dataclass, field
from typing import Any

from sqlalchemy import case, delete, func, insert, select, update
from sqlalchemy.engine import Connection, Engine

from service.outputs.events import SiteUpdate
from service.outputs.sink import Sink
from service.outputs.tables import history_table as table

MINUTE_S = 60
RESOLUTIONS_S = (86_400, 3_600, 900, MINUTE_S)  # stored steps, coarsest first
MAX_STEP_S = 31 * 86_400
MAX_ROWS = 10_000
PRUNE_EVERY_S = 3_600


class HistoryQueryError(ValueError):
    """A history range or step that cannot be answered; the message says why."""


@dataclass
class Figure:
    """Sum of samples, sample count and peak of a count (people, a zone); or for a line, crossings
    in (`total`) and out (`peak`)."""

    total: float = 0.0
    peak: float = 0.0
    samples: int = 0

    def sample(self, value: float) -> None:
        self.total += value
        self.peak = max(self.peak, value)
        self.samples += 1

    @property
    def mean(self) -> float:
        return round(self.total / self.samples, 3) if self.samples else 0.0


@dataclass
class Bucket:
    """Figures of one site over one bucket of time, by (kind, key)."""

    start: int
    figures: dict[tuple[str, str], Figure] = field(default_factory=dict)

    def figure(self, kind: str, key: str) -> Figure:
        return self.figures.setdefault((kind, key), Figure())

    def add(self, update: SiteUpdate) -> None:
        self.figure("people", "").sample(float(update.occupancy.get("count", 0)))
        for zone, count in update.zones.items():
            self.figure("zone", zone).sample(float(count))
        for line in update.lines:
            self.figure("line", line)
        for event in update.of_type("line_crossing"):
            tally = self.figure("line", event["line"])
            if event["direction"] == "in":
                tally.total += 1
            else:
                tally.peak += 1

    def merge(self, kind: str, key: str, other: Figure) -> None:
        mine = self.figure(kind, key)
        mine.total += other.total
        mine.samples += other.samples
        mine.peak = mine.peak + other.peak if kind == "line" else max(mine.peak, other.peak)

    def to_row(self) -> dict[str, Any]:
        """The bucket as a row of the history answer (one pass: a year's rows are many)."""
        zones: dict[str, dict[str, float | int]] = {}
        lines: dict[str, dict[str, int]] = {}
        row: dict[str, Any] = {"time": self.start, "people_mean": 0.0, "people_max": 0, "zones": zones,
                               "lines": lines}
        for (kind, key), figure in self.figures.items():
            if kind == "line":
                lines[key] = {"in": int(figure.total), "out": int(figure.peak)}
            elif kind == "zone":
                zones[key] = {"mean": figure.mean, "max": int(figure.peak)}
            else:
                row["people_mean"], row["people_max"] = figure.mean, int(figure.peak)
        return row


def resolution_for(step_s: int) -> int:
    """The coarsest stored step that divides `step_s`."""
    return next(r for r in RESOLUTIONS_S if step_s % r == 0)


def check_query(from_s: float, to_s: float, step_s: int) -> None:
    if step_s % MINUTE_S or not MINUTE_S <= step_s <= MAX_STEP_S:
        raise HistoryQueryError(f"step must be a multiple of 60 s from 60 to {MAX_STEP_S}, got {step_s}")
    if not to_s > from_s:
        raise HistoryQueryError(f"'to' ({to_s}) must be after 'from' ({from_s})")
    if (to_s - from_s) / step_s > MAX_ROWS:
        raise HistoryQueryError(f"that range at step {step_s} s is more than {MAX_ROWS} rows; "
                                "ask for a larger step or a shorter range")


class HistoryStore:
    """History rows in the database (synchronous; the sink calls it off the event loop)."""

    def __init__(self, engine: Engine, retention_days: float) -> None:
        self.engine = engine
        self.retention_s = retention_days * 86_400

    def add_minute(self, site: str, minute: Bucket) -> None:
        """Add a minute's figures to its minute, hour and day rows."""
        with self.engine.begin() as connection:
            for step in RESOLUTIONS_S:
                start = minute.start - minute.start % step
                for (kind, key), figure in minute.figures.items():
                    self._add(connection, site, step, start, kind, key, figure)
            if minute.start % PRUNE_EVERY_S == 0:
                cut = minute.start - self.retention_s
                gone = (table.c.site == site) & (table.c.start + table.c.step_s <= cut)  # whole buckets only
                connection.execute(delete(table).where(gone))

    @staticmethod
    def _add(connection: Connection, site: str, step: int, start: int, kind: str, key: str,
             figure: Figure) -> None:
        row = ((table.c.site == site) & (table.c.step_s == step) & (table.c.start == start)
               & (table.c.kind == kind) & (table.c.key == key))
        peak = (table.c.peak + figure.peak if kind == "line"
                else case((table.c.peak < figure.peak, figure.peak), else_=table.c.peak))
        changed = connection.execute(update(table).where(row).values(
            total=table.c.total + figure.total, peak=peak, samples=table.c.samples + figure.samples))
        if not changed.rowcount:
            connection.execute(insert(table).values(site=site, step_s=step, start=start, kind=kind, key=key,
                                                    total=figure.total, peak=figure.peak,
                                                    samples=figure.samples))

    def query(self, site: str, from_s: float, to_s: float, step_s: int,
              open_minute: Bucket | None = None) -> list[dict[str, Any]]:
        """Rows of `step_s` buckets (aligned to the epoch, so days are UTC days) from `from_s` to
        `to_s`, each bucket with data once, oldest first; the open minute of the sink included."""
        check_query(from_s, to_s, step_s)
        resolution = resolution_for(step_s)
        lo = int(from_s) - int(from_s) % step_s
        bucket = table.c.start - table.c.start % step_s
        query = (select(bucket.label("bucket"), table.c.kind, table.c.key, func.sum(table.c.total),
                        func.max(table.c.peak), func.sum(table.c.peak), func.sum(table.c.samples))
                 .where((table.c.site == site) & (table.c.step_s == resolution) & (table.c.start >= lo)
                        & (table.c.start < to_s))
                 .group_by(bucket, table.c.kind, table.c.key)
                 .order_by(bucket, table.c.kind, table.c.key))
        with self.engine.connect() as connection:
            rows = connection.execute(query).all()
        buckets: dict[int, Bucket] = {}
        for start, kind, key, total, peak_max, peak_sum, samples in rows:
            found = buckets.get(start)
            if found is None:
                found = buckets[start] = Bucket(int(start))
            found.figures[kind, key] = Figure(float(total), float(peak_sum if kind == "line" else peak_max),
                                              int(samples))
        if open_minute is not None and lo <= open_minute.start < to_s:
            start = open_minute.start - open_minute.start % step_s
            for (kind, key), figure in open_minute.figures.items():
                buckets.setdefault(start, Bucket(start)).merge(kind, key, figure)
        return [buckets[start].to_row() for start in sorted(buckets)]  # sorted: the open minute may be new


CSV_COLUMNS = ("time", "people_mean", "people_max")


def rows_to_csv(rows: list[dict[str, Any]]) -> str:
    """The rows as CSV: time, people_mean, people_max, then `zone:<id>:mean`, `zone:<id>:max`,
    `line:<id>:in`, `line:<id>:out` for every zone and line found in any row (blank where absent)."""
    zones = sorted({zone for row in rows for zone in row["zones"]})
    lines = sorted({line for row in rows for line in row["lines"]})
    header = [*CSV_COLUMNS, *(f"zone:{z}:{m}" for z in zones for m in ("mean", "max")),
              *(f"line:{ln}:{d}" for ln in lines for d in ("in", "out"))]
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header)
    for row in rows:
        cells: list[Any] = [row["time"], row["people_mean"], row["people_max"]]
        for zone in zones:
            value = row["zones"].get(zone)
            cells += [value["mean"], value["max"]] if value else ["", ""]
        for line in lines:
            value = row["lines"].get(line)
            cells += [value["in"], value["out"]] if value else ["", ""]
        writer.writerow(cells)
    return out.getvalue()


class HistorySink(Sink):
    """Writes each site's minutes (see the module docstring)."""

    name = "history"

    def __init__(self, store: HistoryStore) -> None:
        self.store = store
        self._open: dict[str, Bucket] = {}
        self._error: str | None = None

    async def publish(self, update: SiteUpdate) -> None:
        start = int(update.time) - int(update.time) % MINUTE_S
        current = self._open.get(update.site)
        if current is not None and start > current.start:
            await self._write(update.site, current)
            current = None
        if current is None:
            current = self._open[update.site] = Bucket(start)
        current.add(update)

    async def _write(self, site: str, minute: Bucket) -> None:
        try:
            await asyncio.to_thread(self.store.add_minute, site, minute)
            self._error = None
        except Exception as error:  # the database is away: this minute is lost, the next ones are not
            self._error = f"{type(error).__name__}: {error}"
            raise

    def open_minute(self, site: str) -> Bucket | None:
        return self._open.get(site)

    async def close(self) -> None:
        open_minutes, self._open = self._open, {}
        for site, minute in open_minutes.items():
            await self._write(site, minute)

    def health(self) -> dict[str, Any]:
        return {"ok": self._error is None, **({"error": self._error} if self._error else {})}
