#!/usr/bin/env python3
"""What the live view costs the daemon, and what it costs itself.

    target/python-venv/bin/python benches/view.py [--pairs 3] [--paced-s 60]

1. Manhattan through a fresh `slamd run`, the modes alternated `--pairs`
   times: no viewer; `slamd view` with one Foxglove client reading every
   channel; `slamd view` with 20 clients that subscribe to every channel
   and never read, after garbage on both of its ports. Prints total, p50,
   p99 and max wait per keyframe of each run, and each mode's median
   total over the median without a viewer.
2. City10000 through the daemon with `slamd view` and one reading client:
   the viewer's CPU time (utime + stime) over the whole replay, the frames
   it published and its CPU per frame; then, on a daemon that holds all of
   City10000, `--paced-s` seconds of new keyframes at 10 a second from the
   Python frontend: the viewer's share of one core.

Run it with the Python of `python/run_tests.sh`, which has the `slamd`
package and `websockets`: `target/python-venv/bin/python benches/view.py`.
The binary is target/release/slamd (build it first) or $SLAMD_BIN.
"""
import argparse, asyncio, json, os, signal, socket, statistics, subprocess, threading, time
import websockets
from common import BIN, DATA

MANHATTAN = os.path.join(DATA, "manhattanolson3500.g2o")
CITY = os.path.join(DATA, "city10000.g2o")
TICK = os.sysconf("SC_CLK_TCK")


def quiet_env():
    return {k: v for k, v in os.environ.items() if not k.startswith("SLAMD_")}


class Process:
    def __init__(self, *args, stdout=subprocess.DEVNULL):
        self.p = subprocess.Popen([BIN, *args], env=quiet_env(), stdout=stdout, stderr=subprocess.DEVNULL, text=True)

    def cpu_s(self):
        fields = open(f"/proc/{self.p.pid}/stat").read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / TICK

    def stop(self):
        self.p.send_signal(signal.SIGINT)
        try:
            return self.p.communicate(timeout=30)[0]
        except subprocess.TimeoutExpired:
            self.p.kill()
            return self.p.communicate()[0]


def daemon(tag):
    ns = f"slamd-view-bench-{os.getpid()}-{tag}"
    d = Process("run", "--namespace", ns)
    subprocess.run([BIN, "status", "--namespace", ns, "--wait", "10"], capture_output=True, env=quiet_env())
    return ns, d


def viewer(ns):
    v = Process("view", "--namespace", ns, "--port", "0", "--page-port", "0", stdout=subprocess.PIPE)
    urls = {}
    while len(urls) < 2:
        key, _, value = v.p.stdout.readline().strip().partition(": ")
        urls[key] = value
    return v, urls


class Clients:
    """Foxglove clients on their own event loop: `reading` that read every
    message, `stalled` that subscribe to everything and never read."""

    def __init__(self, url, reading=0, stalled=0):
        self.url, self.reading, self.stalled = url, reading, stalled
        self.received = 0
        self.loop = asyncio.new_event_loop()
        self.ready = threading.Event()
        self.thread = threading.Thread(target=self.loop.run_until_complete, args=(self.main(),), daemon=True)
        self.thread.start()
        self.ready.wait(30)

    async def subscribed(self, max_queue):
        ws = await websockets.connect(self.url, subprotocols=["foxglove.sdk.v1"], max_size=None,
                                      max_queue=max_queue, ping_interval=None)
        while (m := json.loads(await ws.recv()))["op"] != "advertise":
            pass
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": i, "channelId": c["id"]} for i, c in enumerate(m["channels"])]}))
        return ws

    async def read(self, ws):
        async for _ in ws:
            self.received += 1

    async def main(self):
        self.stop = asyncio.Event()
        readers = [await self.subscribed(16) for _ in range(self.reading)]
        stalled = [await self.subscribed(1) for _ in range(self.stalled)]
        tasks = [asyncio.ensure_future(self.read(ws)) for ws in readers]
        self.ready.set()
        await self.stop.wait()
        for ws in readers + stalled:
            ws.transport.abort()
        for t in tasks:
            t.cancel()

    def close(self):
        self.loop.call_soon_threadsafe(self.stop.set)
        self.thread.join(30)


def garbage(urls):
    for url in (urls["foxglove"].removeprefix("ws://"), urls["page"].removeprefix("http://").rstrip("/")):
        host, port = url.split(":")
        with socket.create_connection((host, int(port))) as s:
            s.sendall(bytes(range(256)) * 8)


def replay(ns, path, *extra, timeout=None):
    args = [BIN, "replay", path, "--namespace", ns, "--json", *extra]
    out = subprocess.run(args, check=True, capture_output=True, text=True, env=quiet_env(), timeout=timeout).stdout
    return json.loads(out.strip().splitlines()[-1])


def overhead(pairs):
    print("| mode | total s | p50 µs | p99 ms | max ms | median total / no viewer |")
    print("|---|---|---|---|---|---|")
    modes = ["no viewer", "viewer + 1 reading client", "viewer + 20 stalled clients + garbage"]
    runs = {m: [] for m in modes}
    for i in range(pairs):
        for m in modes:
            ns, d = daemon(f"{i}-{modes.index(m)}")
            v = clients = None
            if m != modes[0]:
                v, urls = viewer(ns)
                if m == modes[2]:
                    garbage(urls)
                clients = Clients(urls["foxglove"], reading=int(m == modes[1]), stalled=20 * int(m == modes[2]))
            runs[m].append(replay(ns, MANHATTAN))
            if clients:
                clients.close()
            if v:
                v.stop()
            d.stop()
    base = statistics.median(r["total_s"] for r in runs[modes[0]])
    for m, rs in runs.items():
        col = lambda key, scale, fmt: "/".join(format(r[key] * scale, fmt) for r in rs)
        ratio = statistics.median(r["total_s"] for r in rs) / base
        print(f"| {m} | {col('total_s', 1, '.2f')} | {col('p50_us', 1, '.0f')} | {col('p99_us', 1e-3, '.2f')} "
              f"| {col('max_us', 1e-3, '.1f')} | {ratio:.3f} |")


def viewer_cpu(paced_s):
    ns, d = daemon("city")
    v, urls = viewer(ns)
    clients = Clients(urls["foxglove"], reading=1)
    c0, t0 = v.cpu_s(), time.monotonic()
    r = replay(ns, CITY)
    cpu, wall = v.cpu_s() - c0, time.monotonic() - t0
    clients.close()
    frames = int(v.stop().split("frames: ")[1].split()[0])
    d.stop()
    print(f"City10000 at full speed ({r['total_s']:.1f} s): viewer CPU {cpu:.2f} s over {wall:.1f} s ({100 * cpu / wall:.1f}% of a core), "
          f"{frames} frames, {1e3 * cpu / max(frames, 1):.1f} ms CPU per frame")

    ns, d = daemon("paced")
    replay(ns, CITY)
    v, urls = viewer(ns)
    clients = Clients(urls["foxglove"], reading=1)
    time.sleep(1.0)
    c0 = v.cpu_s()
    added = extend(ns, 9999, 10.0, paced_s)
    cpu = v.cpu_s() - c0
    clients.close()
    frames = int(v.stop().split("frames: ")[1].split()[0])
    d.stop()
    print(f"City10000, then {added} more keyframes at 10 per second ({paced_s} s, the map at 10,000+): "
          f"viewer CPU {cpu:.2f} s ({100 * cpu / paced_s:.1f}% of a core), {frames} frames, "
          f"{1e3 * cpu / max(frames, 1):.1f} ms CPU per frame")


def extend(ns, last, rate, seconds):
    """Keyframes after `last`, one step forward each, at `rate` a second
    for `seconds` through the Python frontend; returns how many."""
    import slamd
    f = slamd.Frontend(ns)
    start, n = time.monotonic(), 0
    while time.monotonic() - start < seconds:
        k = last + 1 + n
        f.add_keyframe(k)
        f.add_edge(k - 1, k, [1.0, 0.0, 0.0], [100.0, 0.0, 0.0, 100.0, 0.0, 1000.0], "odometry")
        f.flush()
        n += 1
        time.sleep(max(0.0, start + n / rate - time.monotonic()))
    return n


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--paced-s", type=int, default=60)
    a = ap.parse_args()
    print(f"`target/python-venv/bin/python benches/view.py --pairs {a.pairs} --paced-s {a.paced_s}`")
    print()
    overhead(a.pairs)
    print()
    viewer_cpu(a.paced_s)


if __name__ == "__main__":
    main()
