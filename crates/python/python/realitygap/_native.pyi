"""Type stub of the extension module ``realitygap._native`` (PyO3, over
the library crates). The public API is in ``realitygap`` (``_api.py``):
these are its raw calls, returning plain values that it turns into pandas
and numpy objects. ``reporter``: an object with the methods of
``realitygap._progress.Reporter`` receiving a long call's progress."""

from typing import Any, Dict, List, Optional, Tuple

class RealityGapError(Exception):
    """An error of realitygap, with the message the command prints."""

def engines() -> List[Dict[str, Any]]: ...
def builtin_study() -> str: ...
def assets_dir() -> str: ...
def version() -> str: ...
def compare(
    study: str,
    *,
    data: str = "builtin",
    results: Optional[str] = None,
    mode: str = "default",
    alignment: Optional[str] = None,
    registration: Optional[str] = None,
    save_registration: Optional[str] = None,
    runs: Optional[str] = None,
    holdout: Optional[str] = None,
    bootstrap: Optional[int] = None,
    seed: int = 2019,
    link: Optional[str] = None,
    joint_space: bool = False,
    series: bool = False,
    physics_free: bool = True,
    physics_free_params: Optional[str] = None,
    reporter: Optional[Any] = None,
) -> Dict[str, str]: ...
def load_run(dir: str, run: Optional[str] = None) -> Dict[str, Any]:
    """``id``, ``columns`` (list of (name, little-endian f64 bytes)),
    ``entry`` and ``manifest`` (JSON text)."""
    ...
def run(
    scenes: List[str],
    *,
    out: str,
    engines: List[str] = ...,
    repeats: int = 1,
    robot: Optional[str] = None,
    packages: List[str] = ...,
    jobs: Optional[int] = None,
    seed: int = 0,
    perturb: List[str] = ...,
    set: List[str] = ...,
    timeout_s: Optional[float] = None,
    params: Optional[str] = None,
    stitch: Optional[str] = None,
    allow_unstable: bool = False,
    reporter: Optional[Any] = None,
) -> Dict[str, Any]: ...
def replay(
    real: str,
    *,
    out: str,
    robot: Optional[str] = None,
    packages: List[str] = ...,
    engines: List[str] = ...,
    params: Optional[str] = None,
    scene: Optional[str] = None,
    jobs: Optional[int] = None,
    reporter: Optional[Any] = None,
) -> Dict[str, str]: ...
def tune(
    *,
    engine: str,
    out: str,
    study: Optional[str] = None,
    recordings: Optional[str] = None,
    params: Optional[str] = None,
    scene: Optional[str] = None,
    efforts: bool = False,
    iterations: Optional[int] = None,
    data: str = "builtin",
    space: Optional[str] = None,
    runs: Optional[str] = None,
    holdout: Optional[str] = None,
    folds: Optional[int] = None,
    budget: Optional[int] = None,
    seed: int = 1,
    restarts: bool = False,
    jobs: Optional[int] = None,
    cube_weight: Optional[float] = None,
    keep_registration: bool = False,
    baseline: bool = True,
    start: str = "space",
    prior_weight: float = 0.0,
    settings: Optional[str] = None,
    set: List[str] = ...,
    robot: Optional[str] = None,
    packages: List[str] = ...,
    reporter: Optional[Any] = None,
) -> Dict[str, Any]: ...
def reproduce(
    *,
    out: str,
    data: str = "builtin",
    repeats: int = 20,
    engines: List[str] = ...,
    scenes: List[str] = ...,
    jobs: Optional[int] = None,
    mode: str = "default",
    timeout_s: Optional[float] = None,
    params: Optional[str] = None,
    tuned: List[str] = ...,
    crossval: List[str] = ...,
    joint_space: bool = False,
    runs: Optional[str] = None,
    holdout: Optional[str] = None,
    tosses: bool = True,
    reporter: Optional[Any] = None,
) -> Dict[str, Any]: ...
def params_toml(json: str) -> str: ...
def read_toml(path: str) -> str: ...
def run_one() -> int: ...
