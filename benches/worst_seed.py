#!/usr/bin/env python3
"""The Vertigo table over several seeds, worst seed shown.

    for s in 1 2 3 4 5; do python3 benches/outliers.py --seed $s > seed$s.md; done
    python3 benches/worst_seed.py seed*.md

Reads the tables `benches/outliers.py` printed, one per seed, and prints one
row per dataset and outlier set: how many seeds reach precision and recall
0.99 (grouped sets 0.98), then the figures of the worst seed (the least of
precision and recall, then the larger χ²), and the largest wait over every
seed.
"""
import argparse
import sys


def rows(path):
    """(dataset, outliers) -> the row's cells, from one seed's table."""
    out = {}
    header = None
    for line in open(path):
        if not line.startswith("| "):
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[0] == "dataset":
            header = cells
            continue
        if header is None or len(cells) < len(header):
            continue
        out[(cells[0], cells[1])] = dict(zip(header, cells))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("tables", nargs="+", help="one `benches/outliers.py` output per seed")
    args = ap.parse_args()
    seeds = [rows(t) for t in args.tables]
    keys = [k for k in seeds[0] if all(k in s for s in seeds)]
    if not keys:
        sys.exit("no row is in every table")
    print(f"{len(seeds)} seeds; worst seed's figures, largest wait over every seed")
    print("| dataset | outliers | seeds at the bar | precision | recall | ATE (m) | ATE clean (m) "
          "| χ² true / optimum | total / clean | p99 (ms) | max (ms) | decided after, median / largest (keyframes) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for key in keys:
        runs = [s[key] for s in seeds]
        bar = 0.98 if "grouped" in key[1] else 0.99
        pr = [(float(r["precision"]), float(r["recall"])) for r in runs]
        at_bar = sum(p >= bar and r >= bar for p, r in pr)
        worst = min(range(len(runs)), key=lambda i: (min(pr[i]), -float(runs[i]["χ² true / optimum"])))
        w = runs[worst]
        lag = w["decided after (keyframes)"].split(" / ")
        decided = f"{lag[0]} / {lag[-1]}" if len(lag) == 3 else w["decided after (keyframes)"]
        longest = max(float(r["max (ms)"]) for r in runs)
        print(f"| {key[0]} | {key[1]} | {at_bar} of {len(runs)} | {w['precision']} | {w['recall']} | "
              f"{w['ATE (m)']} | {w['ATE clean (m)']} | {w['χ² true / optimum']} | {w['total / clean']} | "
              f"{w['p99 (ms)']} | {longest:.0f} | {decided} |")


if __name__ == "__main__":
    main()
