"""realitygap: how far does each physics engine stray from the real robot?

The Python face of the ``realitygap`` command: the same simulations,
comparisons and calibrations, with results as pandas DataFrames and numpy
arrays::

    import realitygap as rg
    rg.engines()                                  # the engines compiled in
    cmp = rg.compare(rg.builtin_study())          # the study's table
    cmp.table                                     # = the command's table.csv
    rg.run("scene1_single_joint", engine="mujoco", out="results/runs")
    tuned = rg.tune("mujoco", out="results/tune", budget=24)

Long calls release the GIL, show a progress bar and stop cleanly on Ctrl-C
(KeyboardInterrupt), keeping the runs that finished. Errors raise
:class:`RealityGapError` with the command's message.

MuJoCo's shared library comes from the ``mujoco`` wheel this package
depends on (loaded here, before the extension); Bullet, PhysX, Rapier and
the physics-free model are inside the extension; ODE and DART are Debian's
system libraries (``libode8``, ``libdart6.12``).
"""

import ctypes as _ctypes
import importlib.util as _importlib_util
import os as _os

_MUJOCO_VERSION = "3.17.0"


def _mujoco_library() -> str:
    """The path of ``libmujoco.so.<version>`` inside the installed
    ``mujoco`` package (found without importing it)."""
    spec = _importlib_util.find_spec("mujoco")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError(
            "realitygap needs the mujoco package (pip install mujoco==%s)" % _MUJOCO_VERSION
        )
    for folder in spec.submodule_search_locations:
        path = _os.path.join(folder, "libmujoco.so." + _MUJOCO_VERSION)
        if _os.path.isfile(path):
            return path
    raise ImportError(
        "realitygap needs MuJoCo %s: no libmujoco.so.%s in the installed mujoco package (%s); "
        "pip install mujoco==%s"
        % (_MUJOCO_VERSION, _MUJOCO_VERSION, ", ".join(spec.submodule_search_locations), _MUJOCO_VERSION)
    )


# Load the mujoco wheel's library first: the extension's dependency on
# libmujoco.so.3.17.0 (its soname) is then satisfied by this copy.
MUJOCO_LIBRARY = _mujoco_library()
_ctypes.CDLL(MUJOCO_LIBRARY, mode=_ctypes.RTLD_GLOBAL)

# The scenes, studies, tuning spaces and the study's recordings ship inside
# the package; child processes inherit the variable.
_ASSETS = _os.path.join(_os.path.dirname(__file__), "assets")
if "REALITYGAP_ASSETS" not in _os.environ and _os.path.isdir(_ASSETS):
    _os.environ["REALITYGAP_ASSETS"] = _ASSETS

from realitygap import _native  # noqa: E402
from realitygap._native import RealityGapError  # noqa: E402
from realitygap._api import (  # noqa: E402
    Comparison,
    Engine,
    Replay,
    Reproduction,
    Run,
    RunBatch,
    TuneResult,
    CrossValidated,
    builtin_study,
    compare,
    engines,
    load_run,
    replay,
    reproduce,
    run,
    scene_file,
    tune,
)

__version__ = _native.version()

__all__ = [
    "Comparison",
    "Engine",
    "RealityGapError",
    "Replay",
    "Reproduction",
    "Run",
    "RunBatch",
    "TuneResult",
    "CrossValidated",
    "builtin_study",
    "compare",
    "engines",
    "load_run",
    "replay",
    "reproduce",
    "run",
    "scene_file",
    "tune",
    "MUJOCO_LIBRARY",
]
