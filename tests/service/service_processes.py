"""`fishloc <command>` in a child process, as an operator runs it: its log lines kept, stopped with
SIGTERM or killed with SIGKILL. The base of the replicas and workers of tests/service/sites and of
the reliability tests' `fishloc serve`."""

from __future__ import annotations

import collections
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[2]


class FishlocProcess:
    """`fishloc <args>` (`python -m service.cli`) with `env` added; `launcher` is a command that runs
    the rest of the argv (e.g. unshare); the last `keep_lines` log lines are kept (None: all)."""

    def __init__(self, args: list[str], env: dict[str, str] | None = None, keep_lines: int | None = 400,
                 launcher: list[str] | None = None) -> None:
        self.args = args
        self.env = env or {}
        self.launcher = launcher or []
        self.lines: collections.deque[str] = collections.deque(maxlen=keep_lines)
        self.process: subprocess.Popen[str] | None = None
        self._reader: threading.Thread | None = None

    def start(self) -> FishlocProcess:
        env = {**os.environ, "PYTHONPATH": str(REPO_ROOT), "FISHLOC_LOG_JSON": "true", **self.env}
        self.process = subprocess.Popen([*self.launcher, sys.executable, "-m", "service.cli", *self.args],
                                        cwd=REPO_ROOT, env=env, stdout=subprocess.DEVNULL,
                                        stderr=subprocess.PIPE, text=True)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        return self

    def on_line(self, line: str) -> None:
        """Called with each log line as it arrives (a subclass watches for what it waits on)."""

    def on_exit(self) -> None:
        """Called once the process's log has ended."""

    def _read(self) -> None:
        assert self.process is not None and self.process.stderr is not None
        for line in self.process.stderr:
            self.lines.append(line)
            self.on_line(line)
        self.on_exit()

    @property
    def pid(self) -> int:
        assert self.process is not None
        return self.process.pid

    @property
    def log(self) -> str:
        return "".join(self.lines)

    def wait_for_line(self, pattern: re.Pattern[str], timeout_s: float = 60) -> re.Match[str]:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for line in list(self.lines):
                found = pattern.search(line)
                if found:
                    return found
            assert self.process is not None
            if self.process.poll() is not None:
                break
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"fishloc {self.args[0]} did not log {pattern.pattern!r}:\n{self.log[-3000:]}")

    def kill(self) -> None:
        """SIGKILL: no shutdown code runs."""
        assert self.process is not None
        self.process.send_signal(signal.SIGKILL)
        self.process.wait(30)
        self._close_pipe()

    def stop(self) -> int:
        """SIGTERM, then the exit status."""
        assert self.process is not None
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        try:
            code = self.process.wait(60)
        except subprocess.TimeoutExpired:
            self.process.kill()
            code = self.process.wait(30)
        self._close_pipe()
        return code

    def _close_pipe(self) -> None:
        if self._reader is not None:
            self._reader.join(30)
        if self.process is not None and self.process.stderr is not None:
            self.process.stderr.close()

    def __enter__(self) -> FishlocProcess:
        return self.start()

    def __exit__(self, *_exc: Any) -> None:
        self.stop()
