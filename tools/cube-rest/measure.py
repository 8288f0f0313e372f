#!/usr/bin/env python3
"""Scene 3's resting phase, measured in `realitygap run` results.

From 8 to 14 s of scene 3 the command takes joint 2 from 30 to -60 degrees
and joint 3 from 120 to 65 degrees; the hand comes down beside and over the
cube. METHOD.md reads the real arm's joint 3, about 10 degrees short of 65
there, as the cube holding the hand up. This prints, per source:

- the shortfall: the mean of q3 - 65 degrees over 12-14 s (the command has
  long reached 65 by then; positive: short of the target);
- where joint 3 stops: when its descent from 120 degrees first slows below
  2 degrees/s, measured from the descent's onset (where it started moving), with q3 and q2 there, the
  wrist's height above the cube's top face and how far the cube has moved
  by then (the event, not the clock, so real runs need no alignment);
- when the cube first moves (5 mm across the table from its rest), from the same onset;
- the cube's final displacement (m) and rotation (degrees) over the run.

Real runs imported with joint angles (`realitygap import qualisys --ik`)
measure like simulated ones. With several runs per source the median is
printed, with the range over runs for the stop.

Usage: measure.py DIR [DIR ...]. A DIR is a folder `run` wrote (its
scene3_cube_push folder is read, every source in it) or one source's folder
(holding runs/ with run CSVs). Standard library only; a missing folder,
column or phase is an error naming the file.
"""

import csv
import math
import statistics
import sys
from pathlib import Path

SCENE = "scene3_cube_push"
TARGET_DEG = 65.0
WINDOW_S = (12.0, 14.0)
CUBE_HALF_EDGE_M = 0.0375
REAL_SHORTFALL_DEG = 9.7
STOP_DEG_S = 2.0
DESCENT_DEG = 10.0
CUBE_MOVED_M = 0.005


def quat_angle_deg(a, b):
    dot = abs(sum(x * y for x, y in zip(a, b)))
    return math.degrees(2.0 * math.acos(min(1.0, dot)))


def column(rows, name, path):
    try:
        return [float(r[name]) for r in rows]
    except KeyError:
        raise SystemExit(f"{path}: no column {name}")
    except (TypeError, ValueError) as e:
        raise SystemExit(f"{path}: column {name}: {e}")


def measure(csv_path):
    with open(csv_path, newline="") as f:
        rows = list(csv.DictReader(f))
    if len(rows) < 10:
        raise SystemExit(f"{csv_path}: too few samples ({len(rows)})")
    t = column(rows, "t_s", csv_path)
    q2 = [math.degrees(v) for v in column(rows, "q2_rad", csv_path)]
    q3 = [math.degrees(v) for v in column(rows, "q3_rad", csv_path)]
    wz = column(rows, "wrist_z_m", csv_path)
    cube = list(zip(*(column(rows, f"cube_{a}_m", csv_path) for a in "xyz")))
    cq = list(zip(*(column(rows, f"cube_q{a}", csv_path) for a in "wxyz")))

    window = [q for ti, q in zip(t, q3) if WINDOW_S[0] <= ti <= WINDOW_S[1]]
    if not window:
        raise SystemExit(f"{csv_path}: no samples between {WINDOW_S[0]} and {WINDOW_S[1]} s")
    shortfall = sum(window) / len(window) - TARGET_DEG

    # The descent from the phase-1 rest (joint 3's highest point): found
    # 10 degrees below that point, its onset where it started moving
    # (faster than 2 degrees/s), its stop where it slows below that again.
    dt = (t[-1] - t[0]) / (len(t) - 1)
    k = max(1, round(0.05 / dt))  # the rate over about 50 ms either side
    rate = lambda i: (q3[min(i + k, len(q3) - 1)] - q3[max(i - k, 0)]) / (
        t[min(i + k, len(q3) - 1)] - t[max(i - k, 0)])
    top = max(range(len(q3)), key=lambda i: q3[i])
    descending = next((i for i in range(top, len(q3)) if q3[i] < q3[top] - DESCENT_DEG), None)
    if descending is None:
        raise SystemExit(f"{csv_path}: joint 3 never descends {DESCENT_DEG} degrees from its phase-1 rest")
    onset = descending
    while onset > top and rate(onset - 1) < -STOP_DEG_S:
        onset -= 1
    stop = next((i for i in range(descending, len(q3)) if rate(i) > -STOP_DEG_S), None)
    if stop is None:
        raise SystemExit(f"{csv_path}: joint 3 never stops after its descent")
    # The cube's rest: its median position before the descent (a capture
    # jitters by a millimetre or two); moved: 5 mm across the table from it.
    rest = [statistics.median(c[a] for c in cube[:onset + 1]) for a in range(3)]
    across = lambda i: math.dist(cube[i][:2], rest[:2])
    moved = next((i for i in range(onset, len(cube)) if across(i) > CUBE_MOVED_M), None)
    return {
        "shortfall": shortfall,
        "stop_s": t[stop] - t[onset],
        "stop_q3": q3[stop],
        "stop_q2": q2[stop],
        "stop_height": wz[stop] - (cube[stop][2] + CUBE_HALF_EDGE_M),
        "stop_cube": across(stop),
        "cube_moves_s": None if moved is None else t[moved] - t[onset],
        "push": math.dist(cube[-1], rest),
        "rotation": quat_angle_deg(cq[0], cq[-1]),
    }


def sources(folder):
    folder = Path(folder)
    if (folder / "runs").is_dir():
        return [folder]
    scene = folder / SCENE
    if not scene.is_dir():
        raise SystemExit(f"{folder}: neither a source folder (runs/) nor a results folder with {SCENE}/")
    return sorted(p for p in scene.iterdir() if (p / "runs").is_dir())


def main(argv):
    if len(argv) < 2:
        print(__doc__)
        return 2
    print(f"| results | source | runs | joint-3 shortfall 12-14 s (deg; real {REAL_SHORTFALL_DEG}) "
          "| joint 3 stops, after the descent's onset (s) | q3 there (deg) | q2 there (deg) "
          "| wrist above the cube's top there (m) | cube moved by then (m) "
          "| cube first moves, after the onset (s) | cube push (m) | cube rotation (deg) |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for folder in argv[1:]:
        for source in sources(folder):
            runs = sorted((source / "runs").glob("*.csv"))
            if not runs:
                raise SystemExit(f"{source}: no run CSVs in runs/")
            m = [measure(r) for r in runs]
            med = lambda key: statistics.median(x[key] for x in m)
            rng = lambda key, fmt: (fmt.format(med(key)) if len(m) == 1 else
                                    f"{fmt.format(med(key))} [{fmt.format(min(x[key] for x in m))}, "
                                    f"{fmt.format(max(x[key] for x in m))}]")
            moves = [x["cube_moves_s"] for x in m if x["cube_moves_s"] is not None]
            moves_s = f"{statistics.median(moves):.2f}" if moves else "never"
            print(f"| {folder} | {source.name} | {len(m)} | {med('shortfall'):.1f} | "
                  f"{rng('stop_s', '{:.2f}')} | {rng('stop_q3', '{:.1f}')} | {med('stop_q2'):.1f} | "
                  f"{rng('stop_height', '{:.3f}')} | {med('stop_cube'):.3f} | {moves_s} | "
                  f"{med('push'):.3f} | {med('rotation'):.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
