"""What the Python tests share: the slamd binary, the datasets and daemons
on fresh namespaces.

Environment:
    SLAMD_BIN       the slamd binary (default <repo>/target/debug/slamd)
    SLAMD_DATASETS  the datasets directory (default <repo>/../shared/datasets)
"""

import os
import signal
import subprocess
import time
import uuid
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def slamd_bin():
    path = Path(os.environ.get("SLAMD_BIN", REPO / "target" / "debug" / "slamd"))
    if not path.is_file():
        pytest.fail(f"no slamd binary at {path}: run `cargo build --bin slamd` "
                    "(or set SLAMD_BIN)")
    return path


def dataset(name):
    root = Path(os.environ.get("SLAMD_DATASETS", REPO.parent / "shared" / "datasets"))
    path = root / name
    if not path.is_file():
        pytest.fail(f"no dataset at {path} (set SLAMD_DATASETS)")
    return path


def fresh_namespace(tag):
    return f"slamd-pytest-{tag}-{os.getpid()}-{uuid.uuid4().hex[:8]}"


def clean_env():
    """The caller's environment without slamd settings that would change
    the daemon or the replay (the namespace is always passed explicitly)."""
    return {k: v for k, v in os.environ.items() if not k.startswith("SLAMD_")}


class Daemon:
    """`slamd run --namespace NS` in the background, its log in `log`."""

    def __init__(self, binary, namespace, log_dir):
        self.namespace = namespace
        self.log = log_dir / f"{namespace}.log"
        with open(self.log, "wb") as out:
            self.proc = subprocess.Popen([str(binary), "run", "--namespace", namespace],
                                         stdout=out, stderr=subprocess.STDOUT, env=clean_env())
        self._await_ready(binary)

    def _await_ready(self, binary, wait_s=20.0):
        """Up once `slamd status` hears from it (it publishes every tick)."""
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                pytest.fail(f"slamd run exited with {self.proc.returncode}:\n{self.tail()}")
            r = subprocess.run([str(binary), "status", "--namespace", self.namespace,
                                "--wait", "1", "--json"],
                               capture_output=True, env=clean_env(), timeout=30)
            if r.returncode == 0:
                return
        pytest.fail(f"slamd run on `{self.namespace}` did not come up:\n{self.tail()}")

    def tail(self):
        return self.log.read_text(errors="replace")[-2000:]

    def shut_down(self):
        """SIGINT, then SIGTERM, then SIGKILL, waiting after each."""
        for sig, wait_s in ((signal.SIGINT, 10), (signal.SIGTERM, 5), (signal.SIGKILL, 5)):
            if self.proc.poll() is not None:
                return
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout=wait_s)
                return
            except subprocess.TimeoutExpired:
                continue


@pytest.fixture
def daemons(tmp_path):
    """Starts daemons on demand; shuts every one of them down, also on failure."""
    binary = slamd_bin()
    started = []

    def start(tag):
        d = Daemon(binary, fresh_namespace(tag), tmp_path)
        started.append(d)
        return d

    yield binary, start
    for d in started:
        d.shut_down()


