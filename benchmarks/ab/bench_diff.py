"""Compare two `aoc bench` results.csv files row by row (the same experiment on two trees).

Rows are matched by (experiment, task, method, setting, seed). Every column but the timing
(`seconds_per_step`) and the free-text `note` must agree: text exactly, numbers to a relative
4e-15 (a few units in the last place: the same decisions give the same returns up to the
summation's rounding). Prints one line per differing row, the largest relative difference,
and the median new/old ratio of `seconds_per_step` over the methods that have one.

Usage: .venv/bin/python benchmarks/ab/bench_diff.py OLD/results.csv NEW/results.csv
"""

from __future__ import annotations

import argparse
import csv
import math
import statistics
import sys

KEY = ("experiment", "task", "method", "setting", "seed")
TIMING = ("seconds_per_step", "note")


def rows(path: str) -> dict:
    with open(path, newline="") as f:
        return {tuple(r[k] for k in KEY): r for r in csv.DictReader(f)}


def number(text: str):
    try:
        return float(text)
    except ValueError:
        return None


def main(old_path: str, new_path: str) -> int:
    old, new = rows(old_path), rows(new_path)
    differ, worst, ratios = 0, 0.0, []
    for key in sorted(set(old) | set(new)):
        if key not in old or key not in new:
            print(f"only in {'new' if key in new else 'old'}: {key}")
            differ += 1
            continue
        a, b = old[key], new[key]
        bad = []
        for col in a:
            if col in TIMING:
                continue
            x, y = number(a[col]), number(b[col])
            if x is not None and y is not None:
                rel = 0.0 if x == y else abs(x - y) / max(abs(x), abs(y))
                worst = max(worst, rel)
                if rel > 4e-15 and not (math.isnan(x) and math.isnan(y)):
                    bad.append(f"{col} {a[col]} -> {b[col]}")
            elif a[col] != b[col]:
                bad.append(f"{col} {a[col]!r} -> {b[col]!r}")
        if bad:
            differ += 1
            print(f"{' '.join(key)}: " + "; ".join(bad))
        x, y = number(a.get("seconds_per_step", "")), number(b.get("seconds_per_step", ""))
        if x and y:
            ratios.append(y / x)
    print(f"rows {len(old)} old, {len(new)} new; differing {differ}; largest relative "
          f"difference {worst:.3g}; seconds_per_step new/old median "
          f"{statistics.median(ratios):.3f} over {len(ratios)} method rows" if ratios else "")
    return 1 if differ else 0


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old", help="the older tree's results.csv")
    ap.add_argument("new", help="the newer tree's results.csv")
    args = ap.parse_args()
    sys.exit(main(args.old, args.new))
