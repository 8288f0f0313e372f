#!/usr/bin/env python3
"""The known-truth table of tools/known-truth/run.sh: per engine and
parameter, the truth, the fitted value, its 95 % interval, whether the
interval covers the truth, the evaluations and the wall time.

Usage: table.py OUT ENGINE [ENGINE ...]. Standard library only.
"""
import json
import sys
import tomllib
from pathlib import Path


def known(path):
    with open(path, "rb") as f:
        doc = tomllib.load(f)
    flat = {}

    def walk(prefix, value):
        if isinstance(value, dict):
            for key, inner in value.items():
                walk(f"{prefix}.{key}" if prefix else key, inner)
        else:
            flat[prefix] = value

    walk("", doc)
    return flat


def main(argv):
    if len(argv) < 3:
        print(__doc__)
        return 2
    out = Path(argv[1])
    print("| engine | parameter | truth | fitted | 95 % interval | covers | evaluations | wall (s) |")
    print("|---|---|---:|---:|---|---|---:|---:|")
    for engine in argv[2:]:
        d = out / engine
        summary = d / "tuned" / "summary.json"
        if not summary.is_file():
            print(f"| {engine} | (no result: see {d}/tune.log) | | | | | | |")
            continue
        truth = known(d / "known.toml")
        s = json.loads(summary.read_text())
        wall = (d / "wall_s").read_text().strip() if (d / "wall_s").is_file() else ""
        evals = s.get("evaluations", "")
        polish = s.get("polish") or {}
        if isinstance(polish, dict) and polish.get("evaluations"):
            evals = f"{evals} + {polish['evaluations']}"
        for iv in polish.get("intervals", []):
            key = iv["key"]
            t = truth.get(key)
            if t is None:
                continue
            lo_hi = iv.get("interval")
            if lo_hi:
                lo, hi = lo_hi
                interval = f"[{lo:.4g}, {hi:.4g}]"
                covers = "yes" if lo <= t <= hi else "**no**"
            else:
                interval, covers = "none (not identifiable)", "-"
            print(f"| {engine} | `{key}` | {t:g} | {iv['value']:.4g} | {interval} | {covers} "
                  f"| {evals} | {float(wall):.0f} |" if wall else
                  f"| {engine} | `{key}` | {t:g} | {iv['value']:.4g} | {interval} | {covers} | {evals} | |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
