#!/usr/bin/env python3
"""Streaming a graph into `slamd.Engine` from Python against the Rust
embedded replay of the same graph, in one run.

    cargo build --release --bin slamd
    pip install ./python            # the release build of the package
    python3 benches/python_engine.py [--files city10000.g2o] [--repeat 3]

Both sides stream the same keyframes in the same order: keyframe k, then
every edge whose newer end it is (file order), then one update; after the
last keyframe, an inline re-solve over everything (`resolve_now`). Rust:
`slamd replay FILE --embedded --json`, its `total_s`. Python: the same loop
on `slamd.Engine()` (default settings, background re-solves), timed from
the first keyframe to the closing re-solve; the edges are turned into
Python lists before the clock starts, as replay builds its steps first.
The runs alternate and each figure is the best of --repeat.

A second table gives what one marginal covariance costs on the engine the
last Python stream left (the mean of 50 calls): of the newest keyframe (what
a daemon puts in every snapshot header), one from the middle, and the first
past the gauge.
"""
import argparse, json, os, subprocess, time

import slamd
from common import BIN, DATA


def steps(graph):
    """Per keyframe (file order): its id and the edges whose newer end it is."""
    index = {int(k): i for i, k in enumerate(graph.ids)}
    groups = [[] for _ in range(len(graph))]
    ends, meas, info, kinds = graph.edges.tolist(), graph.measurements.tolist(), graph.information.tolist(), graph.kinds
    for e, (a, b) in enumerate(ends):
        groups[max(index[a], index[b])].append((a, b, meas[e], info[e], kinds[e]))
    return list(zip(graph.ids.tolist(), groups))


def python_stream(graph):
    stream = steps(graph)
    engine = slamd.Engine(graph.dimension)
    start = time.perf_counter()
    for kid, edges in stream:
        engine.add_keyframe(kid)
        for a, b, z, omega, kind in edges:
            engine.add_edge(a, b, z, omega, kind)
        engine.update()
    engine.resolve_now()
    seconds = time.perf_counter() - start
    return seconds, engine.snapshot().chi2, engine


def marginal_ms(engine, keyframe, calls=50):
    start = time.perf_counter()
    for _ in range(calls):
        engine.marginal(keyframe)
    return (time.perf_counter() - start) / calls * 1e3


def rust_replay(path):
    out = subprocess.run([BIN, "replay", path, "--embedded", "--json"], check=True, capture_output=True, text=True)
    d = json.loads(out.stdout)
    return d["total_s"], d["chi2"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--files", nargs="*", default=["city10000.g2o", "manhattanolson3500.g2o"])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print("| file | Rust replay s | Python stream s | ratio | Rust χ² | Python χ² |")
    print("|---|---|---|---|---|---|")
    engines = []
    for name in args.files:
        path = os.path.join(DATA, name)
        graph = slamd.read(path)
        rust, py = [], []
        for _ in range(args.repeat):
            rust.append(rust_replay(path))
            py.append(python_stream(graph))
        r, p = min(rust), min(py, key=lambda t: t[0])
        print(f"| {name} | {r[0]:.2f} | {p[0]:.2f} | {p[0] / r[0]:.2f} | {r[1]:.4f} | {p[1]:.4f} |", flush=True)
        engines.append((name, graph.ids.tolist(), py[-1][2]))
    print()
    print("| file | newest keyframe ms | middle ms | first past the gauge ms |")
    print("|---|---|---|---|")
    for name, ids, engine in engines:
        cells = [marginal_ms(engine, k) for k in (ids[-1], ids[len(ids) // 2], ids[1])]
        print(f"| {name} | " + " | ".join(f"{c:.3f}" for c in cells) + " |", flush=True)


if __name__ == "__main__":
    main()
