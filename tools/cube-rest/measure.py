#!/usr/bin/env python3
"""Scene 3's resting phase, measured in `realitygap run` results.

From 8 to 14 s of scene 3 the command takes joint 3 from 120 to 65 degrees
while the hand comes down on the cube. On the real arm (METHOD.md, inverse
kinematics of runs 1-20) joint 3 stays 9.7 degrees short of 65: the cube
holds the hand up. This prints, for every source of a results folder:

- the shortfall: the mean of q3 - 65 degrees over 12-14 s (the command has
  long reached 65 by then; positive: held short of the target);
- the cube's final displacement (m) and rotation (degrees) over the run.

Usage: measure.py RUNS_DIR [RUNS_DIR ...]  (folders `run` wrote; the scene
folder scene3_cube_push is looked for in each). Standard library only.
"""

import csv
import math
import sys
from pathlib import Path

SCENE = "scene3_cube_push"
TARGET_DEG = 65.0
WINDOW_S = (12.0, 14.0)
REAL_SHORTFALL_DEG = 9.7


def quat_angle_deg(a, b):
    dot = abs(sum(x * y for x, y in zip(a, b)))
    return math.degrees(2.0 * math.acos(min(1.0, dot)))


def measure(csv_path):
    with open(csv_path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise SystemExit(f"{csv_path}: no samples")
    for col in ("t_s", "q3_rad", "cube_x_m", "cube_qw"):
        if col not in rows[0]:
            raise SystemExit(f"{csv_path}: no column {col}")
    q3 = [math.degrees(float(r["q3_rad"])) for r in rows
          if WINDOW_S[0] <= float(r["t_s"]) <= WINDOW_S[1]]
    if not q3:
        raise SystemExit(f"{csv_path}: no samples between {WINDOW_S[0]} and {WINDOW_S[1]} s")
    shortfall = sum(q3) / len(q3) - TARGET_DEG
    pos = lambda r: [float(r[f"cube_{a}_m"]) for a in "xyz"]
    quat = lambda r: [float(r[f"cube_q{a}"]) for a in "wxyz"]
    d = math.dist(pos(rows[0]), pos(rows[-1]))
    rot = quat_angle_deg(quat(rows[0]), quat(rows[-1]))
    return shortfall, d, rot


def main(argv):
    if len(argv) < 2:
        print(__doc__)
        return 2
    print(f"| results | source | joint-3 shortfall 12-14 s (deg; real {REAL_SHORTFALL_DEG}) "
          "| cube push (m) | cube rotation (deg) |")
    print("|---|---|---:|---:|---:|")
    for folder in argv[1:]:
        scene = Path(folder) / SCENE
        if not scene.is_dir():
            raise SystemExit(f"{folder}: no {SCENE} folder")
        for source in sorted(p for p in scene.iterdir() if p.is_dir()):
            runs = sorted((source / "runs").glob("run*.csv"))
            if not runs:
                continue
            s, d, r = measure(runs[0])
            print(f"| {folder} | {source.name} | {s:.1f} | {d:.3f} | {r:.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
