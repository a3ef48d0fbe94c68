"""What the live-view tests share: `slamd view` as a child process, a
Foxglove WebSocket client, a recording reader, a quiet daemon's last
snapshot and headless Chromium over the DevTools protocol."""

import asyncio
import base64
import json
import math
import os
import shutil
import signal
import struct
import subprocess
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
import websockets
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap.reader import make_reader

import slamd

from conftest import clean_env

TRAJECTORY = "/slamd/trajectory"
GRAPH = "/slamd/graph"
HEALTH = "/slamd/health"
ALL_TOPICS = {TRAJECTORY, GRAPH, HEALTH, "/slamd/newest", "/slamd/location", "/slamd/locations",
              "/slamd/map"}


class Viewer:
    """`slamd view` on free ports; its URLs read from what it prints."""

    def __init__(self, binary, namespace, *extra):
        self.proc = subprocess.Popen(
            [str(binary), "view", "--namespace", namespace, "--port", "0", "--page-port", "0",
             *map(str, extra)],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=clean_env(), text=True)
        self.lines = []
        self.urls = {}
        ready = threading.Event()

        def read():
            for line in self.proc.stdout:
                self.lines.append(line)
                key, _, value = line.strip().partition(": ")
                self.urls[key] = value
                if "foxglove" in self.urls and "page" in self.urls:
                    ready.set()
            ready.set()

        threading.Thread(target=read, daemon=True).start()
        if not ready.wait(30) or "foxglove" not in self.urls:
            self.proc.kill()
            pytest.fail(f"slamd view did not say where it serves: {''.join(self.lines)}")
        self.ws = self.urls["foxglove"]
        self.page = self.urls["page"]

    def stop(self):
        """SIGINT, then the exit code (it closes its recording first)."""
        self.proc.send_signal(signal.SIGINT)
        try:
            return self.proc.wait(20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            pytest.fail(f"slamd view did not stop on SIGINT: {''.join(self.lines)}")

    def alive(self):
        return self.proc.poll() is None


def quiet_snapshot(namespace, quiet_s=1.5, settle_s=60.0):
    """The daemon's settled snapshot (`settling` false: input answered,
    re-solves landed, the judge done) and switches, once it has published
    nothing newer for `quiet_s`."""
    snapshots = slamd.Snapshots(namespace)
    last = snapshots.wait(10.0)
    assert last is not None, "the daemon published no snapshot"
    deadline = time.monotonic() + settle_s
    while (newer := snapshots.wait(quiet_s)) is not None or last.settling:
        assert time.monotonic() < deadline, f"the daemon did not settle within {settle_s} s"
        last = newer or last
    return last, snapshots.switches()


async def foxglove_messages(url, topics, enough, timeout_s=20.0):
    """Subscribes to `topics` with the `foxglove.sdk.v1` subprotocol and
    returns {topic: newest payload} once `enough(it)` holds."""
    async with websockets.connect(url, subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
        assert ws.subprotocol == "foxglove.sdk.v1"
        by_sub, newest = {}, {}
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                m = await asyncio.wait_for(ws.recv(), deadline - time.monotonic())
            except asyncio.TimeoutError:
                break
            if isinstance(m, str):
                msg = json.loads(m)
                if msg["op"] == "advertise":
                    subs = []
                    for ch in msg["channels"]:
                        if ch["topic"] in topics:
                            by_sub[len(by_sub) + 1] = ch["topic"]
                            subs.append({"id": len(by_sub), "channelId": ch["id"]})
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                continue
            op, sub, _ = struct.unpack_from("<BIQ", m)
            if op == 1 and sub in by_sub:
                newest[by_sub[sub]] = bytes(m[13:])
                if topics <= newest.keys() and enough(newest):
                    return newest
        pytest.fail(f"no Foxglove messages that satisfy the test within {timeout_s} s: "
                    f"got {sorted(newest)}")


def recorded(path):
    """{topic: [payload, …]} of an MCAP file, in log-time order."""
    out = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        for _schema, channel, message in reader.iter_messages(log_time_order=True):
            out.setdefault(channel.topic, []).append(message.data)
    return out


def assert_trajectory_is_the_snapshot(trajectory: PosesInFrame, snap):
    """Every pose equals the daemon's to 1e-9: position and heading."""
    assert trajectory.frame_id == "map"
    got = np.array([[p.position.x, p.position.y, 2 * math.atan2(p.orientation.z, p.orientation.w)]
                    for p in trajectory.poses])
    want = snap.poses
    assert got.shape == want.shape
    assert np.abs(got[:, :2] - want[:, :2]).max() <= 1e-9
    turn = np.angle(np.exp(1j * (got[:, 2] - want[:, 2])))
    assert np.abs(turn).max() <= 1e-9


def off_segments(snap, switches, state="off"):
    """The sorted end points of the daemon's loop closures in `state`."""
    where = {int(i): row for i, row in zip(snap.ids, snap.poses)}
    segs = []
    for (a, b), s in zip(switches.edges, switches.states):
        if s == state and int(a) in where and int(b) in where:
            segs.append((tuple(where[int(a)][:2]), tuple(where[int(b)][:2])))
    return sorted(segs)


def drawn_segments(update: SceneUpdate, line):
    """The sorted end-point pairs of one line list of the graph entity."""
    graph = next(e for e in update.entities if e.id == "graph")
    pts = [(p.x, p.y) for p in graph.lines[line].points]
    return sorted(zip(pts[0::2], pts[1::2])), {kv.key: int(kv.value) for kv in graph.metadata}


def with_outliers(dataset_path, out, count, seed=1):
    """`dataset_path` with `count` random wrong loop closures (the shared
    tools' Vertigo-style generator)."""
    tool = dataset_path.parents[1] / "tools" / "add_outliers.py"
    subprocess.run(["python3", str(tool), "-i", str(dataset_path), "-o", str(out),
                    "--kind", "random", "--count", str(count), "--seed", str(seed)],
                   check=True, capture_output=True, timeout=120)
    return out


def replay(binary, namespace, path):
    r = subprocess.run([str(binary), "replay", "--namespace", namespace, str(path)],
                       capture_output=True, text=True, env=clean_env(), timeout=900)
    assert r.returncode == 0, r.stdout + r.stderr
    return r.stdout


class Chromium:
    """Headless Chromium on a page, driven over the DevTools protocol."""

    FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             "--window-size=1100,800", "--remote-debugging-port=0"]

    def __init__(self, url):
        exe = shutil.which("chromium") or shutil.which("chromium-browser")
        if exe is None:
            pytest.fail("no chromium on PATH: `apt-get install chromium` (.ci/run installs it)")
        self.profile = tempfile.mkdtemp(prefix="slamd-chromium-")
        self.proc = subprocess.Popen([exe, *self.FLAGS, f"--user-data-dir={self.profile}", url],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        port_file = Path(self.profile) / "DevToolsActivePort"
        deadline = time.monotonic() + 30
        while not port_file.is_file() or not port_file.read_text().strip():
            if time.monotonic() > deadline or self.proc.poll() is not None:
                self.close()
                pytest.fail("chromium did not open its DevTools port")
            time.sleep(0.1)
        port = int(port_file.read_text().split()[0])
        deadline = time.monotonic() + 30
        while True:
            targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list"))
            pages = [t for t in targets if t.get("type") == "page" and t["url"].startswith(url)]
            if pages:
                self.debugger = pages[0]["webSocketDebuggerUrl"]
                break
            if time.monotonic() > deadline:
                self.close()
                pytest.fail(f"chromium opened no page at {url}: {targets}")
            time.sleep(0.1)
        self.next_id = 0

    async def _call(self, method, **params):
        async with websockets.connect(self.debugger, max_size=None) as ws:
            self.next_id += 1
            await ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
            while True:
                msg = json.loads(await ws.recv())
                if msg.get("id") == self.next_id:
                    if "error" in msg:
                        raise RuntimeError(f"{method}: {msg['error']}")
                    return msg["result"]

    def evaluate(self, expression):
        r = asyncio.run(self._call("Runtime.evaluate", expression=expression, returnByValue=True))
        return r["result"].get("value")

    def screenshot(self, path):
        r = asyncio.run(self._call("Page.captureScreenshot", format="png"))
        Path(path).write_bytes(base64.b64decode(r["data"]))

    def close(self):
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)
        shutil.rmtree(self.profile, ignore_errors=True)


def screenshot_path(tmp_path):
    """Where the page's screenshot goes: `VIEW_SCREENSHOT` (to refresh the
    one in docs/), else the test's own directory."""
    return Path(os.environ.get("VIEW_SCREENSHOT", tmp_path / "page.png"))

