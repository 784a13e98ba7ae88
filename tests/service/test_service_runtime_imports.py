"""The service runs from the runtime dependencies alone: it never imports torch or the training code."""

from __future__ import annotations

import subprocess
import sys

SCRIPT = """
import sys
import service.server, service.gateway.client, service.serve_cli, service.gateway.cli, service.grpc.server
heavy = sorted({m.split('.')[0] for m in sys.modules} & {'torch', 'onnx', 'onnxscript', 'detector',
                                                         'exporter', 'matplotlib', 'scipy', 'redis'})
print(','.join(heavy))
"""


def test_service_imports_no_training_tools() -> None:
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=120,
                          check=True)
    assert done.stdout.strip() == ""
