#!/usr/bin/env python3
"""Stream a g2o pose graph to a running slamd daemon, in pure Python.

Usage:
    SLAMD_NAMESPACE=slamd python3 iceoryx2_frontend.py FILE [--timeout S] [--guess]

Only the iceoryx2 Python package (``pip install iceoryx2==0.10.0``) and the
standard library are used: the message layouts below are written from
docs/protocol.md, not imported from slamd. The stream is what
``slamd replay FILE --namespace NS`` sends, in the same order:

1. keyframe ``k`` (ids sorted), then every edge whose newer end is ``k``,
   sorted by (newer, older) with ties in file order; consecutive ids are
   odometry, any other pair a loop closure;
2. one poke of the ``{ns}/ingest`` event;
3. when ``k`` brought edges, wait until a snapshot acknowledges the last
   of them (its header's ack for this frontend reaches that number).

Snapshots come as whole maps on ``{ns}/poses`` and, for every version, what
it changed on ``{ns}/changes``; ``Map`` puts the two together as
docs/clients.md ("Reading snapshots") says. After the last keyframe it
takes snapshots until one says the map is settled (the daemon's closing
re-solves are done), then prints the final map's
chi2 as a JSON object on the last line of stdout. ``chi2`` is computed
from the snapshot's poses over the file's edges, as ``slamd replay``
reports it; ``snapshot_chi2`` is the header's (with the outlier filter's
weights). 2-D (VERTEX_SE2/EDGE_SE2) and 3-D (VERTEX_SE3:QUAT/EDGE_SE3:QUAT)
files are read; a 3-D file needs a daemon started with SLAMD_DIMENSION=3.
"""

import argparse
import collections
import ctypes
import json
import math
import os
import sys
import time

import iceoryx2 as iox2

PROTOCOL_VERSION = 6
PROTOCOL_KEY = "slamd.protocol"
U32, U64, F64 = ctypes.c_uint32, ctypes.c_uint64, ctypes.c_double


def _named(name):
    """A class decorator giving a ctypes struct the iceoryx2 type name."""

    def wrap(cls):
        cls.type_name = staticmethod(lambda: name)
        return cls

    return wrap


@_named("slamd::Keyframe")
class Keyframe(ctypes.Structure):
    _fields_ = [("id", U64), ("timestamp_ns", U64), ("guess", F64 * 7),
                ("has_guess", U32), ("frontend", U32), ("sequence", U64),
                ("protocol", U32), ("dimension", U32)]


@_named("slamd::Edge")
class Edge(ctypes.Structure):
    _fields_ = [("from_", U64), ("to", U64), ("measurement", F64 * 7),
                ("information", F64 * 21), ("kind", U32), ("frontend", U32),
                ("sequence", U64), ("protocol", U32), ("dimension", U32)]


@_named("slamd::Pose")
class Pose(ctypes.Structure):
    _fields_ = [(n, U64 if n in ("id", "timestamp_ns") else F64) for n in
                ("id", "x", "y", "z", "qx", "qy", "qz", "qw", "theta",
                 "east", "north", "up", "heading", "timestamp_ns")]


@_named("slamd::FrontendAck")
class FrontendAck(ctypes.Structure):
    _fields_ = [("frontend", U32), ("reserved", U32), ("sequence", U64)]


@_named("slamd::SnapshotHeader")
class SnapshotHeader(ctypes.Structure):
    _fields_ = [("protocol", U32), ("dimension", U32), ("version", U64),
                ("poses", U64), ("chi2", F64), ("solved_at_ns", U64),
                ("keyframes", U64), ("edges", U64), ("rejected", U64),
                ("held", U64), ("resolves", U64), ("fixes", U64),
                ("georeferenced", U32), ("has_origin", U32),
                ("origin", F64 * 3), ("acks", FrontendAck * 8),
                ("has_covariance", U32), ("pending", U32),
                ("covariance_keyframe", U64), ("covariance", F64 * 21),
                ("base", U64), ("instance", U64), ("whole", U32), ("settling", U32)]


@_named("slamd::DaemonStatus")
class DaemonStatus(ctypes.Structure):
    _fields_ = [("protocol", U32), ("journal_failing", U32), ("instance", U64),
                ("started_at_ns", U64), ("checkpoint_at_ns", U64),
                ("journal_bytes", U64), ("frontends", U64),
                ("latency_p50_us", F64), ("latency_p99_us", F64),
                ("snapshot", SnapshotHeader), ("acks", FrontendAck * 8)]


@_named("slamd::Rejection")
class Rejection(ctypes.Structure):
    _fields_ = [("frontend", U32), ("reason", U32), ("sequence", U64),
                ("message", U32), ("reserved", U32), ("ids", U64 * 2),
                ("text", ctypes.c_char * 120)]


for _t, _size in ((Keyframe, 96), (Edge, 264), (Pose, 112), (SnapshotHeader, 456),
                  (DaemonStatus, 648), (Rejection, 160)):
    assert ctypes.sizeof(_t) == _size and ctypes.alignment(_t) == 8, _t


def ack_of(acks, frontend):
    """The number through which `frontend`'s messages were taken, if listed."""
    for a in acks:
        if a.frontend == frontend and frontend != 0:
            return a.sequence
    return None


# ---------------------------------------------------------------- the graph

def _unit(q):
    n = math.sqrt(sum(c * c for c in q))
    if abs(n - 1.0) > 1e-3:
        raise ValueError(f"quaternion norm {n} is not 1")
    q = [c / n for c in q]
    return [-c for c in q] if q[3] < 0 else q  # qw >= 0, as slamd writes it


def read_g2o(path):
    """Keyframe ids (sorted), guesses, edges (i, j, meas[7], info[21]), dim."""
    vertices, edges, dims = {}, [], set()
    with open(path) as f:
        for line in f:
            t = line.split()
            if not t or t[0].startswith("#") or t[0] == "FIX":
                continue
            tag = t[0]
            v = [float(x) for x in t[2:]] if tag.startswith("VERTEX") else None
            if tag == "VERTEX_SE2":
                dims.add(2)
                vertices[int(t[1])] = v[:3] + [0.0] * 4
            elif tag == "EDGE_SE2":
                dims.add(2)
                v = [float(x) for x in t[3:12]]
                edges.append((int(t[1]), int(t[2]), v[:3] + [0.0] * 4, v[3:] + [0.0] * 15))
            elif tag == "VERTEX_SE3:QUAT":
                dims.add(3)
                vertices[int(t[1])] = v[:3] + _unit(v[3:7])
            elif tag == "EDGE_SE3:QUAT":
                dims.add(3)
                v = [float(x) for x in t[3:31]]
                edges.append((int(t[1]), int(t[2]), v[:3] + _unit(v[3:7]), v[7:]))
            else:
                raise ValueError(f"{path}: unsupported record {tag}")
    if len(dims) != 1:
        raise ValueError(f"{path}: no graph, or 2-D and 3-D records mixed")
    ends = {e[0] for e in edges} | {e[1] for e in edges}
    if vertices and not ends <= set(vertices):
        raise ValueError(f"{path}: edges name undeclared keyframes {sorted(ends - set(vertices))[:5]}")
    ids = sorted(vertices) if vertices else sorted(ends)
    return ids, vertices, edges, dims.pop()


def stream(ids, edges):
    """Per keyframe index, the edges whose newer end it is, in time order."""
    index = {k: n for n, k in enumerate(ids)}
    steps = [[] for _ in ids]
    order = sorted(range(len(edges)), key=lambda e: (max(index[edges[e][0]], index[edges[e][1]]),
                                                     min(index[edges[e][0]], index[edges[e][1]])))
    for e in order:
        steps[max(index[edges[e][0]], index[edges[e][1]])].append(edges[e])
    return steps


# ------------------------------------------------------------------ the link

class Link:
    """The frontend's ports and its side of flow control (acks, restarts)."""

    def __init__(self, namespace, backpressure_s=0.2, reconnect_s=30.0):
        iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
        self.ns, self.backpressure_s, self.reconnect_s = namespace, backpressure_s, reconnect_s
        self.node = (iox2.NodeBuilder.new().name(iox2.NodeName.new("slamd-py-frontend"))
                     .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
                     .create(iox2.ServiceType.Ipc))
        self.attrs = iox2.AttributeVerifier.new().require(
            iox2.AttributeKey.new(PROTOCOL_KEY), iox2.AttributeValue.new(str(PROTOCOL_VERSION)))
        discard = iox2.BackpressureStrategy.DiscardData  # a full queue: 0 recipients
        self.keyframes = self._topic("keyframes", Keyframe).publisher_builder() \
            .backpressure_strategy(discard).create()
        self.edges = self._topic("edges", Edge).publisher_builder() \
            .backpressure_strategy(discard).create()
        self.status = self._topic("status", DaemonStatus).subscriber_builder().create()
        self.poses = self._topic("poses", iox2.Slice[Pose], SnapshotHeader) \
            .subscriber_builder().create()
        self.changes = self._topic("changes", iox2.Slice[Pose], SnapshotHeader) \
            .subscriber_builder().create()
        self.map = Map()
        self.rejections = self._topic("rejections", Rejection).subscriber_builder().create()
        self.ingest = self._event("ingest").notifier_builder().create()
        self.published = self._event("published").listener_builder().create()
        # nonzero (0 is "no id": never acknowledged) and distinct per process
        self.id = ((os.getpid() * 2654435761) & 0xFFFFFFFF) or 1
        self.sequence = 0
        self.outbox = collections.deque()  # (sequence, publisher, message) not yet acknowledged
        self.acked = 0
        self.resent = 0
        self.full = 0  # sends that found the daemon's queue full
        # the daemon serving now (status has a history of 1; it also comes every tick)
        self.first_status = self._await_status(0.5)
        self.instance = self.first_status.instance if self.first_status else 0
        self.heard = time.monotonic()  # the daemon's last snapshot or status
        self.holding = False  # its last status said its journal cannot be written

    def _name(self, suffix):
        return iox2.ServiceName.new(f"{self.ns.rstrip('/')}/{suffix}")

    def _topic(self, suffix, payload, header=None):
        b = self.node.service_builder(self._name(suffix)).publish_subscribe(payload)
        if header is not None:
            b = b.user_header(header)
        try:
            return b.open_with_attributes(self.attrs)
        except iox2.PublishSubscribeOpenError as e:
            raise SystemExit(f"cannot open {self.ns}/{suffix} ({e!r}): is `slamd run` serving "
                             f"namespace `{self.ns}`, with protocol {PROTOCOL_VERSION}?")

    def _event(self, suffix):
        try:
            return self.node.service_builder(self._name(suffix)).event() \
                .open_with_attributes(self.attrs)
        except iox2.EventOpenError as e:
            raise SystemExit(f"cannot open {self.ns}/{suffix} ({e!r}): no daemon?")

    # -- sending

    def _next(self):
        self.sequence += 1
        return self.sequence

    def send_keyframe(self, kid, guess, dimension):
        seq = self._next()
        m = Keyframe(id=kid, timestamp_ns=time.time_ns(), has_guess=int(guess is not None),
                     frontend=self.id, sequence=seq, protocol=PROTOCOL_VERSION,
                     dimension=dimension)
        if guess is not None:
            m.guess[:] = guess
        return self._send(self.keyframes, m)

    def send_edge(self, i, j, measurement, information, dimension):
        seq = self._next()
        m = Edge(from_=i, to=j, kind=0 if abs(i - j) == 1 else 1, frontend=self.id,
                 sequence=seq, protocol=PROTOCOL_VERSION, dimension=dimension)
        m.measurement[:] = measurement
        m.information[:] = information
        return self._send(self.edges, m)

    def _send(self, publisher, m):
        """Keeps `m` until acknowledged and publishes it; returns its number."""
        self.outbox.append((m.sequence, publisher, m))
        if publisher.send_copy(m) == 0 and not self._await_room(publisher, m):
            raise SystemExit(f"the daemon serving `{self.ns}` took nothing for "
                             f"{self.reconnect_s:.0f} s: gone?")
        return m.sequence

    def _await_room(self, publisher, m):
        """The daemon's queue was full (0 recipients): poke it and retry for the
        backpressure time, then wait for it or a restarted daemon to take it."""
        self.full += 1
        start = time.monotonic()
        before = self.instance
        while time.monotonic() - start < self.reconnect_s:
            self.poke()
            time.sleep(0.001 if time.monotonic() - start < self.backpressure_s else 0.01)
            self.poll()
            if self.instance != before:
                return True  # sent again with the rest of the outbox
            if publisher.send_copy(m) > 0:
                return True
        return False

    def poke(self):
        self.ingest.notify()

    # -- acknowledgements

    def _await_status(self, wait_s):
        deadline = time.monotonic() + wait_s
        while True:
            s = self.latest_status()
            if s is not None or time.monotonic() > deadline:
                return s
            time.sleep(0.005)

    def latest_status(self):
        newest = None
        while True:
            s = self.status.receive()
            if s is None:
                return newest
            newest = DaemonStatus.from_buffer_copy(s.payload().contents)
            s.delete()

    def refresh(self):
        """Forgets what the daemon acknowledged; after a daemon restart sends
        again whatever the new one lacks. True if anything was sent again."""
        s = self.latest_status()
        if s is None:
            return False
        # a status is a sign of life, also from a daemon that holds its acks
        self.heard, self.holding = time.monotonic(), s.journal_failing != 0
        acked = ack_of(s.acks, self.id) or 0
        self.forget_through(acked)
        if s.instance == self.instance:
            return False
        self.instance = s.instance
        deadline = time.monotonic() + self.reconnect_s
        for n, (_, publisher, m) in enumerate(list(self.outbox)):
            while publisher.send_copy(m) == 0:
                if time.monotonic() > deadline:
                    raise SystemExit(f"the daemon serving `{self.ns}` takes nothing: gone?")
                self.poke()
                time.sleep(0.001)
            self.resent += 1
            if n % 256 == 255:
                self.poke()
        return bool(self.outbox)

    def forget_through(self, acked):
        self.acked = max(self.acked, acked)
        while self.outbox and self.outbox[0][0] <= acked:
            self.outbox.popleft()

    def flush(self):
        self.refresh()
        self.poke()

    def poll(self):
        if self.refresh():
            self.poke()

    # -- snapshots

    def latest_snapshot(self):
        """Takes every whole map and change delivered into the map; the
        newest header among them, or None (never blocks)."""
        newest = None
        for topic, take in ((self.poses, self.map.whole), (self.changes, self.map.change)):
            while True:
                s = topic.receive()
                if s is None:
                    break
                h = header_of(s)
                take(h, poses_of(s))
                s.delete()  # at most 3 may be borrowed at once
                if newest is None or (h.instance, h.version) > (newest.instance, newest.version):
                    newest = h
        return newest

    def wait_snapshot(self, timeout_s):
        deadline = time.monotonic() + timeout_s
        while True:
            s = self.latest_snapshot()
            if s is not None:
                return s
            left = deadline - time.monotonic()
            if left < 2e-6:  # a zero timeout would wait forever
                return None
            self.published.timed_wait(iox2.Duration.from_secs_f64(left))

    def our_rejections(self):
        out = []
        while True:
            r = self.rejections.receive()
            if r is None:
                return out
            m = Rejection.from_buffer_copy(r.payload().contents)
            r.delete()
            if m.frontend == self.id:
                out.append(m)


def header_of(sample):
    return SnapshotHeader.from_buffer_copy(sample.user_header().contents)


class Map:
    """The daemon's map as a subscriber builds it: a whole map from
    ``{ns}/poses``, then each version's changes from ``{ns}/changes`` whose
    ``base`` is the version held. A change that cannot be placed yet (its map
    has not come, or one before it was lost) waits for a whole map."""

    def __init__(self):
        self.header, self.poses, self.waiting = None, {}, {}

    def _holds(self, h):
        return (self.header is not None and h.instance == self.header.instance
                and h.version <= self.header.version)

    def whole(self, h, poses):
        if self._holds(h):
            return
        self.header, self.poses = h, {p.id: p for p in poses}
        self.waiting = {k: w for k, w in self.waiting.items()
                        if k[0] == h.instance and k[1] >= h.version}
        self._place()

    def change(self, h, poses):
        if not self._holds(h):
            self.waiting[(h.instance, h.base)] = (h, poses)
            self._place()

    def _place(self):
        while self.header is not None:
            key = (self.header.instance, self.header.version)
            w = self.waiting.get(key)
            if w is None or w[0].whole:  # a whole version's map comes on {ns}/poses
                return
            del self.waiting[key]
            self.header = w[0]
            self.poses.update((p.id, p) for p in w[1])


def poses_of(sample):
    # the element count is the header's `poses` (iceoryx2-python 0.10's
    # Slice.len() of a Rust-sent slice counts bytes, not elements)
    n = min(header_of(sample).poses, sample.header.number_of_elements)
    if n == 0:
        return []
    p = sample.payload()
    return (Pose * n).from_buffer_copy(ctypes.string_at(p.as_ptr(), n * ctypes.sizeof(Pose)))


# ------------------------------------------------------------- the replay

RESTART_POLL = 0.05  # s between looks at the acks while waiting
SAY_EVERY_S = 5.0  # s between notes on a daemon that is alive but holding


class Replay:
    def __init__(self, link, timeout_s):
        self.link, self.timeout_s = link, timeout_s
        self.pending = collections.deque()  # (keyframe index, last message number)

    def collect(self, wait_s):
        deadline = time.monotonic() + wait_s
        while True:
            left = max(0.0, deadline - time.monotonic())
            s = self.link.wait_snapshot(min(left, RESTART_POLL))
            if s is not None:
                self.link.heard = time.monotonic()
                break
            self.link.poll()
            if left <= RESTART_POLL:
                return
        acked = ack_of(s.acks, self.link.id)
        if acked is not None:
            while self.pending and self.pending[0][1] <= acked:
                self.pending.popleft()

    def drain(self):
        """Waits for the acknowledgement of every keyframe sent while the daemon
        shows it is alive (a snapshot or a status within the timeout); says why
        every SAY_EVERY_S while it holds its acknowledgements."""
        self.link.heard, waiting, said = time.monotonic(), time.monotonic(), None
        while self.pending:
            now = time.monotonic()
            left = self.link.heard + self.timeout_s - now
            if left <= 0:
                raise SystemExit(f"the daemon serving `{self.link.ns}` did not answer within "
                                 f"{self.timeout_s:.1f} s (is `slamd run` alive?)")
            if now - waiting >= self.timeout_s and (said is None or now - said >= SAY_EVERY_S):
                said = now
                why = ("holds its acknowledgements: its journal cannot be written (a full disk?)"
                       if self.link.holding else "has not acknowledged yet")
                print(f"the daemon serving `{self.link.ns}` is alive but {why}; waiting "
                      f"({now - waiting:.0f} s so far)", file=sys.stderr)
            self.collect(min(left, SAY_EVERY_S))

    def keyframe(self, k, kid, guess, edges, dim):
        last = self.link.send_keyframe(kid, guess, dim)
        for i, j, z, info in edges:
            last = self.link.send_edge(i, j, z, info, dim)
        self.link.flush()
        if edges:
            self.pending.append((k, last))
        self.drain()

    def finish(self):
        """The settled map: snapshots until one says the daemon's work on the
        stream is done (``settling`` 0, nothing ``pending``), for as long as
        the daemon is alive (while other frontends' input keeps it busy, at
        most max(timeout, 30 s))."""
        self.drain()
        self.link.heard = time.monotonic()
        deadline = time.monotonic() + max(self.timeout_s, 30.0)
        def given(h):
            return None if h is None else (h.keyframes, h.edges, h.fixes)
        ours = given(self.link.map.header)
        while True:
            if self.link.wait_snapshot(RESTART_POLL) is not None:
                self.link.heard = time.monotonic()
            h = self.link.map.header
            if h is not None and h.settling == 0 and h.pending == 0:
                break
            if time.monotonic() > deadline and given(h) != ours:
                break  # other frontends keep it busy
            self.link.poll()
            if time.monotonic() - self.link.heard > self.timeout_s:
                raise SystemExit(f"the daemon serving `{self.link.ns}` did not answer within "
                                 f"{self.timeout_s:.1f} s (is `slamd run` alive?)")
        m = self.link.map
        if m.header is None:
            raise SystemExit("no snapshot arrived")
        return m.header, list(m.poses.values())


# ------------------------------------------------------------------ chi2

def _wrap(a):
    r = a % (2.0 * math.pi)
    return r - 2.0 * math.pi if r > math.pi else r


def _upper_quadratic(info, e):
    """e^T Ω e with Ω given as its upper triangle, row by row."""
    n, k, total = len(e), 0, 0.0
    for r in range(n):
        for c in range(r, n):
            total += info[k] * e[r] * e[c] * (1.0 if r == c else 2.0)
            k += 1
    return total


def _qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def _rotate(q, v):
    x, y, z, _ = _qmul(_qmul(q, (v[0], v[1], v[2], 0.0)), (-q[0], -q[1], -q[2], q[3]))
    return (x, y, z)


def _between3(a, b):
    """a⁻¹ b for poses (t, q)."""
    qi = (-a[1][0], -a[1][1], -a[1][2], a[1][3])
    d = tuple(bt - at for bt, at in zip(b[0], a[0]))
    return (_rotate(qi, d), _qmul(qi, b[1]))


def _pose3(p):
    return ((p.x, p.y, p.z), _norm((p.qx, p.qy, p.qz, p.qw)))


def chi2(poses, edges, dim):
    """Σ eᵀ Ω e over `edges` at `poses`, slamd's (and g2o's) error."""
    by_id = {p.id: p for p in poses}
    total = 0.0
    for i, j, z, info in edges:
        a, b = by_id[i], by_id[j]
        if dim == 2:
            c, s = math.cos(a.theta), math.sin(a.theta)
            dx, dy = b.x - a.x, b.y - a.y
            px, py = c * dx + s * dy - z[0], -s * dx + c * dy - z[1]
            cm, sm = math.cos(z[2]), math.sin(z[2])
            e = (cm * px + sm * py, -sm * px + cm * py, _wrap(_wrap(b.theta - a.theta) - z[2]))
            total += _upper_quadratic(info[:6], e)
        else:
            t, q = _between3((tuple(z[:3]), tuple(z[3:7])), _between3(_pose3(a), _pose3(b)))
            if q[3] < 0:
                q = tuple(-c for c in q)
            total += _upper_quadratic(info, (t[0], t[1], t[2], q[0], q[1], q[2]))
    return total


def _norm(q):
    n = math.sqrt(sum(c * c for c in q))
    return tuple(c / n for c in q)


# ------------------------------------------------------------------- main

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("file")
    ap.add_argument("--timeout", type=float, default=5.0,
                    help="seconds to wait for the daemon's answer (default 5)")
    ap.add_argument("--guess", action="store_true",
                    help="send the file's VERTEX poses as initial guesses")
    args = ap.parse_args()
    namespace = os.environ.get("SLAMD_NAMESPACE", "slamd")
    ids, vertices, edges, dim = read_g2o(args.file)
    link = Link(namespace)
    status = link.first_status
    if status is not None and status.snapshot.dimension != dim:
        raise SystemExit(f"the daemon serving `{namespace}` serves {status.snapshot.dimension}-D "
                         f"graphs and this graph is {dim}-D (start it with SLAMD_DIMENSION={dim})")
    replay = Replay(link, args.timeout)
    start = time.monotonic()
    for k, (kid, group) in enumerate(zip(ids, stream(ids, edges))):
        replay.keyframe(k, kid, vertices.get(kid) if args.guess else None, group, dim)
    header, poses = replay.finish()
    total_s = time.monotonic() - start
    for r in link.our_rejections():
        print(f"rejected message {r.sequence} (reason {r.reason}): "
              f"{r.text.decode(errors='replace')}", file=sys.stderr)
    missing = set(ids) - {p.id for p in poses}
    if missing:
        raise SystemExit(f"{len(missing)} keyframes are missing from the final snapshot")
    print(json.dumps({
        "chi2": chi2(poses, edges, dim), "snapshot_chi2": header.chi2,
        "keyframes": len(poses), "edges": int(header.edges), "rejected": int(header.rejected),
        "resolves": int(header.resolves), "version": int(header.version),
        "frontend": link.id, "resent": link.resent, "full_queue": link.full, "total_s": round(total_s, 3),
    }))


if __name__ == "__main__":
    main()
