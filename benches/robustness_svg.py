#!/usr/bin/env python3
"""The picture in docs/robustness.md: City10000 with 1000 random wrong loop
closures, without and with the filter, side by side.

    cargo build --release --bin slamd
    python3 benches/robustness_svg.py [--out docs/robustness-city10000.svg]

Left: `slamd solve --polish` (plain least squares, every edge trusted).
Right: `slamd replay --embedded` (online, the filter on by default). Each
panel draws the estimate (blue) over the ground truth (grey) rigidly aligned
onto it, with the ATE that alignment leaves.
"""
import argparse, json, math, os, subprocess, sys, tempfile
from common import BIN, DATA, HERE

CLEAN = os.path.join(DATA, "city10000.g2o")
GT = os.path.join(DATA, "groundtruth", "city10000_groundtruth_isam.txt")


def table(path):
    rows = {}
    for line in open(path):
        t = line.split()
        if len(t) == 4:
            rows[int(t[0])] = (float(t[1]), float(t[2]))
    return rows


def truth(binary, tmp):
    """Ground-truth positions by id, through slamd's own reader."""
    out = os.path.join(tmp, "truth.txt")
    subprocess.run([binary, "solve", GT, "--out", out], check=True, capture_output=True)
    return table(out)


def align(truth_xy, est_xy):
    """Rigidly aligns the truth onto the estimate; returns (aligned truth, rmse)."""
    n = len(est_xy)
    mt = [sum(p[i] for p in truth_xy) / n for i in (0, 1)]
    me = [sum(p[i] for p in est_xy) / n for i in (0, 1)]
    sxx = sum((t[0] - mt[0]) * (e[0] - me[0]) + (t[1] - mt[1]) * (e[1] - me[1]) for t, e in zip(truth_xy, est_xy))
    sxy = sum((t[0] - mt[0]) * (e[1] - me[1]) - (t[1] - mt[1]) * (e[0] - me[0]) for t, e in zip(truth_xy, est_xy))
    a = math.atan2(sxy, sxx)
    c, s = math.cos(a), math.sin(a)
    moved = [(c * (t[0] - mt[0]) - s * (t[1] - mt[1]) + me[0], s * (t[0] - mt[0]) + c * (t[1] - mt[1]) + me[1]) for t in truth_xy]
    rmse = math.sqrt(sum((m[0] - e[0]) ** 2 + (m[1] - e[1]) ** 2 for m, e in zip(moved, est_xy)) / n)
    return moved, rmse


def panel(x0, w, h, title, layers):
    pts = [p for _, xy in layers for p in xy]
    lo = [min(p[i] for p in pts) for i in (0, 1)]
    hi = [max(p[i] for p in pts) for i in (0, 1)]
    scale = min((w - 40) / (hi[0] - lo[0]), (h - 70) / (hi[1] - lo[1]))
    out = [f'<text x="{x0 + w / 2}" y="24" text-anchor="middle" font-size="16">{title}</text>']
    for color, xy in layers:
        d = " ".join(f"{x0 + 20 + (x - lo[0]) * scale:.1f},{h - 20 - (y - lo[1]) * scale:.1f}" for x, y in xy)
        out.append(f'<polyline points="{d}" fill="none" stroke="{color}" stroke-width="0.6"/>')
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--slamd", default=BIN)
    ap.add_argument("--out", default=os.path.join(HERE, "..", "docs", "robustness-city10000.svg"))
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="slamd-svg-")
    spoiled = os.path.join(tmp, "city-random-1000.g2o")
    subprocess.run([sys.executable, os.path.join(DATA, "..", "tools", "add_outliers.py"), "-i", CLEAN, "-o", spoiled,
                    "--kind", "random", "--count", "1000", "--seed", str(args.seed)], check=True, capture_output=True)
    plain, robust = os.path.join(tmp, "plain.txt"), os.path.join(tmp, "robust.txt")
    subprocess.run([args.slamd, "solve", spoiled, "--polish", "--out", plain], check=True, capture_output=True)
    subprocess.run([args.slamd, "replay", spoiled, "--embedded", "--out", robust], check=True, capture_output=True)
    gt = truth(args.slamd, tmp)
    w, h = 520, 560
    body = []
    for k, (label, path) in enumerate([("no filter (batch least squares)", plain), ("filter on (online replay)", robust)]):
        est = table(path)
        ids = sorted(set(est) & set(gt))
        exy = [est[i] for i in ids]
        txy, rmse = align([gt[i] for i in ids], exy)
        body += panel(k * w, w, h, f"{label}: ATE {rmse:.2f} m", [("#bbbbbb", txy), ("#1f5fbf", exy)])
    svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{2 * w}" height="{h}" viewBox="0 0 {2 * w} {h}" font-family="sans-serif">',
           f'<rect width="{2 * w}" height="{h}" fill="white"/>', *body,
           f'<text x="{w}" y="{h - 4}" text-anchor="middle" font-size="12" fill="#555">City10000 + 1000 random wrong loop closures (add_outliers.py seed {args.seed}); grey: ground truth aligned, blue: estimate</text>',
           "</svg>"]
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out, "w") as f:
        f.write("\n".join(svg) + "\n")
    print(args.out)


if __name__ == "__main__":
    sys.exit(main())
