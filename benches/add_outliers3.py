#!/usr/bin/env python3
"""Inject wrong loop closures into a 3-D g2o pose graph (EDGE_SE3:QUAT).

    python3 benches/add_outliers3.py -i sphere2500.g2o -o /tmp/s1000.g2o \\
        --kind random --count 1000 --seed 1

The semantics of Vertigo's generateDataset.py, as ../shared/tools/
add_outliers.py has them for 2-D, carried to SE(3):

  * pose count P (vertices in file order), group size g (1 for random and
    local, 10 by default for the grouped kinds);
  * v1 ~ U{0 .. P-1-g}; random kinds v2 ~ U{0 .. P-1-g}, local kinds
    v2 ~ U{v1 .. min(P-1-g, v1+W)} (W = 20); ordered v1 < v2, v2 = v1+2
    where it would be v1+1, both drawn again while equal;
  * one measurement per group: x, y, z ~ N(0, 0.3²) m, roll, pitch, yaw
    ~ N(0, (10°)²), R = Rz(yaw) Ry(pitch) Rx(roll); the group's edges are
    (v1+k, v2+k), k = 0..g-1, with the same measurement and information;
  * information: `auto` (the default) copies the first loop closure's 21
    entries, so an outlier is as confident as a true loop closure; or give
    one number for a diagonal, or 21 comma-separated entries.

--count counts injected edges (a multiple of g). The output is the input
verbatim plus the injected edges; the JSON side file (OUTPUT.outliers.json)
lists each by its 0-based index among the EDGE_SE3:QUAT lines, the index
`slamd solve --robust --json` reports in `rejected_edges`.
"""
import argparse, json, math, os, random, sys

KINDS = ("random", "local", "random-grouped", "local-grouped")


def quaternion_rpy(roll, pitch, yaw):
    """(qx, qy, qz, qw) of Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-i", "--input", required=True)
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--kind", choices=KINDS, required=True)
    p.add_argument("--count", type=int, required=True, help="injected edges")
    p.add_argument("--group-size", type=int, default=None)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--information", default="auto")
    p.add_argument("--local-window", type=int, default=20)
    p.add_argument("--sigma-xyz", type=float, default=0.3)
    p.add_argument("--sigma-angle-deg", type=float, default=10.0)
    p.add_argument("--side-file", default=None)
    a = p.parse_args(argv)
    grouped, local = a.kind.endswith("grouped"), a.kind.startswith("local")
    g = a.group_size or (10 if grouped else 1)
    if grouped != (g > 1):
        sys.exit(f"error: kind {a.kind} and group size {g} do not go together")
    if a.count < 0 or a.count % g:
        sys.exit(f"error: --count {a.count} must be a non-negative multiple of {g}")

    lines = open(a.input).read().splitlines()
    vids, n_edges, first_loop = [], 0, None
    for line in lines:
        t = line.split()
        if not t:
            continue
        if t[0] == "VERTEX_SE3:QUAT":
            vids.append(int(t[1]))
        elif t[0] == "EDGE_SE3:QUAT":
            n_edges += 1
            if first_loop is None and abs(int(t[1]) - int(t[2])) != 1:
                first_loop = t[10:31]
    if a.information == "auto":
        if first_loop is None:
            sys.exit("error: --information auto: the input has no loop closure")
        info = first_loop
    else:
        v = a.information.split(",")
        if len(v) == 1:
            info = [v[0] if c == r else "0" for r in range(6) for c in range(r, 6)]
        elif len(v) == 21:
            info = v
        else:
            sys.exit("error: --information needs auto, 1 or 21 values")
    hi = len(vids) - 1 - g
    if hi < 2:
        sys.exit("error: graph too small")
    rng = random.Random(a.seed)
    out, injected = list(lines), []
    for group in range(a.count // g):
        v1 = v2 = 0
        while v1 == v2:
            v1 = rng.randint(0, hi)
            v2 = rng.randint(v1, min(hi, v1 + a.local_window)) if local else rng.randint(0, hi)
            v1, v2 = min(v1, v2), max(v1, v2)
            if v2 == v1 + 1:
                v2 = v1 + 2
        xyz = [rng.gauss(0.0, a.sigma_xyz) for _ in range(3)]
        rpy = [rng.gauss(0.0, math.radians(a.sigma_angle_deg)) for _ in range(3)]
        q = quaternion_rpy(*rpy)
        for k in range(g):
            i, j = vids[v1 + k], vids[v2 + k]
            fields = [f"{x!r}" for x in xyz + list(q)]
            out.append(f"EDGE_SE3:QUAT {i} {j} " + " ".join(fields + list(info)))
            injected.append({"edge_index": n_edges + len(injected), "from": i, "to": j, "group": group})
    with open(a.output, "w") as f:
        f.write("\n".join(out) + "\n")
    side = {
        "generator": "benches/add_outliers3.py (Vertigo semantics, SE(3))",
        "input": os.path.abspath(a.input), "kind": a.kind, "group_size": g,
        "seed": a.seed, "n_injected_edges": len(injected), "n_original_edges": n_edges,
        "edge_index_convention": "0-based position among EDGE_SE3:QUAT lines of the output file",
        "outliers": injected,
    }
    side_path = a.side_file or a.output + ".outliers.json"
    with open(side_path, "w") as f:
        json.dump(side, f, indent=1)
    print(f"wrote {a.output} (+{len(injected)} outlier edges, seed {a.seed}) and {side_path}")


if __name__ == "__main__":
    main()
