"""The benchmark report: its JSON form (schema `fishloc-bench/1`), the printed table, the budget.

Every section is `{"available": true, ...figures}` or `{"available": false, "reason": "..."}`, so a
reader (or a test) can tell a skipped section from a missing one.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

SCHEMA = "fishloc-bench/1"
SECTIONS = ("in_process", "http", "grpc")
BUDGET_METRIC = "http.single.latency_ms.p95"
SUMMARY_KEYS = ("n", "mean", "p50", "p95", "p99", "min", "max")

# The targets on the 2-core machine.
TARGET_HTTP_P95_MS = 60.0
TARGET_GRPC_FPS = 20.0
TARGET_GRPC_P95_MS = 100.0
TARGET_OVERHEAD_PCT = 15.0

EXIT_OK, EXIT_OVER_BUDGET, EXIT_UNMEASURED = 0, 1, 3


def unavailable(reason: str) -> dict[str, object]:
    return {"available": False, "reason": reason}


def _get(report: dict[str, Any], dotted: str) -> Any:
    value: Any = report.get("sections", {})
    for key in dotted.split("."):
        if not isinstance(value, dict) or key not in value:
            return None
        value = value[key]
    return value


@dataclass(frozen=True)
class BudgetVerdict:
    budget_ms: float
    value_ms: float | None

    @property
    def measured(self) -> bool:
        return self.value_ms is not None

    @property
    def passed(self) -> bool:
        return self.value_ms is not None and self.value_ms <= self.budget_ms

    @property
    def exit_code(self) -> int:
        """0 within budget, 1 over it, 3 when the HTTP p95 was not measured (it cannot pass)."""
        if self.value_ms is None:
            return EXIT_UNMEASURED
        return EXIT_OK if self.passed else EXIT_OVER_BUDGET

    def as_dict(self) -> dict[str, object]:
        return {"metric": BUDGET_METRIC, "budget_ms": self.budget_ms, "value_ms": self.value_ms,
                "passed": self.passed}


def budget_verdict(report: dict[str, Any], budget_ms: float) -> BudgetVerdict:
    """The HTTP end-to-end p95 of one client against `budget_ms`."""
    value = _get(report, BUDGET_METRIC)
    return BudgetVerdict(budget_ms, float(value) if isinstance(value, int | float) else None)


def _target(name: str, goal: str, value: float | None, met: bool | None) -> dict[str, object]:
    return {"name": name, "goal": goal, "measured": value, "met": met}


def targets(report: dict[str, Any]) -> list[dict[str, object]]:
    """The issue's targets and what this run measured for them (met: None when not measured)."""
    out = []
    p95 = _get(report, BUDGET_METRIC)
    out.append(_target("http_p95_ms", f"HTTP end-to-end p95 ≤ {TARGET_HTTP_P95_MS:g} ms (one client)", p95,
                       None if p95 is None else p95 <= TARGET_HTTP_P95_MS))
    fps, grpc_p95 = _get(report, "grpc.throughput_fps"), _get(report, "grpc.latency_ms.p95")
    cameras = _get(report, "grpc.cameras") or report.get("settings", {}).get("streams")
    met = None
    if fps is not None and grpc_p95 is not None:
        met = fps >= TARGET_GRPC_FPS and grpc_p95 <= TARGET_GRPC_P95_MS
    out.append(_target("grpc_streams", f"≥ {TARGET_GRPC_FPS:g} frames/s from 8 streams with p95 ≤ "
                       f"{TARGET_GRPC_P95_MS:g} ms (this run: {cameras} streams)", fps, met))
    overhead = _get(report, "http.overhead_pct_over_decode_plus_inference")
    out.append(_target("service_overhead_pct",
                       f"HTTP p50 over decode + inference ≤ {TARGET_OVERHEAD_PCT:g} %", overhead,
                       None if overhead is None else overhead <= TARGET_OVERHEAD_PCT))
    return out


def _check_summary(value: Any, where: str, problems: list[str]) -> None:
    if value is None:
        return
    if not isinstance(value, dict) or any(not isinstance(value.get(k), int | float) for k in SUMMARY_KEYS):
        problems.append(f"{where}: not a latency summary with {', '.join(SUMMARY_KEYS)}")
        return
    if not value["min"] <= value["p50"] <= value["p95"] <= value["p99"] <= value["max"]:
        problems.append(f"{where}: percentiles out of order")


def check_report(report: Any) -> list[str]:
    """Problems with a report's shape (empty when it follows schema fishloc-bench/1)."""
    if not isinstance(report, dict):
        return ["the report is not a JSON object"]
    problems: list[str] = []
    if report.get("schema") != SCHEMA:
        problems.append(f"schema is {report.get('schema')!r}, expected {SCHEMA!r}")
    for key in ("created_utc", "command", "machine", "model", "frames", "settings", "sections", "budget",
                "targets"):
        if key not in report:
            problems.append(f"missing key {key!r}")
    machine = report.get("machine", {})
    for key in ("cpu_model", "logical_cpus", "onnxruntime"):
        if not isinstance(machine, dict) or key not in machine:
            problems.append(f"machine lacks {key!r}")
    for key in ("name", "version", "input_size"):
        if not isinstance(report.get("model"), dict) or key not in report["model"]:
            problems.append(f"model lacks {key!r}")
    sections = report.get("sections", {})
    for name in SECTIONS:
        section = sections.get(name) if isinstance(sections, dict) else None
        if not isinstance(section, dict) or not isinstance(section.get("available"), bool):
            problems.append(f"section {name!r} missing or without 'available'")
        elif not section["available"] and not section.get("reason"):
            problems.append(f"section {name!r} is unavailable without a reason")
    for name, stage in (_get(report, "in_process.stages_ms") or {}).items():
        _check_summary(stage, f"in_process.stages_ms.{name}", problems)
    for dotted in ("in_process.pipeline_ms", "in_process.naive_ms", "in_process.floor_inference_ms",
                   "in_process.pipeline_cpu_ms", "in_process.decode_cpu_ms",
                   "in_process.floor_inference_cpu_ms", "in_process.floor_decode_ms",
                   "http.single.latency_ms", "http.concurrent.latency_ms", "grpc.latency_ms"):
        _check_summary(_get(report, dotted), dotted, problems)
    budget = report.get("budget")
    if not isinstance(budget, dict) or not {"budget_ms", "value_ms", "passed"} <= set(budget):
        problems.append("budget lacks budget_ms, value_ms or passed")
    return problems


def write_report(report: dict[str, Any], path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(report, indent=2, sort_keys=False) + "\n", encoding="utf-8")


def _ms(value: Any) -> str:
    return "—" if not isinstance(value, int | float) else f"{value:.1f}"


def _row(label: str, summary: Any, extra: str = "") -> str:
    if not isinstance(summary, dict):
        return f"| {label} | — | — | — | — | {extra} |"
    return (f"| {label} | {_ms(summary['p50'])} | {_ms(summary['p95'])} | {_ms(summary['p99'])} | "
            f"{_ms(summary['mean'])} | {extra} |")


def format_table(report: dict[str, Any]) -> str:
    """The report as a Markdown table (ms) with the machine, model and frames named above it."""
    machine, model, frames = report["machine"], report["model"], report["frames"]
    lines = [
        f"Machine: {machine.get('summary', machine.get('cpu_model'))}",
        f"Model: {model['name']} {model['version']} (input {model['input_size']}, {model.get('path', '')})",
        f"Frames: {frames['count']} × {frames['width']}×{frames['height']} from {frames['folder']}, "
        f"{frames['bytes_min'] / 1e6:.2f}–{frames['bytes_max'] / 1e6:.2f} MB "
        f"(mean {frames['bytes_mean'] / 1e6:.2f} MB)",
        "",
        "| measurement (ms) | p50 | p95 | p99 | mean | notes |",
        "|---|---|---|---|---|---|",
    ]
    inproc = report["sections"]["in_process"]
    if inproc["available"]:
        for name, summary in inproc["stages_ms"].items():
            note = f"n={summary['n']}"
            if name == "decode" and "decode_reduction" in inproc:
                width, height = inproc["decoded_wh"]
                note += f"; JPEG decoded at 1/{inproc['decode_reduction']} scale ({width}×{height})"
            lines.append(_row(f"in-process stage: {name}", summary, note))
        lines.append(_row("in-process `Pipeline.detect`", inproc["pipeline_ms"], "the service's code path"))
        lines.append(_row("  its CPU time (all threads)", inproc["pipeline_cpu_ms"],
                          "CPU ms per frame; not inflated by other processes"))
        lines.append(_row("  decode CPU time (one thread)", inproc["decode_cpu_ms"], ""))
        lines.append(_row("  inference-alone CPU time", inproc["floor_inference_cpu_ms"],
                          "CPU overhead over decode+inference "
                          f"{_pct(inproc['ratios'].get('service_cpu_overhead_pct_over_decode_plus_inference'))}"))
        ratios = inproc["ratios"]
        lines.append(_row("naive pipeline", inproc["naive_ms"],
                          f"naive / service = {_ratio(ratios['naive_over_service_p50'])}"))
        lines.append(_row("floor: decode alone", inproc["floor_decode_ms"], ""))
        lines.append(_row("floor: inference alone", inproc["floor_inference_ms"],
                          f"service / floor = {_ratio(ratios['service_over_floor_inference_p50'])}; "
                          f"overhead over decode+inference "
                          f"{_pct(ratios['service_overhead_pct_over_decode_plus_inference'])}"))
    else:
        lines.append(f"| in-process | unavailable: {inproc['reason']} | | | | |")
    http = report["sections"]["http"]
    if http["available"]:
        single, concurrent = http["single"], http["concurrent"]
        lines.append(_row("HTTP, 1 client", single["latency_ms"],
                          f"{single['throughput_fps']:.1f} frames/s; pipeline total in the server p50 "
                          f"{_ms((single['server_total_ms'] or {}).get('p50'))}; overhead over "
                          f"decode+inference {_pct(http['overhead_pct_over_decode_plus_inference'])}"))
        if concurrent is not None:
            lines.append(_row(f"HTTP, {concurrent['clients']} clients", concurrent["latency_ms"],
                              f"{concurrent['throughput_fps']:.1f} frames/s, "
                              f"{concurrent['overloaded_503']} × 503, {concurrent['errors']} errors"))
    else:
        lines.append(f"| HTTP | unavailable: {http['reason']} | | | | |")
    grpc = report["sections"]["grpc"]
    if grpc["available"]:
        label = f"gRPC, {grpc['cameras']} streams × {grpc['fps_per_camera']:g} fps"
        lines.append(_row(label, grpc["latency_ms"],
                          f"{grpc['throughput_fps']:.1f} frames/s OK of {grpc['offered_fps']:g} offered, "
                          f"dropped {grpc['dropped_fraction'] * 100:.1f} %, errors {grpc['errors']}"))
    else:
        lines.append(f"| gRPC streams | unavailable: {grpc['reason']} | | | | |")
    lines.append("")
    for target in report["targets"]:
        verdict = {True: "met", False: "NOT met", None: "not measured"}[target["met"]]
        lines.append(f"Target {target['goal']}: {verdict} (measured {_ms(target['measured'])})")
    budget = report["budget"]
    lines.append(f"Budget: HTTP p95 {_ms(budget['value_ms'])} ms against {budget['budget_ms']:g} ms: "
                 f"{'within' if budget['passed'] else 'OVER or unmeasured'}")
    return "\n".join(lines)


def _ratio(value: Any) -> str:
    return "—" if value is None else f"{value:.2f}×"


def _pct(value: Any) -> str:
    return "—" if value is None else f"{value:+.0f} %"
