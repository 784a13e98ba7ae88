"""The Grafana dashboard of sites parses, and every metric its queries name is one the service exposes."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from service.core.metrics import ServiceMetrics
from sites import CountingLine, SiteLayout, Zone

DASHBOARD = Path(__file__).resolve().parents[2] / "deploy" / "grafana" / "fishloc-sites.json"
_METRIC = re.compile(r"\b(fishloc_[a-z_]+)")


def _queries(dashboard: dict[str, Any]) -> list[str]:
    queries = [target["expr"] for panel in dashboard["panels"] for target in panel["targets"]]
    for variable in dashboard["templating"]["list"]:
        query = variable.get("query")
        if isinstance(query, dict):
            queries.append(query["query"])
    return queries


def _exposed_series() -> set[str]:
    """Series names in the exposition of a service that has seen a frame of a site."""
    metrics = ServiceMetrics()
    layout = SiteLayout.of([Zone("entrance", np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]))],
                           [CountingLine("door", np.array([0.0, 0.0]), np.array([0.0, 1.0]))])
    occupancy = {"count": 1, "zones": {"entrance": {"count": 1}}}
    metrics.follow_layout("hall", layout)
    metrics.observe_site("hall", "used", {"door": (0, 0)}, {"door": (1, 1)}, occupancy, 0.0004)
    text = metrics.exposition().decode()
    samples = [line for line in text.splitlines() if line and not line.startswith("#")]
    return {line.split("{")[0].split(" ")[0] for line in samples}


def test_the_dashboard_parses_and_names_existing_metrics() -> None:
    dashboard = json.loads(DASHBOARD.read_text(encoding="utf-8"))
    assert dashboard["uid"] == "fishloc-sites" and dashboard["panels"]
    assert len({panel["id"] for panel in dashboard["panels"]}) == len(dashboard["panels"])
    exposed = _exposed_series()
    named = {name for query in _queries(dashboard) for name in _METRIC.findall(query)}
    assert {"fishloc_site_people", "fishloc_zone_people", "fishloc_line_crossings_total"} <= named
    unknown = {name for name in named if name not in exposed}
    assert not unknown, f"the dashboard queries metrics the service does not expose: {sorted(unknown)}"
