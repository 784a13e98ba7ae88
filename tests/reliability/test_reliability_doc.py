"""docs/RELIABILITY.md shows what the tests observe: its tables are the ones made from the case
list the tests run, and every test the document names exists."""

from __future__ import annotations

import ast
import re
from pathlib import Path

from reliability_cases import ALL_CASES, SCENARIOS, document_block, markdown_tables
from reliability_grpc_cases import GRPC_CAMERA_CASES, GRPC_FRAME_CASES, GRPC_SCENARIOS

ROOT = Path(__file__).resolve().parents[2]
DOCUMENT = ROOT / "docs" / "RELIABILITY.md"


def test_document_tables_match_the_case_list() -> None:
    assert document_block(DOCUMENT.read_text()) == markdown_tables(), (
        "docs/RELIABILITY.md is out of date: python tests/reliability/reliability_cases.py --write "
        "docs/RELIABILITY.md"
    )


def test_case_and_scenario_names_are_unique() -> None:
    names = [case.name for case in ALL_CASES] + [row.name for row in SCENARIOS + GRPC_SCENARIOS]
    assert len(names) == len(set(names))
    # A gRPC case may share the name of the REST case of the same input, never another's.
    grpc_names = [case.name for case in GRPC_FRAME_CASES] + [case.name for case in GRPC_CAMERA_CASES]
    assert len(grpc_names) == len(set(grpc_names))
    rest = {case.name for case in ALL_CASES}
    for case in GRPC_FRAME_CASES:
        assert case.rest is None or case.rest in rest, case.name
        assert case.name not in rest or case.rest == case.name, case.name


def test_every_named_test_exists() -> None:
    for test_id in re.findall(r"`(tests/reliability/[^`]+::[^`]+)`", DOCUMENT.read_text()):
        path, _, name = test_id.partition("::")
        function = name.split("[")[0]
        tree = ast.parse((ROOT / path).read_text())
        defined = {node.name for node in ast.walk(tree) if isinstance(node, ast.FunctionDef)}
        assert function in defined, test_id
