"""Executes a notebook with nbclient (as CI does: scripts/test-python) and
fails on the first cell that raises.

    python examples/run_notebook.py examples/quickstart.ipynb [--cwd DIR] [--save OUT.ipynb]
"""

import argparse
import sys

import nbformat
from nbclient import NotebookClient


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("notebook")
    ap.add_argument("--cwd", default=".", help="the folder the notebook runs in (its outputs land there)")
    ap.add_argument("--save", help="write the executed notebook here")
    ap.add_argument("--timeout", type=int, default=1200, help="seconds per cell")
    a = ap.parse_args()
    nb = nbformat.read(a.notebook, as_version=4)
    NotebookClient(nb, timeout=a.timeout, kernel_name="python3", resources={"metadata": {"path": a.cwd}}).execute()
    if a.save:
        nbformat.write(nb, a.save)
    print("executed %s: %d cells" % (a.notebook, len(nb.cells)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
