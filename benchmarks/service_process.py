"""``tracker-service`` as a subprocess for the benchmarks that drive it from outside.

:func:`running_service` starts it on free loopback ports with a known token and nothing saved
(no configuration file, a temporary state folder: a benchmark never writes into the user's
own), waits until ``/health`` answers, and stops it with SIGTERM at the end (killed after
10 s). Its log goes to a temporary file, printed when it fails to start.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import closing, contextmanager
from dataclasses import dataclass
from pathlib import Path

import httpx

__all__ = ["ROOT", "TOKEN", "ServiceProcess", "free_port", "running_service"]

ROOT = Path(__file__).resolve().parent.parent
#: The write token of a benchmark's service.
TOKEN = "bench"


def free_port() -> int:
    with closing(socket.socket(socket.AF_INET, socket.SOCK_STREAM)) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass(frozen=True)
class ServiceProcess:
    """A running service: its process, REST base URL and Zenoh endpoint."""

    process: subprocess.Popen[bytes]
    url: str
    endpoint: str

    @property
    def pid(self) -> int:
        return self.process.pid


@contextmanager
def running_service(*args: str, start_timeout: float = 30.0) -> Iterator[ServiceProcess]:
    """The service started with ``args`` added to its command line, ready to answer."""
    http_port, zenoh_port = free_port(), free_port()
    endpoint = f"tcp/127.0.0.1:{zenoh_port}"
    url = f"http://127.0.0.1:{http_port}"
    with tempfile.TemporaryDirectory(prefix="tracker-bench-") as state_dir:
        log_path = Path(state_dir) / "service.log"
        command = [
            *(sys.executable, "-m", "service", "--http-port", str(http_port)),
            *("--zenoh-listen", endpoint, "--api-token", TOKEN, "--log-level", "warning"),
            *("--state-dir", state_dir, "--config-file", "none", *args),
        ]
        with open(log_path, "wb") as log:
            process = subprocess.Popen(
                command,
                cwd=ROOT,
                env=dict(os.environ, PYTHONUNBUFFERED="1"),
                stdout=subprocess.DEVNULL,
                stderr=log,
            )
        try:
            _wait_healthy(process, url, start_timeout, log_path)
            yield ServiceProcess(process, url, endpoint)
        finally:
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


def _wait_healthy(
    process: subprocess.Popen[bytes], url: str, timeout: float, log_path: Path
) -> None:
    deadline = time.monotonic() + timeout
    while True:
        try:
            if httpx.get(f"{url}/health", timeout=1).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        if time.monotonic() > deadline or process.poll() is not None:
            log = log_path.read_text(errors="replace").strip()
            raise RuntimeError(f"the service did not start:\n{log}")
        time.sleep(0.1)


def proc_status_mb(pid: int, field_name: str) -> float:
    """A memory field of ``/proc/<pid>/status`` (``VmRSS``, ``VmHWM``, ...) in MB (Linux; NaN
    elsewhere or when the process is gone)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return float("nan")
    m = re.search(rf"^{field_name}:\s+(\d+) kB", status, re.MULTILINE)
    return int(m.group(1)) / 1024 if m else float("nan")


def rss_mb(pid: int) -> float:
    """Resident set size of process ``pid`` in MB (Linux ``/proc``; NaN elsewhere)."""
    return proc_status_mb(pid, "VmRSS")


def cpu_seconds(pid: int) -> float:
    """User plus system CPU seconds used so far by process ``pid``, all its threads (Linux
    ``/proc``; NaN elsewhere)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return float("nan")
    fields = stat[stat.rindex(")") + 2 :].split()  # after "pid (comm) "
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
