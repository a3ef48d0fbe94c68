"""`slamd view`: Foxglove clients, its recording and its page show what
the daemon serves, and bad clients do not stop it."""

import asyncio
import json
import math
import re
import socket
import subprocess
import time

import pytest
import websockets
from foxglove_schemas_protobuf.LocationFixes_pb2 import LocationFixes
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

from conftest import REPO, clean_env, dataset, slamd_bin
from viewing import (ALL_TOPICS, GRAPH, HEALTH, TRAJECTORY, Chromium, Viewer, assert_trajectory_is_the_snapshot,
                     drawn_segments, foxglove_messages, off_segments, quiet_snapshot, recorded, replay,
                     screenshot_path, with_outliers)

MANHATTAN = "manhattanolson3500.g2o"


def test_foxglove_clients_and_the_recording_show_the_daemons_map(daemons, tmp_path):
    binary, start = daemons
    d = start("view")
    viewer = Viewer(binary, d.namespace, "--record", tmp_path / "run.mcap")
    replay(binary, d.namespace, with_outliers(dataset(MANHATTAN), tmp_path / "m100.g2o", 100))
    snap, switches = quiet_snapshot(d.namespace)
    assert len(snap.ids) == 3500
    assert "off" in switches.states, "the filter switched none of 100 wrong loop closures off"

    def current(m):
        # the viewer has drawn the snapshot's version, not an older one of
        # the same size
        t = PosesInFrame.FromString(m[TRAJECTORY])
        return len(t.poses) == len(snap.ids) and json.loads(m[HEALTH])["version"] == snap.version

    got = asyncio.run(foxglove_messages(viewer.ws, {TRAJECTORY, GRAPH, HEALTH}, current))
    assert_trajectory_is_the_snapshot(PosesInFrame.FromString(got[TRAJECTORY]), snap)
    update = SceneUpdate.FromString(got[GRAPH])
    drawn, counts = drawn_segments(update, line=2)
    assert drawn == off_segments(snap, switches, "off")
    assert counts == {s: switches.states.count(s) for s in ("kept", "off", "pending")}

    assert viewer.stop() == 0
    rec = recorded(tmp_path / "run.mcap")
    assert {TRAJECTORY, GRAPH, HEALTH, "/slamd/newest", "/slamd/map"} <= rec.keys()
    assert_trajectory_is_the_snapshot(PosesInFrame.FromString(rec[TRAJECTORY][-1]), snap)
    health = json.loads(rec[HEALTH][-1])
    assert health["keyframes"] == 3500 and health["version"] == snap.version


def test_a_recording_of_the_demo_holds_every_channel_and_the_final_map(tmp_path):
    binary = slamd_bin()
    rec = tmp_path / "demo.mcap"
    out = subprocess.run([str(binary), "demo", "--poses", "600", "--gps", "--record", str(rec),
                          "--out", str(tmp_path / "demo.svg")],
                         capture_output=True, text=True, env=clean_env(), timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    printed = next(float(line.split()[1]) for line in out.stdout.splitlines() if line.startswith("slamd "))
    messages = recorded(rec)
    assert messages.keys() == ALL_TOPICS
    last = PosesInFrame.FromString(messages[TRAJECTORY][-1])
    assert len(last.poses) == 600
    assert len(LocationFixes.FromString(messages["/slamd/locations"][-1]).fixes) == 600
    # the last trajectory scored on the same world is the χ² the demo printed
    world = tmp_path / "world.g2o"
    subprocess.run([str(binary), "synth", "--poses", "600", "--seed", "7", "--out", str(world),
                    "--truth", str(tmp_path / "truth.txt")], check=True, env=clean_env(), timeout=120)
    table = tmp_path / "last.txt"
    with open(table, "w") as f:
        for i, p in enumerate(last.poses):
            theta = 2 * math.atan2(p.orientation.z, p.orientation.w)
            f.write(f"{i} {p.position.x!r} {p.position.y!r} {theta!r}\n")
    scored = subprocess.run([str(binary), "eval", str(world), str(table), "--json"],
                            capture_output=True, text=True, env=clean_env(), timeout=120)
    assert scored.returncode == 0, scored.stderr
    assert abs(json.loads(scored.stdout)["chi2"] - printed) <= 0.005 + 1e-9 * printed


def test_the_page_draws_the_daemons_map_during_a_replay(daemons, tmp_path):
    binary, start = daemons
    d = start("page")
    viewer = Viewer(binary, d.namespace)
    browser = Chromium(viewer.page)
    try:
        deadline = time.monotonic() + 20
        while not browser.evaluate("window.slamdView && window.slamdView.connected"):
            assert time.monotonic() < deadline, "the page did not connect to the viewer"
            time.sleep(0.1)
        replay(binary, d.namespace, with_outliers(dataset(MANHATTAN), tmp_path / "m100.g2o", 100))
        snap, switches = quiet_snapshot(d.namespace)
        deadline = time.monotonic() + 20
        while (view := browser.evaluate("JSON.stringify(window.slamdView)")) is None or \
                json.loads(view)["version"] != snap.version:
            assert time.monotonic() < deadline, f"the page stayed behind: {view and view[:200]}"
            time.sleep(0.2)
        view = json.loads(view)
        assert view["frames"] > 1, "the page drew the map as it grew"
        drawn = view["poses"]
        assert [p[0] for p in drawn] == [int(i) for i in snap.ids]
        assert max(abs(p[1] - q[0]) + abs(p[2] - q[1]) for p, q in zip(drawn, snap.poses)) <= 1e-9
        for state in ("kept", "off", "pending"):
            want = sorted((int(a), int(b)) for (a, b), s in zip(switches.edges, switches.states) if s == state)
            assert sorted(map(tuple, view["loops"][state])) == want, state
        assert view["loops"]["off"], "no loop closure drawn switched off"
        shot = screenshot_path(tmp_path)
        browser.screenshot(shot)
        assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    finally:
        browser.close()
        assert viewer.stop() == 0


def test_bad_clients_do_not_stop_the_view(daemons, tmp_path):
    binary, start = daemons
    d = start("bad")
    viewer = Viewer(binary, d.namespace)
    host, port = viewer.ws.removeprefix("ws://").split(":")
    page_port = int(viewer.page.removeprefix("http://").split(":")[1].rstrip("/"))
    # connects and never reads: a WebSocket that subscribes to everything
    silent = socket.create_connection((host, int(port)))
    silent.sendall(b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                   b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
                   b"Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n")
    # garbage on both ports, raw and inside a WebSocket
    for p in (int(port), page_port):
        with socket.create_connection((host, p)) as s:
            s.sendall(bytes(range(256)) * 8)
    idle_page = socket.create_connection((host, page_port))

    async def scenario():
        async with websockets.connect(viewer.ws, subprotocols=["foxglove.sdk.v1"]) as ws:
            await ws.send("{not json")
            await ws.send(b"\x07\x00\x01")
        # 20 at once that subscribe to everything, then never read again
        crowd = []
        for _ in range(20):
            ws = await websockets.connect(viewer.ws, subprotocols=["foxglove.sdk.v1"], max_size=None,
                                          max_queue=1)
            while (msg := json.loads(await ws.recv()))["op"] != "advertise":
                pass
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": i, "channelId": c["id"]} for i, c in enumerate(msg["channels"])]}))
            crowd.append(ws)
        await asyncio.to_thread(replay, binary, d.namespace, dataset(MANHATTAN))
        snap, _ = await asyncio.to_thread(quiet_snapshot, d.namespace)
        got = await foxglove_messages(
            viewer.ws, {TRAJECTORY}, lambda m: len(PosesInFrame.FromString(m[TRAJECTORY]).poses) == 3500)
        assert_trajectory_is_the_snapshot(PosesInFrame.FromString(got[TRAJECTORY]), snap)
        for ws in crowd:
            ws.transport.abort()

    asyncio.run(scenario())
    assert viewer.alive()
    silent.close()
    idle_page.close()
    assert viewer.stop() == 0


def test_the_foxglove_layout_shows_the_views_topics_in_every_panel():
    layout = json.loads((REPO / "docs" / "foxglove-layout.json").read_text())
    topics = set(re.findall(r"/slamd/[a-z]+", json.dumps(layout["configById"])))
    assert {TRAJECTORY, GRAPH, HEALTH, "/slamd/location"} <= topics <= ALL_TOPICS

    def panels(node):
        return [node] if isinstance(node, str) else panels(node["first"]) + panels(node["second"])

    assert sorted(panels(layout["layout"])) == sorted(layout["configById"])
