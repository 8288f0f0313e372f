"""The Python package's overhead against the command (docs/python.md).

Run with the test environment's interpreter (scripts/test-python makes
it), from outside the source tree:

    REALITYGAP_CLI=$CARGO_TARGET_DIR/release/realitygap \\
        ~/.cache/realitygap/py-test-venv/bin/python python/bench_overhead.py [--n 5]

Per case, N rounds alternating the two sides, the median wall time:
- compare: ``realitygap compare <built-in study> --format csv`` against
  ``python -c "import realitygap as rg; rg.compare(rg.builtin_study()).table"``
  (both as whole processes), and the call alone inside a warm interpreter;
- run: ``realitygap run scene1 --engine mujoco`` (one run, a fresh output
  folder each time) against ``rg.run("scene1", "mujoco", ...)`` in a
  whole process, and the call alone.
"""

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import realitygap as rg


def wall(argv):
    t = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=5)
    a = ap.parse_args()
    cli = os.environ["REALITYGAP_CLI"]
    py = sys.executable
    study = rg.builtin_study()
    scene = rg.scene_file("scene1")
    tmp = tempfile.mkdtemp()
    rows = {k: [] for k in ["compare cli", "compare py process", "compare py call",
                            "run cli", "run py process", "run py call"]}
    try:
        # Warm the caches (the study's recordings unpacked, files read).
        wall([cli, "compare", study, "--format", "csv"])
        rg.compare(study, progress=False).table
        for i in range(a.n):
            rows["compare cli"].append(wall([cli, "compare", study, "--format", "csv"]))
            rows["compare py process"].append(wall([py, "-c",
                "import realitygap as rg; rg.compare(rg.builtin_study(), progress=False).table"]))
            t = time.perf_counter()
            rg.compare(study, progress=False).table
            rows["compare py call"].append(time.perf_counter() - t)
            out = os.path.join(tmp, "r%d" % i)
            rows["run cli"].append(wall([cli, "run", scene, "--engine", "mujoco", "--out", out + "c"]))
            rows["run py process"].append(wall([py, "-c",
                "import sys, realitygap as rg; rg.run('scene1', 'mujoco', out=sys.argv[1], progress=False)",
                out + "p"]))
            t = time.perf_counter()
            rg.run("scene1", "mujoco", out=out + "q", progress=False)
            rows["run py call"].append(time.perf_counter() - t)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    med = {k: statistics.median(v) for k, v in rows.items()}
    print("| case | median wall (s) | ratio to the command | rounds |")
    print("|---|---:|---:|---:|")
    for k, v in med.items():
        base = med["compare cli"] if k.startswith("compare") else med["run cli"]
        print("| %s | %.3f | %.2f | %d |" % (k, v, v / base, len(rows[k])))
    return 0


if __name__ == "__main__":
    sys.exit(main())
