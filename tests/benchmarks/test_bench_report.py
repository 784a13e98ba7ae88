"""The report's JSON schema, the budget's exit codes and the targets, on hand-made reports."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import pytest

from benchmarks.report import (
    EXIT_OK,
    EXIT_OVER_BUDGET,
    EXIT_UNMEASURED,
    budget_verdict,
    check_report,
    format_table,
    targets,
    unavailable,
    write_report,
)
from benchmarks.stats import summarize


def _summary(*values: float) -> dict[str, float | int]:
    return summarize(list(values)).as_dict()


def make_report(http_p95_values: tuple[float, ...] = (40.0, 50.0, 55.0)) -> dict[str, Any]:
    stages = {name: _summary(1.0, 2.0) for name in
              ("decode", "preprocess", "inference", "postprocess", "localization", "total")}
    report: dict[str, Any] = {
        "schema": "fishloc-bench/1", "created_utc": "2026-01-01T00:00:00+00:00",
        "command": ["fishloc", "bench"],
        "machine": {"cpu_model": "Test CPU", "logical_cpus": 2, "onnxruntime": "1.0", "summary": "Test CPU"},
        "model": {"name": "m", "version": "1", "input_size": 384, "path": "m.onnx"},
        "frames": {"folder": "f", "count": 1, "width": 2952, "height": 2952, "bytes_min": 2_000_000,
                   "bytes_max": 2_000_000, "bytes_mean": 2_000_000.0},
        "settings": {},
        "sections": {
            "in_process": {"available": True, "stages_ms": stages, "pipeline_ms": _summary(30.0, 31.0),
                           "naive_ms": _summary(60.0), "floor_inference_ms": _summary(15.0),
                           "pipeline_cpu_ms": _summary(40.0), "decode_cpu_ms": _summary(20.0),
                           "floor_inference_cpu_ms": _summary(15.0), "floor_decode_ms": _summary(20.0),
                           "ratios": {"naive_over_service_p50": 2.0, "service_over_floor_inference_p50": 2.0,
                                      "service_overhead_pct_over_decode_plus_inference": 5.0}},
            "http": {"available": True,
                     "single": {"latency_ms": _summary(*http_p95_values), "throughput_fps": 20.0,
                                "server_total_ms": _summary(30.0)},
                     "concurrent": {"clients": 4, "latency_ms": _summary(80.0), "throughput_fps": 30.0,
                                    "overloaded_503": 0, "errors": 0},
                     "overhead_pct_over_decode_plus_inference": 12.0},
            "grpc": unavailable("not in this checkout"),
        },
    }
    report["budget"] = budget_verdict(report, 100.0).as_dict()
    report["targets"] = targets(report)
    return report


def test_a_complete_report_follows_the_schema(tmp_path: Path) -> None:
    report = make_report()
    assert check_report(report) == []
    path = tmp_path / "out" / "report.json"
    write_report(report, path)
    assert check_report(json.loads(path.read_text(encoding="utf-8"))) == []


@pytest.mark.parametrize(("damage", "expected"), [
    (lambda r: r.pop("machine"), "missing key 'machine'"),
    (lambda r: r["machine"].pop("onnxruntime"), "machine lacks 'onnxruntime'"),
    (lambda r: r["model"].pop("input_size"), "model lacks 'input_size'"),
    (lambda r: r.update(schema="other"), "schema is 'other'"),
    (lambda r: r["sections"].pop("grpc"), "section 'grpc' missing"),
    (lambda r: r["sections"]["grpc"].pop("reason"), "section 'grpc' is unavailable without a reason"),
    (lambda r: r["sections"]["http"]["single"]["latency_ms"].pop("p99"), "http.single.latency_ms: not a"),
    (lambda r: r["sections"]["in_process"]["stages_ms"]["decode"].update(p50=1e9), "out of order"),
    (lambda r: r.update(budget={}), "budget lacks"),
])
def test_damaged_reports_are_named(damage: Any, expected: str) -> None:
    report = copy.deepcopy(make_report())
    damage(report)
    problems = check_report(report)
    assert any(expected in problem for problem in problems), problems


def test_not_a_report() -> None:
    assert check_report([1, 2]) == ["the report is not a JSON object"]


@pytest.mark.parametrize(("latencies", "budget_ms", "code"), [
    ((40.0, 50.0, 90.0), 100.0, EXIT_OK),
    ((40.0, 100.0, 100.0), 100.0, EXIT_OK),          # p95 exactly at the budget passes
    ((40.0, 50.0, 150.0), 100.0, EXIT_OVER_BUDGET),   # p95 = 140
    ((40.0, 50.0, 90.0), 60.0, EXIT_OVER_BUDGET),
])
def test_budget_exit_code(latencies: tuple[float, ...], budget_ms: float, code: int) -> None:
    verdict = budget_verdict(make_report(latencies), budget_ms)
    assert verdict.exit_code == code
    assert verdict.passed == (code == EXIT_OK)
    assert verdict.value_ms == pytest.approx(summarize(list(latencies)).p95)


def test_budget_cannot_pass_unmeasured() -> None:
    report = make_report()
    report["sections"]["http"] = unavailable("fishloc serve did not start")
    verdict = budget_verdict(report, 100.0)
    assert (verdict.measured, verdict.passed, verdict.exit_code) == (False, False, EXIT_UNMEASURED)


def test_targets_and_table() -> None:
    report = make_report((40.0, 50.0, 70.0))  # p95 68: within the budget, over the 60 ms target
    by_name = {t["name"]: t for t in report["targets"]}
    assert by_name["http_p95_ms"]["met"] is False
    assert by_name["grpc_streams"]["met"] is None          # section unavailable: not measured
    assert by_name["service_overhead_pct"]["met"] is True  # 12 % ≤ 15 %
    table = format_table(report)
    assert "HTTP, 1 client" in table and "unavailable: not in this checkout" in table
    assert "Test CPU" in table and "2.00–2.00 MB" in table
