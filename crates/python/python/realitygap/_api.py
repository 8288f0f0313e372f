"""The API: thin wrappers over the extension (``realitygap._native``) that
turn its results into pandas DataFrames and numpy arrays.

pandas and numpy are imported when a result is built, not at import time:
the simulations' child processes (``python -m realitygap._child``) import
this package and should start fast.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Dict, Iterable, List, Optional, Sequence, Tuple, Union

from realitygap import _native
from realitygap._progress import reporter as _reporter

if TYPE_CHECKING:  # pragma: no cover
    import numpy as np
    import pandas as pd

PathLike = Union[str, "os.PathLike[str]"]
Params = Union[PathLike, Dict[str, Any]]


def _path(p: Optional[PathLike]) -> Optional[str]:
    return None if p is None else os.fspath(p)


def _paths(ps: Union[None, PathLike, Iterable[PathLike]]) -> List[str]:
    if ps is None:
        return []
    if isinstance(ps, (str, os.PathLike)):
        return [os.fspath(ps)]
    return [os.fspath(p) for p in ps]


def _names(v: Union[None, str, Iterable[str]]) -> List[str]:
    if v is None:
        return []
    if isinstance(v, str):
        return [v]
    return list(v)


def _key_values(v: Union[None, str, Dict[str, Any], Iterable[str]]) -> List[str]:
    """``{"mujoco.timestep_s": 0.0005}`` or ``["key=value", ...]`` as the
    command's ``KEY=VALUE`` arguments."""
    if v is None:
        return []
    if isinstance(v, str):
        return [v]
    if isinstance(v, dict):
        out = []
        for k, x in v.items():
            if isinstance(x, bool):
                x = "true" if x else "false"
            out.append("%s=%s" % (k, x))
        return out
    return list(v)


def _perturb(v: Union[None, str, Dict[str, float], Iterable[str]]) -> List[str]:
    if isinstance(v, dict):
        return [",".join("%s=%s" % (k, x) for k, x in v.items())]
    return _key_values(v)


def _params_file(params: Optional[Params], out: PathLike) -> Optional[str]:
    """A parameters file: the path given, or a dict written as TOML into
    ``out`` (``params-<hash>.toml``; checked first)."""
    if params is None:
        return None
    if isinstance(params, dict):
        text = _native.params_toml(json.dumps(params))
        digest = hashlib.sha256(text.encode()).hexdigest()[:12]
        os.makedirs(out, exist_ok=True)
        path = os.path.join(os.fspath(out), "params-%s.toml" % digest)
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
        return path
    return os.fspath(params)


def _csv_frame(text: str) -> "pd.DataFrame":
    import pandas as pd

    return pd.read_csv(io.StringIO(text))


# --------------------------------------------------------------- engines


@dataclass(frozen=True)
class Engine:
    """A physics engine compiled in (``realitygap engines``)."""

    name: str
    version: str
    default_timestep_s: float
    settings: Dict[str, str] = field(default_factory=dict)
    """Settings it accepts (``[engine.NAME]`` in a scene, ``set=``), with help."""
    params: Dict[str, str] = field(default_factory=dict)
    """Per physical parameter key, what it becomes in the engine."""
    commands: List[Tuple[str, str, str]] = field(default_factory=list)
    """How its servos take each kind of joint command: (kind, unit, mechanism)."""


def engines() -> List[Engine]:
    """The physics engines compiled in, in ``realitygap engines`` order
    (MuJoCo, ODE, Rapier, Bullet, PhysX, DART, and ``ideal``, the
    physics-free model)."""
    return [
        Engine(
            name=e["name"],
            version=e["version"],
            default_timestep_s=e["default_timestep_s"],
            settings=dict(e["settings"]),
            params=dict(e["params"]),
            commands=[tuple(c) for c in e["commands"]],
        )
        for e in _native.engines()
    ]


def builtin_study() -> str:
    """The study file of the reproduced study (Collins et al., ICRA 2019),
    shipped with the package: ``compare(builtin_study())`` gives its table
    against the recordings built in."""
    return _native.builtin_study()


def scene_file(scene: PathLike) -> str:
    """A scene file: a path as it is, or the name of a scene shipped with
    the package (``"scene1_single_joint"``, ``"scene2_two_joints"``,
    ``"scene3_cube_push"``, ``"iiwa_reach"``, ``"iiwa_push"``; ``"scene1"``
    for short)."""
    p = os.fspath(scene)
    if os.path.exists(p) or os.sep in p or p.endswith(".toml"):
        return p
    folder = os.path.join(_native.assets_dir(), "scenes")
    exact = os.path.join(folder, p + ".toml")
    if os.path.isfile(exact):
        return exact
    matches = sorted(f for f in os.listdir(folder) if f.startswith(p + "_") and f.endswith(".toml"))
    if len(matches) == 1:
        return os.path.join(folder, matches[0])
    names = sorted(f[: -len(".toml")] for f in os.listdir(folder) if f.endswith(".toml"))
    raise _native.RealityGapError(
        "scene %r: no such file, and no shipped scene of that name (shipped: %s)" % (p, ", ".join(names))
    )


# --------------------------------------------------------------- compare


class Comparison:
    """A comparison (``realitygap compare``).

    ``table``: the accumulated-error table as a DataFrame, equal to the
    command's ``--format csv`` (``table.csv``), interval columns included;
    ``measures``: one row per scene and source with every measure
    (accumulated, mean, largest and final error, lag, runs used, ...);
    ``json``: the command's ``--format json``; ``markdown``: its table.
    For a replay's folder, ``table`` is the joint-space table.
    """

    def __init__(self, kind: str, csv: str, markdown: str, json_text: str) -> None:
        self.kind = kind
        self.csv = csv
        self.markdown = markdown
        self._json_text = json_text
        self._json: Optional[Any] = None
        self._table: Optional["pd.DataFrame"] = None
        self._measures: Optional["pd.DataFrame"] = None

    @property
    def json(self) -> Any:
        """The command's ``--format json``, parsed."""
        if self._json is None:
            self._json = json.loads(self._json_text)
        return self._json

    @property
    def table(self) -> "pd.DataFrame":
        """The table, as the command's ``--format csv`` writes it."""
        if self._table is None:
            self._table = _csv_frame(self.csv)
        return self._table.copy()

    @property
    def measures(self) -> "pd.DataFrame":
        """Per scene and source (the reference, ``real``, first in each
        scene): every measure of the JSON output, nested ones flattened
        (``accumulated_error_interval_m.low_m``, ``goal.final_distance_m``,
        ...); per-step series left out (see :meth:`series`)."""
        import pandas as pd

        if self._measures is None:
            rows = []
            if self.kind == "study":
                for scene, s in self.json["scenes"].items():
                    for role, src in [("reference", s["reference"])] + [("source", x) for x in s["sources"]]:
                        row = {k: v for k, v in src.items() if k != "series"}
                        row["scene"] = scene
                        row["role"] = role
                        rows.append(row)
                frame = pd.json_normalize(rows)
                # A nested measure absent from some rows (the reference has
                # no interval) leaves an empty column beside its parts.
                frame = frame.drop(columns=[
                    c for c in frame.columns
                    if frame[c].isna().all() and any(o.startswith(c + ".") for o in frame.columns)
                ])
                first = ["scene", "source", "role"]
                frame = frame[first + [c for c in frame.columns if c not in first]]
            else:
                frame = pd.json_normalize(self.json["rows"] if isinstance(self.json, dict) else self.json)
            self._measures = frame
        return self._measures.copy()

    def series(self, scene: str, quantity: str = "wrist_distance_to_reference_m") -> "pd.DataFrame":
        """A per-step series of every source of ``scene`` (one column per
        source, the reference too when it has the quantity), indexed by
        time (``t_s``). Needs ``compare(..., series=True)``. Quantities:
        ``wrist_distance_to_reference_m`` (the figure of the README),
        ``wrist_distance_to_goal_m``, ``wrist_spread_m``,
        ``cube_displacement_m``, ``cube_pitch_change_deg``, ``runs``."""
        import pandas as pd

        scenes = self.json.get("scenes", {}) if isinstance(self.json, dict) else {}
        if scene not in scenes:
            raise KeyError("no scene %r (scenes: %s)" % (scene, ", ".join(scenes)))
        s = scenes[scene]
        columns: Dict[str, Any] = {}
        index = None
        for src in [s["reference"]] + s["sources"]:
            series = src.get("series")
            if not series:
                raise ValueError("no per-step series: call compare(..., series=True)")
            values = series.get(quantity)
            if values:
                columns[src["source"]] = values
                index = series["t_s"]
        frame = pd.DataFrame(columns, index=pd.Index(index, name="t_s"))
        return frame

    def _repr_markdown_(self) -> str:
        return self.markdown

    def __repr__(self) -> str:
        return self.markdown


def compare(
    study: Optional[PathLike] = None,
    *,
    data: Union[str, PathLike] = "builtin",
    results: Optional[PathLike] = None,
    mode: str = "default",
    alignment: Optional[str] = None,
    registration: Optional[str] = None,
    save_registration: Optional[PathLike] = None,
    runs: Optional[str] = None,
    holdout: Optional[str] = None,
    bootstrap: Optional[int] = None,
    seed: int = 2019,
    link: Optional[str] = None,
    joint_space: bool = False,
    series: bool = False,
    physics_free: Union[bool, PathLike] = True,
    progress: Any = True,
) -> Comparison:
    """Compares sources against a reference (``realitygap compare``).

    ``study``: a study file (default the built-in study) or the output
    folder of :func:`replay` (the joint-space comparison, or of tossed
    objects the toss table: ``kind`` ``"tosses"``). The keywords are
    the command's options: ``data`` (``"builtin"``, ``"none"`` or a
    folder), ``results``, ``mode`` (``"default"`` or ``"study"``),
    ``alignment``, ``registration`` (``"estimate"``, ``"none"`` or a file),
    ``save_registration``, ``runs`` and ``holdout`` (``"1-15"``,
    ``"16-20"``), ``bootstrap`` (resamples; 0: no intervals), ``seed``,
    ``link`` (a replay's folder), ``joint_space``; ``series``: keep the
    per-step series (:meth:`Comparison.series`); ``physics_free``: by
    default (``True``) the physics-free model (perfect tracking) is added
    to every scene of a study whose scenes name scene files, unless it
    already has a physics-free row; a parameters file or a :func:`tune`
    folder adds the physics-free model fitted beside that tune too
    (``--physics-free``); ``False`` leaves them out
    (``--no-physics-free``)."""
    r = _reporter(progress)
    out = _native.compare(
        _path(study) if study is not None else builtin_study(),
        data=os.fspath(data),
        results=_path(results),
        mode=mode,
        alignment=alignment,
        registration=None if registration is None else os.fspath(registration),
        save_registration=_path(save_registration),
        runs=runs,
        holdout=holdout,
        bootstrap=bootstrap,
        seed=seed,
        link=link,
        joint_space=joint_space,
        series=series,
        physics_free=physics_free is not False,
        physics_free_params=None if isinstance(physics_free, bool) else os.fspath(physics_free),
        reporter=r,
    )
    return Comparison(out["kind"], out["csv"], out["markdown"], out["json"])


# --------------------------------------------------------------- load_run


class Run:
    """One run's trajectory (a results directory's ``runs/<id>.csv``).

    ``frame``: a DataFrame with the run CSV's columns (``t_s``,
    ``wrist_x_m`` ... ``wrist_qz``, ``q1_rad`` ..., ``NaN`` at a gap);
    ``time_s``, ``position(role)``, ``pose(role)``, ``joint_angles_rad``:
    numpy arrays; ``entry``: its manifest entry; ``manifest``: the
    directory's manifest (runs left out)."""

    def __init__(self, dir: str, id: str, columns: List[Tuple[str, bytes]], entry: Dict[str, Any], manifest: Dict[str, Any]) -> None:
        import numpy as np

        self.dir = dir
        self.id = id
        self.entry = entry
        self.manifest = manifest
        self.columns: Dict[str, "np.ndarray"] = {
            name: np.frombuffer(data, dtype="<f8") for name, data in columns
        }

    @property
    def frame(self) -> "pd.DataFrame":
        """The run as a DataFrame, columns as in the run CSV."""
        import pandas as pd

        return pd.DataFrame({k: v.copy() for k, v in self.columns.items()})

    @property
    def time_s(self) -> "np.ndarray":
        """Sample times, seconds."""
        return self.columns["t_s"]

    @property
    def bodies(self) -> List[str]:
        """The tracked bodies' roles (``wrist``, ``cube``, ...)."""
        return [c[: -len("_x_m")] for c in self.columns if c.endswith("_x_m")]

    def position(self, role: str = "wrist") -> "np.ndarray":
        """A body's positions, metres, shape (samples, 3); ``NaN`` at a gap."""
        import numpy as np

        return np.stack([self.columns["%s_%s_m" % (role, a)] for a in "xyz"], axis=1)

    def pose(self, role: str = "wrist") -> "np.ndarray":
        """A body's poses, shape (samples, 7): x, y, z (m), qw, qx, qy, qz."""
        import numpy as np

        names = ["%s_%s_m" % (role, a) for a in "xyz"] + ["%s_q%s" % (role, a) for a in "wxyz"]
        return np.stack([self.columns[n] for n in names], axis=1)

    def _joint_block(self, prefix: str, suffix: str) -> Optional["np.ndarray"]:
        import numpy as np

        cols = []
        j = 1
        while "%s%d%s" % (prefix, j, suffix) in self.columns:
            cols.append(self.columns["%s%d%s" % (prefix, j, suffix)])
            j += 1
        return np.stack(cols, axis=1) if cols else None

    @property
    def joint_angles_rad(self) -> Optional["np.ndarray"]:
        """Joint angles, radians, shape (samples, joints), when known."""
        return self._joint_block("q", "_rad")

    @property
    def joint_velocity_commands_rad_s(self) -> Optional["np.ndarray"]:
        """Commanded joint velocities, rad/s, when known."""
        return self._joint_block("qd_cmd", "_rad_s")

    @property
    def status(self) -> str:
        """``ok``, ``diverged``, ``unstable``, ..."""
        return self.entry.get("status", "")

    def __len__(self) -> int:
        return len(self.time_s)

    def __repr__(self) -> str:
        return "Run(%r, %r: %d samples, bodies %s)" % (self.dir, self.id, len(self), ", ".join(self.bodies))


def load_run(path: PathLike, run: Optional[str] = None) -> Run:
    """One run of a results directory (``manifest.json`` and ``runs/``):
    ``path`` is the directory (``run``: its id, default the first run with
    a trajectory) or a run's CSV file (``.../runs/run000.csv``)."""
    p = Path(os.fspath(path))
    if p.is_file() and p.suffix == ".csv":
        if run is None:
            run = p.stem
        p = p.parent.parent
    d = _native.load_run(os.fspath(p), run)
    return Run(os.fspath(p), d["id"], d["columns"], json.loads(d["entry"]), json.loads(d["manifest"]))


# --------------------------------------------------------------- run


class RunBatch:
    """A batch of runs (``realitygap run``): ``groups`` (one row per
    results directory: scene, source, engine, dir, ok, diverged, unstable,
    failed, kept) and ``summary`` (the command's lines)."""

    def __init__(self, out: str, summary: List[str], groups: List[Dict[str, Any]]) -> None:
        self.out = out
        self.summary = summary
        self._groups = groups

    @property
    def groups(self) -> "pd.DataFrame":
        import pandas as pd

        return pd.DataFrame(self._groups)

    @property
    def dirs(self) -> List[str]:
        """The results directories."""
        return [g["dir"] for g in self._groups]

    def load(self, scene: Optional[str] = None, source: Optional[str] = None, run: Optional[str] = None) -> Run:
        """A run of the batch (default the first group's first)."""
        for g in self._groups:
            if (scene is None or g["scene"] == scene) and (source is None or g["source"] == source):
                return load_run(g["dir"], run)
        raise KeyError("no results directory for scene %r, source %r" % (scene, source))

    def __repr__(self) -> str:
        return "\n".join(self.summary)


def run(
    scenes: Union[PathLike, Sequence[PathLike]],
    engine: Union[None, str, Sequence[str]] = None,
    *,
    out: PathLike,
    repeats: int = 1,
    params: Optional[Params] = None,
    robot: Optional[str] = None,
    packages: Union[None, Dict[str, PathLike], Sequence[str]] = None,
    jobs: Optional[int] = None,
    seed: int = 0,
    perturb: Union[None, str, Dict[str, float], Sequence[str]] = None,
    set: Union[None, Dict[str, Any], Sequence[str]] = None,
    timeout_s: Optional[float] = None,
    stitch: Union[None, str, Sequence[str]] = None,
    allow_unstable: bool = False,
    progress: Any = True,
) -> RunBatch:
    """Simulates scenes in engines (``realitygap run``), in parallel child
    processes, into ``out/<scene>/<source>/``; a rerun skips finished
    runs, and Ctrl-C keeps them.

    ``scenes``: scene files or shipped scene names (:func:`scene_file`);
    ``engine``: one name or several (default: every engine compiled in);
    ``params``: a parameters file or a dict (``{"joints": {"NAME":
    {"damping": 0.1}}}``, written into ``out`` as TOML); ``set``: engine
    settings (``{"mujoco.timestep_s": 0.0005}``); ``perturb``:
    ``{"sensor_noise_deg": 0.1}``; ``packages``: ``{"NAME": DIR}``;
    ``stitch``: engines per phase. Raises :class:`RealityGapError` when a
    model does not load or a run fails, with the command's message."""
    scene_list = [scene_file(s) for s in ([scenes] if isinstance(scenes, (str, os.PathLike)) else scenes)]
    pk = ["%s=%s" % (k, os.fspath(v)) for k, v in packages.items()] if isinstance(packages, dict) else _names(packages)
    r = _reporter(progress)
    res = _native.run(
        scene_list,
        out=os.fspath(out),
        engines=_names(engine),
        repeats=repeats,
        robot=robot,
        packages=pk,
        jobs=jobs,
        seed=seed,
        perturb=_perturb(perturb),
        set=_key_values(set),
        timeout_s=timeout_s,
        params=_params_file(params, out),
        stitch=stitch if stitch is None or isinstance(stitch, str) else ",".join(stitch),
        allow_unstable=allow_unstable,
        reporter=r,
    )
    return RunBatch(os.fspath(out), list(res["summary"]), json.loads(res["groups"]))


# --------------------------------------------------------------- replay


class Replay:
    """A replay (``realitygap replay``): ``kind`` (``"replay"``, a robot's
    episodes, or ``"tosses"``, tossed objects), ``table`` (the joint-space
    table: per source and joint, RMS and largest angle error, tracking
    delay; or the toss table: per source the cube centre's error in cube
    edges, by phase, with intervals), ``rows`` (its JSON), ``markdown``,
    ``report`` (index.html) and ``out``."""

    def __init__(self, out: str, d: Dict[str, Any]) -> None:
        self.out = out
        self.kind = d["kind"]
        self.csv = d["csv"]
        self.markdown = d["markdown"]
        self.rows = json.loads(d["json"])
        self.report = d["report"]

    @property
    def table(self) -> "pd.DataFrame":
        return _csv_frame(self.csv)

    def compare(self, link: Optional[str] = None) -> Comparison:
        """The comparison of the replay's folder again (``compare OUT``)."""
        return compare(self.out, link=link)

    def _repr_markdown_(self) -> str:
        return self.markdown

    def __repr__(self) -> str:
        return self.markdown


def replay(
    recordings: PathLike,
    robot: Optional[PathLike] = None,
    engines: Union[None, str, Sequence[str]] = None,
    *,
    out: PathLike,
    params: Optional[Params] = None,
    scene: Optional[PathLike] = None,
    packages: Union[None, Dict[str, PathLike], Sequence[str]] = None,
    jobs: Optional[int] = None,
    progress: Any = True,
) -> Replay:
    """Replays a robot's recorded episodes (a results directory written by
    ``realitygap import rosbag|csv|lerobot``) in every engine from their
    first joint state, with the physics-free model beside them
    (``realitygap replay``). ``robot``: its URDF (default: the one the
    import recorded); ``params``: servo gains and other parameters (a file
    or a dict); ``scene``: a scene instead of the generated one.
    ``recordings`` may also be tossed objects (``realitygap import
    contactnets``): every toss from its first recorded pose and twist
    (``kind`` ``"tosses"``; ``robot``, ``scene`` and ``packages`` do not
    apply)."""
    pk = ["%s=%s" % (k, os.fspath(v)) for k, v in packages.items()] if isinstance(packages, dict) else _names(packages)
    r = _reporter(progress)
    d = _native.replay(
        os.fspath(recordings),
        out=os.fspath(out),
        robot=_path(robot),
        packages=pk,
        engines=_names(engines),
        params=_params_file(params, out),
        scene=_path(scene),
        jobs=jobs,
        reporter=r,
    )
    return Replay(os.fspath(out), d)


# --------------------------------------------------------------- tune


class TuneResult:
    """A tune (``realitygap tune``), read from its output folder.

    ``params``: the tuned parameters (``tuned.toml``) as a dict, ready for
    ``run(..., params=...)``; ``params_file``: that file; ``summary``: the
    scores, untuned against tuned per set of runs and scene, with 95 %
    intervals (a DataFrame); ``parameters``: per parameter its bounds,
    start and value; ``history``: every evaluation (``history.csv``);
    ``intervals``: the intervals the tune gives (the scores' for a study,
    the fitted parameters' for recordings); ``summary_json``: all of
    ``summary.json``; ``markdown``: the summary as printed."""

    def __init__(self, engine: str, out: str, markdown: str, files: List[str]) -> None:
        self.engine = engine
        self.out = out
        self.markdown = markdown
        self.files = files
        with open(os.path.join(out, "summary.json"), encoding="utf-8") as f:
            self.summary_json: Dict[str, Any] = json.load(f)
        self.recordings = "scores" in self.summary_json and "identifiability" in self.summary_json

    @property
    def params_file(self) -> str:
        return os.path.join(self.out, "tuned.toml")

    @property
    def params(self) -> Dict[str, Any]:
        return json.loads(_native.read_toml(self.params_file))

    @property
    def history(self) -> "pd.DataFrame":
        import pandas as pd

        path = os.path.join(self.out, "history.csv")
        if not os.path.isfile(path):
            return pd.DataFrame()
        return pd.read_csv(path)

    @property
    def parameters(self) -> "pd.DataFrame":
        import pandas as pd

        key = "params" if self.recordings else "parameters"
        return pd.json_normalize(self.summary_json.get(key, []))

    @property
    def summary(self) -> "pd.DataFrame":
        import pandas as pd

        s = self.summary_json
        rows = []
        if s.get("kind") == "tosses":
            # A study of tosses: the held-out table (the engine at its
            # defaults, tuned, and the physics-free row), in cube edges.
            return pd.json_normalize(s.get("held_out", []))
        if self.recordings:
            for src in s["scores"]:
                for set_name in ("train", "holdout"):
                    x = src.get(set_name)
                    if x:
                        iv = x.get("interval_deg") or [None, None]
                        rows.append({"set": set_name, "source": src["source"], "rms_deg": x["rms_deg"],
                                     "low_deg": iv[0], "high_deg": iv[1]})
            return pd.DataFrame(rows)

        def scored(x: Optional[Dict[str, Any]]) -> Tuple[Any, Any, Any]:
            if not x:
                return (None, None, None)
            iv = x.get("interval_m") or [None, None]
            return (x["value_m"], iv[0], iv[1])

        for set_name in ("training", "holdout"):
            c = s.get(set_name)
            if not c:
                continue
            for sc in c["scenes"]:
                u, t = scored(sc.get("untuned")), scored(sc.get("tuned"))
                rows.append({"set": set_name, "runs": c["runs"], "scene": sc["scene"],
                             "untuned_m": u[0], "untuned_low_m": u[1], "untuned_high_m": u[2],
                             "tuned_m": t[0], "tuned_low_m": t[1], "tuned_high_m": t[2]})
            u, t = scored(c.get("total_untuned")), scored(c.get("total_tuned"))
            rows.append({"set": set_name, "runs": c["runs"], "scene": "Total",
                         "untuned_m": u[0], "untuned_low_m": u[1], "untuned_high_m": u[2],
                         "tuned_m": t[0], "tuned_low_m": t[1], "tuned_high_m": t[2]})
        return pd.DataFrame(rows)

    @property
    def intervals(self) -> Optional["pd.DataFrame"]:
        import pandas as pd

        if self.recordings:
            rows = [
                {"key": p["key"], "value": p["value"], "low": p["interval"][0], "high": p["interval"][1]}
                for p in self.summary_json.get("params", [])
                if p.get("interval")
            ]
            return pd.DataFrame(rows) if rows else None
        s = self.summary
        if s.empty:
            return None
        rows = []
        for _, r in s.iterrows():
            for which in ("untuned", "tuned"):
                if r[which + "_low_m"] is not None and not pd.isna(r[which + "_low_m"]):
                    rows.append({"set": r["set"], "scene": r["scene"], "engine": which,
                                 "value_m": r[which + "_m"], "low_m": r[which + "_low_m"],
                                 "high_m": r[which + "_high_m"]})
        return pd.DataFrame(rows) if rows else None

    def _repr_markdown_(self) -> str:
        return self.markdown

    def __repr__(self) -> str:
        return self.markdown


def tune(
    engine: str,
    *,
    out: PathLike,
    study: Optional[PathLike] = None,
    recordings: Optional[PathLike] = None,
    budget: Optional[int] = None,
    seed: int = 1,
    restarts: bool = False,
    runs: Optional[str] = None,
    holdout: Optional[str] = None,
    folds: Optional[int] = None,
    jobs: Optional[int] = None,
    space: Optional[PathLike] = None,
    settings: Optional[PathLike] = None,
    set: Union[None, Dict[str, Any], Sequence[str]] = None,
    data: Union[str, PathLike] = "builtin",
    cube_weight: Optional[float] = None,
    keep_registration: bool = False,
    baseline: bool = True,
    start: str = "space",
    prior_weight: float = 0.0,
    robot: Optional[str] = None,
    packages: Union[None, Dict[str, PathLike], Sequence[str]] = None,
    params: Optional[Params] = None,
    scene: Optional[PathLike] = None,
    efforts: bool = False,
    iterations: Optional[int] = None,
    progress: Any = True,
) -> TuneResult:
    """Calibrates ``engine`` (``realitygap tune``) into ``out``: against a
    study's real runs (``study``, default the built-in study; a study of
    tosses such as ``assets/studies/contactnets2020.toml`` fits the contact
    on its tosses and scores it on the ones it holds out) with CMA-ES
    over ``budget`` evaluations (default 600, or the toss study's own) (``restarts``: restart a stalled search
    from a random point with twice the population), then untuned against tuned on the
    training and held-out runs with intervals (``folds``: cross-validated,
    one tune per fold of consecutive runs, gathered into ``crossval.md``); or against a robot's own
    recorded episodes (``recordings``: a results directory of ``realitygap
    import``; ``params``: known parameters, ``scene``, ``efforts``,
    ``iterations``). ``baseline=False`` leaves out the physics-free model
    behind its own fitted actuator stage (about half a study tune's time);
    ``start="physics-free"`` fits it first and starts the engine's search at
    its fitted actuator stage and registration; ``prior_weight`` (metres per
    range, ``--prior-weight``) pulls the engine's shared keys toward that fit's
    values. A rerun with the same options resumes from
    ``history.csv``; Ctrl-C keeps the finished generations."""
    if recordings is None and study is None:
        study = builtin_study()
    pk = ["%s=%s" % (k, os.fspath(v)) for k, v in packages.items()] if isinstance(packages, dict) else _names(packages)
    r = _reporter(progress)
    d = _native.tune(
        engine=engine,
        out=os.fspath(out),
        study=_path(study),
        recordings=_path(recordings),
        params=_params_file(params, out),
        scene=_path(scene),
        efforts=efforts,
        iterations=iterations,
        data=os.fspath(data),
        space=_path(space),
        runs=runs,
        holdout=holdout,
        folds=folds,
        budget=budget,
        seed=seed,
        restarts=restarts,
        jobs=jobs,
        cube_weight=cube_weight,
        keep_registration=keep_registration,
        baseline=baseline,
        start=start,
        prior_weight=prior_weight,
        settings=_path(settings),
        set=_key_values(set),
        robot=robot,
        packages=pk,
        reporter=r,
    )
    if folds is not None:
        return CrossValidated(engine, os.fspath(out), d["markdown"], list(d["files"]))
    return TuneResult(engine, os.fspath(out), d["markdown"], list(d["files"]))


class CrossValidated:
    """A cross-validated tune (``tune(..., folds=K)``), read from its
    output folder: ``json`` (all of ``crossval.json``), ``table`` (per
    source and scene, the held-out accumulated error's mean over folds,
    its 95 % t interval and standard deviation), ``differences`` (the tuned
    engine minus each physics-free row, likewise, with the folds it wins),
    ``verdict``, ``folds`` (each fold's own :class:`TuneResult`) and
    ``markdown``."""

    def __init__(self, engine: str, out: str, markdown: str, files: List[str]) -> None:
        self.engine = engine
        self.out = out
        self.markdown = markdown
        self.files = files
        with open(os.path.join(out, "crossval.json"), encoding="utf-8") as f:
            self.json: Dict[str, Any] = json.load(f)
        self.verdict: str = self.json["verdict"]

    def _frame(self, key: str, name: str) -> "pd.DataFrame":
        import pandas as pd

        rows = []
        scenes = list(self.json["scenes"]) + ["total"]
        for r in self.json[key]:
            cells = list(r["scenes"]) + [r["total"]]
            for scene, c in zip(scenes, cells):
                if c is None:
                    continue
                row = {name: r[name], "scene": scene, "mean_m": c["mean"], "low_m": c["interval"][0],
                       "high_m": c["interval"][1], "sd_m": c["sd"]}
                if key == "differences":
                    row["folds_below_zero"] = sum(1 for v in c["folds"] if v < 0)
                rows.append(row)
        return pd.DataFrame(rows)

    @property
    def table(self) -> "pd.DataFrame":
        return self._frame("rows", "source")

    @property
    def differences(self) -> "pd.DataFrame":
        return self._frame("differences", "against")

    @property
    def folds(self) -> List[TuneResult]:
        return [TuneResult(self.engine, f["folder"], "", []) for f in self.json["folds"]]

    @property
    def phases(self) -> "pd.DataFrame":
        """Per scene, phase of the schedule (numbered from 1, with its start
        in seconds) and source, the held-out accumulated error's mean over
        folds with its 95 % t interval; for the tuned engine minus each
        physics-free row, ``source`` is ``"tuned minus <row>"`` and
        ``folds_below_zero`` counts the folds the engine wins."""
        import pandas as pd

        rows = []
        for p in self.json.get("phases", []):
            named = [(r["source"], r, False) for r in p["rows"]]
            named += [("tuned minus " + d["source"], d, True) for d in p["differences"]]
            for name, r, diff in named:
                for i, c in enumerate(r["phases"]):
                    if c is None:
                        continue
                    row = {"scene": p["scene"], "phase": i + 1, "start_s": p["phases_s"][i],
                           "source": name, "mean_m": c["mean"], "low_m": c["interval"][0],
                           "high_m": c["interval"][1]}
                    if diff:
                        row["folds_below_zero"] = sum(1 for v in c["folds"] if v < 0)
                    rows.append(row)
        return pd.DataFrame(rows)

    def __repr__(self) -> str:
        return "CrossValidated(%r, %d folds: %s)" % (self.engine, len(self.json["folds"]), self.verdict)


# --------------------------------------------------------------- reproduce


class Reproduction(Comparison):
    """The whole study (``realitygap reproduce``): the comparison
    (``table``, ``measures``, ``json``, ``markdown``), and ``report``
    (``OUT/report/index.html``), ``timings`` (seconds per stage),
    ``problems`` (simulations that did not all finish), ``joint_space``
    (Markdown, when asked for), ``out``."""

    def __init__(self, out: str, d: Dict[str, Any]) -> None:
        super().__init__("study", d["csv"], d["markdown"], d["json"])
        self.out = out
        self.report = d["report"]
        self.timings = dict(d["timings"])
        self.problems = list(d["problems"])
        self.joint_space = d["joint_space"]
        self.tosses = d.get("tosses")


def reproduce(
    out: PathLike,
    *,
    data: Union[str, PathLike] = "builtin",
    repeats: int = 20,
    engines: Union[None, str, Sequence[str]] = None,
    scenes: Union[None, PathLike, Sequence[PathLike]] = None,
    jobs: Optional[int] = None,
    mode: str = "default",
    timeout_s: Optional[float] = None,
    params: Optional[Params] = None,
    tuned: Union[None, PathLike, TuneResult, Sequence[Union[PathLike, TuneResult]]] = None,
    crossval: Union[None, PathLike, "CrossValidated", Sequence[Union[PathLike, "CrossValidated"]]] = None,
    joint_space: bool = False,
    runs: Optional[str] = None,
    holdout: Optional[str] = None,
    tosses: bool = True,
    progress: Any = True,
) -> Reproduction:
    """The whole study in one call (``realitygap reproduce``): every scene
    in every engine (``repeats`` times), compared with the real arm and the
    study's recorded simulators, the table, the figures and
    ``out/report/index.html``. ``tuned``: tunes (:class:`TuneResult` or
    their folders) whose engines run again tuned, as "<engine> (tuned)"
    rows. ``crossval``: cross-validated tunes (:class:`CrossValidated` or
    their folders): the report's verdict opens with whether any tuned engine
    beats the physics-free model behind its fitted actuator stage on runs it
    did not see, and a section holds their table and figures. ``tosses``:
    also replay the 456 real cube tosses built in, in every engine beside
    the physics-free row (``tosses``: their table, Markdown). Resumes where
    an earlier call stopped."""
    if tuned is None:
        tuned_list: List[Any] = []
    elif isinstance(tuned, (str, os.PathLike, TuneResult)):
        tuned_list = [tuned]
    else:
        tuned_list = list(tuned)
    tuned_dirs = [t.out if isinstance(t, TuneResult) else os.fspath(t) for t in tuned_list]
    if crossval is None:
        cv_list: List[Any] = []
    elif isinstance(crossval, (str, os.PathLike, CrossValidated)):
        cv_list = [crossval]
    else:
        cv_list = list(crossval)
    cv_dirs = [c.out if isinstance(c, CrossValidated) else os.fspath(c) for c in cv_list]
    scene_list = None if scenes is None else [
        scene_file(s) for s in ([scenes] if isinstance(scenes, (str, os.PathLike)) else scenes)
    ]
    r = _reporter(progress)
    d = _native.reproduce(
        out=os.fspath(out),
        data=os.fspath(data),
        repeats=repeats,
        engines=_names(engines),
        scenes=scene_list or [],
        jobs=jobs,
        mode=mode,
        timeout_s=timeout_s,
        params=_params_file(params, out),
        tuned=tuned_dirs,
        crossval=cv_dirs,
        joint_space=joint_space,
        runs=runs,
        holdout=holdout,
        tosses=tosses,
        reporter=r,
    )
    return Reproduction(os.fspath(out), d)
