"""A real Dask cluster for the tests: a ``dask scheduler`` and ``dask worker`` processes on localhost.

Each process runs in a session of its own and is always terminated (:meth:`DaskProcesses.stop`,
registered as a finalizer before anything starts), its output logged to a file that a
failure to start quotes.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent  # the venv's executables: dask, rozyn


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class DaskProcesses:
    """``dask scheduler --host 127.0.0.1 --port PORT`` and ``n_workers`` single-thread workers."""

    def __init__(self, n_workers: int, log_dir: Path, timeout_s: float = 60.0) -> None:
        self.n_workers, self.log_dir, self.timeout_s = n_workers, log_dir, timeout_s
        self.procs: list[subprocess.Popen[bytes]] = []
        self.address = ""

    def start(self) -> str:
        """Start the processes; return the scheduler's address once every worker has registered."""
        dask = BIN / "dask"
        if not dask.exists():
            pytest.skip("dask is not installed")
        from distributed import Client

        self.address = f"tcp://127.0.0.1:{free_port()}"
        self._spawn("scheduler", [str(dask), "scheduler", "--host", "127.0.0.1", "--port",
                                  self.address.rsplit(":", 1)[1], "--no-dashboard"])
        for k in range(self.n_workers):
            self._spawn(f"worker{k}", [str(dask), "worker", self.address, "--nthreads", "1",
                                       "--no-dashboard"])
        try:
            with Client(self.address, timeout=f"{self.timeout_s:g}s") as client:
                client.wait_for_workers(self.n_workers, timeout=self.timeout_s)
        except (OSError, TimeoutError) as exc:
            raise RuntimeError(f"the Dask cluster did not start ({exc}):\n{self.logs()}") from None
        return self.address

    def _spawn(self, name: str, cmd: list[str]) -> None:
        with (self.log_dir / f"dask-{name}.log").open("wb") as log:
            self.procs.append(subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                               start_new_session=True,
                                               env=dict(os.environ, PYTHONUNBUFFERED="1")))

    def logs(self) -> str:
        return "\n".join(f"--- {p.name}\n{p.read_text(errors='replace')[-2000:]}"
                         for p in sorted(self.log_dir.glob("dask-*.log")))

    def stop(self) -> None:
        """Terminate the workers, then the scheduler (SIGTERM, SIGKILL after 30 s)."""
        for proc in reversed(self.procs):
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
        for proc in reversed(self.procs):
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        self.procs.clear()
