#!/usr/bin/env python3
"""Bicocca with real bag-of-words loop closures, beside GTSAM's GNC.

    python3 benches/bicocca.py [--gnc-timeout 900] [--svg-dir docs]

For each of the three RRR files in SLAMD_DATASETS/rrr (loop-acceptance
thresholds 0.000, 0.500 and 1.000: 446, 122 and 23 loop closures, many of
them false), runs in one process run:

- `slamd solve FILE --polish --skip-invalid` (every edge trusted);
- `slamd replay FILE --embedded --skip-invalid` (the filter on, as
  shipped): how many loop closures it keeps;
- GTSAM's GncOptimizer (Levenberg-Marquardt inside, odometry known
  inliers, from the odometry guess), as `benches/outliers.py --peers` runs it.

Each map is scored against the GPS ground truth, interpolated at each
pose's time from the timestamps file (poses outside its span left out),
by `slamd eval` (ATE after the best rigid alignment). With --svg-dir,
writes bicocca-THRESHOLD.svg there: the three maps over the aligned
ground truth. The binary is target/release/slamd or $SLAMD_BIN.
"""
import argparse, bisect, math, os, sys, tempfile

from outliers import gnc  # noqa: E402
from robustness_svg import align, panel, table  # noqa: E402
from common import DATA, slamd

RRR = os.path.join(DATA, "rrr")
THRESHOLDS = ["0.000", "0.500", "1.000"]


def ground_truth(path):
    """`id x y theta` rows for the poses within the ground truth's time
    span, interpolated linearly between the two ground-truth rows around
    each pose's timestamp (at most 1 s apart)."""
    stamps = [float(line) for line in open(os.path.join(RRR, "bicocca_b25b_timestamps.txt")) if line.strip()]
    rows = [tuple(float(v) for v in line.split(",")) for line in open(
        os.path.join(RRR, "bicocca_2009-02-25b-gt-extended.csv")) if line.strip()]
    times = [r[0] for r in rows]
    matched = 0
    with open(path, "w") as f:
        for k, t in enumerate(stamps):
            i = bisect.bisect_right(times, t)
            if i == 0 or i == len(rows) or times[i] - times[i - 1] > 1.0:
                continue
            (t0, x0, y0, a0), (t1, x1, y1, a1) = rows[i - 1], rows[i]
            u = (t - t0) / (t1 - t0)
            da = math.atan2(math.sin(a1 - a0), math.cos(a1 - a0))
            f.write(f"{k} {x0 + u * (x1 - x0)} {y0 + u * (y1 - y0)} {a0 + u * da}\n")
            matched += 1
    return matched, len(stamps)


def svg(path, title, gt, maps):
    w, h = 420, 460
    body = []
    for k, (label, est) in enumerate(maps):
        ids = sorted(set(est) & set(gt))[::8]
        exy = [est[i] for i in ids]
        txy, rmse = align([gt[i] for i in ids], exy)
        body += panel(k * w, w, h, f"{label}: ATE {rmse:.2f} m", [("#bbbbbb", txy), ("#1f5fbf", exy)])
    width = w * len(maps)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{h}" viewBox="0 0 {width} {h}" '
           'font-family="sans-serif">', f'<rect width="{width}" height="{h}" fill="white"/>', *body,
           f'<text x="{width / 2}" y="{h - 4}" text-anchor="middle" font-size="12" fill="#555">{title}; '
           'grey: GPS ground truth aligned, blue: estimate (every 8th pose)</text>', "</svg>"]
    with open(path, "w") as f:
        f.write("\n".join(out) + "\n")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--gnc-timeout", type=float, default=900)
    ap.add_argument("--svg-dir")
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="slamd-bicocca-")
    gt_path = os.path.join(tmp, "gt.txt")
    matched, total = ground_truth(gt_path)
    gt = table(gt_path)
    print(f"`python3 benches/bicocca.py` ({matched} of {total} poses matched to the ground truth)")
    print()
    print("| threshold | loop closures | skipped lines | plain ATE (m) | slamd kept | slamd ATE (m) | slamd (s) "
          "| GNC ATE (m) | GNC (s) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for th in THRESHOLDS:
        path = os.path.join(RRR, f"bicocca_b25b_{th}.g2o")
        plain, online = os.path.join(tmp, f"plain-{th}.txt"), os.path.join(tmp, f"online-{th}.txt")
        slamd("solve", path, "--polish", "--skip-invalid", "--out", plain, "--json")
        r = slamd("replay", path, "--embedded", "--skip-invalid", "--out", online, "--json")
        # `slamd eval` reads the graph whole: without what --skip-invalid skips
        scored = os.path.join(tmp, f"valid-{th}.g2o")
        with open(scored, "w") as f:
            for line in open(path):
                t = line.split()
                if not (t and t[0].startswith("EDGE") and t[1] == t[2]):
                    f.write(line)
        ate = {name: slamd("eval", scored, p, "--ground-truth", gt_path, "--json")["ate"]
               for name, p in (("plain", plain), ("online", online))}
        g = gnc(scored, a.gnc_timeout)
        if g is None:
            gnc_cells, gnc_map = "failed or timed out | –", None
        else:
            seconds, poses = g
            gnc_ate = slamd("eval", scored, poses, "--ground-truth", gt_path, "--json")["ate"]
            gnc_cells, gnc_map = f"{gnc_ate:.2f} | {seconds:.1f}", table(poses)
        kept = r["loop_closures"] - r["switched_off"]
        print(f"| {th} | {r['loop_closures']} | {r['skipped_lines']['count']} | {ate['plain']:.2f} "
              f"| {kept} | {ate['online']:.2f} | {r['total_s']:.2f} | {gnc_cells} |")
        if a.svg_dir:
            maps = [("plain", table(plain)), ("slamd, filter on", table(online))]
            maps += [("GTSAM GNC", gnc_map)] if gnc_map else []
            svg(os.path.join(a.svg_dir, f"bicocca-{th}.svg"), f"Bicocca 25b, bag-of-words threshold {th}", gt, maps)
    return 0


if __name__ == "__main__":
    sys.exit(main())
