# Running the swarf CLI (and, when asked, a local swarfd) as subprocesses:
# progress parsed from swarf's own progress output, cancellable by killing
# the process group. No FreeCAD imports: testable with plain Python.
import os
import re
import select
import signal
import subprocess
import threading
import time

from .compat import SwarfError

# swarf's progress: on a terminal "\r 42% [====>   ] 1234/5678 moves ...",
# otherwise "swarf: 25% (1234 of 5678 moves, ...)".
_PROGRESS = re.compile(r"(\d+)% (?:\[|\()")
_PORT = re.compile(r"listening on \S+ \(port (\d+)\)")


class Cancelled(Exception):
    pass


def _kill_group(proc):
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


class LocalServer:
    """A swarfd started for one run on a free loopback port, journal off
    (--data_dir ""); its log (stdout) names the port. Stopped by stop()."""

    def __init__(self, swarfd, timeout_s=30):
        if not os.access(swarfd, os.X_OK):
            raise SwarfError("swarfd path %r (the add-on's preferences or "
                             "--swarfd) is not an executable" % swarfd)
        self.proc = subprocess.Popen(
            [swarfd, "--listen", "127.0.0.1:0", "--data_dir", "",
             "--drain_seconds", "1"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            start_new_session=True)
        self.address = None
        deadline = time.monotonic() + timeout_s
        seen = []
        while time.monotonic() < deadline:
            ready, _, _ = select.select([self.proc.stdout], [], [], 0.2)
            if ready:
                line = self.proc.stdout.readline().decode("utf-8", "replace")
                if not line:
                    break
                seen.append(line.rstrip())
                m = _PORT.search(line)
                if m:
                    self.address = "127.0.0.1:" + m.group(1)
                    break
            elif self.proc.poll() is not None:
                break
        if self.address is None:
            self.stop()
            raise SwarfError("swarfd %s did not start listening: %s" %
                             (swarfd, " | ".join(seen[-5:]) or "no output"))
        # Keep draining its log so it never blocks on a full pipe.
        threading.Thread(target=self._drain, daemon=True).start()

    def _drain(self):
        for _ in iter(self.proc.stdout.readline, b""):
            pass

    def stop(self):
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGTERM)
                self.proc.wait(timeout=5)
            except (subprocess.TimeoutExpired, ProcessLookupError):
                _kill_group(self.proc)
                self.proc.wait()


def run(cmd, env=None, progress=None, cancelled=None, idle=None, echo=None,
        use_pty=False):
    """Runs `cmd`; returns (exit status, output text). progress(percent)
    is called as swarf reports it; cancelled() is polled every 0.1 s (True
    kills the process group and raises Cancelled); idle() runs between
    polls (a GUI's event processing); echo(text) gets the output as it
    comes. use_pty gives swarf a terminal so that it draws its fine-grained
    progress bar instead of quarter lines."""
    master = None
    if use_pty:
        import pty
        master, slave = pty.openpty()
        proc = subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL,
                                stdout=slave, stderr=slave,
                                start_new_session=True)
        os.close(slave)
        source = master
    else:
        proc = subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL,
                                stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT,
                                start_new_session=True)
        source = proc.stdout.fileno()
    chunks = []
    lock = threading.Lock()

    def reader():
        while True:
            try:
                data = os.read(source, 65536)
            except OSError:  # EIO: the pty's other side closed
                break
            if not data:
                break
            with lock:
                chunks.append(data)

    t = threading.Thread(target=reader, daemon=True)
    t.start()
    seen = 0
    last_percent = -1
    pending = ""
    try:
        while True:
            finished = proc.poll() is not None
            if finished:
                t.join(timeout=5)
            with lock:
                new = b"".join(chunks[seen:])
                seen = len(chunks)
            if new:
                text = new.decode("utf-8", "replace")
                if echo:
                    echo(text)
                pending += text
                parts = re.split(r"[\r\n]", pending)
                pending = parts.pop()
                for part in parts + [pending]:
                    m = None
                    for m in _PROGRESS.finditer(part):
                        pass
                    if m and progress:
                        pct = int(m.group(1))
                        if pct != last_percent:
                            last_percent = pct
                            progress(pct)
            if finished:
                break
            if cancelled and cancelled():
                _kill_group(proc)
                proc.wait()
                raise Cancelled()
            if idle:
                idle()
            time.sleep(0.05)
    finally:
        if master is not None:
            os.close(master)
        elif proc.stdout:
            proc.stdout.close()
    out = b"".join(chunks).decode("utf-8", "replace")
    return proc.returncode, out.replace("\r\n", "\n")
