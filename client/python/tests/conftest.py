"""Fixtures: a real swarfd (the binary named by $SWARFD) started per test
module on a free loopback port, restartable on the same port and data
directory; the swarf CLI as $SWARF."""

import os
import pathlib
import re
import signal
import socket
import subprocess
import time
from typing import Iterator, List, Optional

import pytest

import swarf_client


def _binary(var: str) -> str:
    path = os.environ.get(var)
    if not path or not os.access(path, os.X_OK):
        # A missing binary is a failure, never a skip: ctest must not pass
        # on tests that did not run.
        raise RuntimeError(f"${var} must name the built binary, got {path!r}")
    return path


def require_shared(path: pathlib.Path) -> None:
    """Files outside the repository (../shared/corpus, read in place):
    a missing one skips the test, naming it, so that a fresh clone passes;
    with SWARF_REQUIRE_SHARED set (not "" or "0"; .ci/run sets it) it
    fails instead, so CI cannot silently lose the corpus coverage."""
    if path.exists():
        return
    if os.environ.get("SWARF_REQUIRE_SHARED", "") not in ("", "0"):
        pytest.fail(f"missing {path} (SWARF_REQUIRE_SHARED is set)")
    pytest.skip(f"missing {path}")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Swarfd:
    """swarfd on 127.0.0.1:port, journaling under data_dir."""

    def __init__(self, data_dir: pathlib.Path, extra: Optional[List[str]] = None):
        self.binary = _binary("SWARFD")
        self.port = free_port()
        self.target = f"127.0.0.1:{self.port}"
        self.data_dir = data_dir
        self.extra = extra or []
        self.proc: Optional[subprocess.Popen] = None
        self.log = data_dir / "swarfd.log"

    def start(self) -> None:
        self.data_dir.mkdir(parents=True, exist_ok=True)
        with open(self.log, "ab") as log:
            self.proc = subprocess.Popen(
                [self.binary, f"--listen={self.target}",
                 f"--data_dir={self.data_dir}", "--journal_sync=off",
                 "--worker_threads=2", "--drain_seconds=1"] + self.extra,
                stdout=log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 30
        with swarf_client.Client(self.target) as c:
            while not c.health(timeout=1.0):
                if self.proc.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError("swarfd did not start:\n" +
                                       self.log.read_text())
                time.sleep(0.05)

    def kill(self) -> None:
        """SIGKILL: no draining, no snapshot."""
        assert self.proc is not None
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=30)
        self.proc = None

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
            self.proc = None


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo
                              ) -> Iterator[None]:
    """A failed test that ran against a swarfd reports the server's log
    tail too (what the server did while the client waited)."""
    outcome = yield
    report = outcome.get_result()  # type: ignore[attr-defined]
    server = getattr(item, "funcargs", {}).get("swarfd")
    if report.failed and isinstance(server, Swarfd) and server.log.exists():
        lines = server.log.read_text(errors="replace").splitlines()
        report.sections.append(("swarfd log (last 80 lines)",
                                "\n".join(lines[-80:])))


@pytest.fixture(scope="module")
def swarfd(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Swarfd]:
    server = Swarfd(tmp_path_factory.mktemp("swarfd"))
    server.start()
    yield server
    server.stop()


@pytest.fixture
def client(swarfd: Swarfd) -> Iterator[swarf_client.Client]:
    with swarf_client.Client(swarfd.target) as c:
        yield c


@pytest.fixture(scope="session")
def swarf_cli() -> str:
    return _binary("SWARF")
