"""The committed gRPC stubs are exactly what `make protos` generates from the protos."""

from __future__ import annotations

from pathlib import Path

from protos.generate import PROTO_FILES, REPO_ROOT, generate


def test_committed_stubs_match_the_protos(tmp_path: Path) -> None:
    generate(tmp_path)
    for proto in PROTO_FILES:
        stem = proto.removesuffix(".proto")
        for suffix in ("_pb2.py", "_pb2.pyi", "_pb2_grpc.py"):
            fresh = (tmp_path / f"{stem}{suffix}").read_bytes()
            committed = (REPO_ROOT / f"{stem}{suffix}").read_bytes()
            assert fresh == committed, f"{stem}{suffix} is stale: run `make protos` and commit the result"
