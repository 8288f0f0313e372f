"""realitygap's engine-adapter SDK: a physics engine as a child process.

An engine that is not linked into realitygap runs as a child process that
speaks the engine protocol (``docs/engine-protocol.md``) on its standard
input and output. This module is the Python side of that protocol: an
adapter subclasses :class:`Adapter` (what the engine is, its settings, how
it loads a model) and :class:`Simulation` (one loaded model: stepping,
readings, states), and :func:`serve` does the rest: the framing (one JSON
object per line), the bits of every vector (:func:`bits`, :func:`floats`),
the checks of what comes in and goes out, and the errors.

Units everywhere: SI (m, s, kg, N, N m); joint angles in rad for hinge
joints and m for slide joints, joint velocities in rad/s or m/s; poses as
``x y z qw qx qy qz`` (m, unit quaternion, body to world).

Only numpy and the standard library are needed (Python >= 3.11).
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
import traceback
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

__all__ = [
    "PROTOCOL",
    "COMMAND_KINDS",
    "Setting",
    "Param",
    "EngineError",
    "SettingError",
    "LoadError",
    "ParamError",
    "UnstableError",
    "StateError",
    "UsageError",
    "Reading",
    "ObjectState",
    "FullState",
    "StabilityIssue",
    "SettingsReader",
    "Adapter",
    "Simulation",
    "bits",
    "floats",
    "display",
    "serve",
]

#: The protocol version this SDK speaks.
PROTOCOL = 1

#: The kinds of joint commands, in the protocol's spelling.
COMMAND_KINDS = ("velocity", "position", "effort")


# --------------------------------------------------------------------------
# Descriptions


@dataclass(frozen=True)
class Setting:
    """A setting the engine accepts (``[engine.NAME]`` and ``--set``).

    ``key`` as written by the user (``timestep_s``); ``help`` says what it
    does, its unit, its allowed values and its default.
    """

    key: str
    help: str


@dataclass(frozen=True)
class Param:
    """A physical parameter key the engine maps itself, and how.

    ``key`` as in a parameters file with ``*`` for the name
    (``joints.*.armature``); ``mapping`` names the engine's own quantity
    (``dof_armature of the joint's DOF``).
    """

    key: str
    mapping: str


# --------------------------------------------------------------------------
# Errors: one class per reply kind


class EngineError(Exception):
    """An error reply: ``{"error": {"kind": KIND, "message": MESSAGE}}``.

    Raise one of the subclasses from any adapter method; :func:`serve`
    turns it into the reply of its kind.
    """

    kind = "usage"

    def __init__(self, message: str):
        super().__init__(message)
        self.message = str(message)

    def reply(self) -> dict:
        """The ``error`` object of the reply."""
        return {"kind": self.kind, "message": self.message}


class SettingError(EngineError):
    """A setting is unknown or has a bad value (``setting``, with ``key``).

    The message says what is accepted: ``must be > 0 s and finite, found -1``.
    """

    kind = "setting"

    def __init__(self, key: str, message: str):
        super().__init__(message)
        self.key = str(key)

    def reply(self) -> dict:
        return {"kind": self.kind, "message": self.message, "key": self.key}


class LoadError(EngineError):
    """The model description cannot be built (``load``): a shape or
    feature the engine lacks, a model the engine rejects."""

    kind = "load"


class ParamError(EngineError):
    """An engine-mapped parameter cannot be honoured with its value
    (``param``, with ``key``, e.g. ``objects.cube.restitution``)."""

    kind = "param"

    def __init__(self, key: str, message: str):
        super().__init__(message)
        self.key = str(key)

    def reply(self) -> dict:
        return {"kind": self.kind, "message": self.message, "key": self.key}


class UnstableError(EngineError):
    """The simulation became unusable (``unstable``): a non-finite state,
    an instability the engine detected.

    ``t_s`` is the simulated time (s) at which it was found; ``None`` lets
    :func:`serve` use the time of the last reading it sent.
    """

    kind = "unstable"

    def __init__(self, message: str, t_s: float | None = None):
        super().__init__(message)
        self.t_s = None if t_s is None else float(t_s)

    def reply(self) -> dict:
        out = {"kind": self.kind, "message": self.message}
        if self.t_s is not None and math.isfinite(self.t_s):
            out["t_s"] = self.t_s
        return out


class StateError(EngineError):
    """A full state that cannot be loaded (``state``): wrong joint or
    object count, non-finite values, a native state of another model."""

    kind = "state"


class UsageError(EngineError):
    """A request that does not fit (``usage``): a vector of the wrong
    length, an unknown op, a step before any load."""

    kind = "usage"


# --------------------------------------------------------------------------
# What a simulation reports


@dataclass
class Reading:
    """What the controller reads after every control period.

    - ``t``: simulated time, s;
    - ``q``: the controlled joints' positions (rad or m), actuator order;
    - ``qd``: their velocities (rad/s or m/s);
    - ``poses``: ``(tracked, 7)``, each ``x y z qw qx qy qz`` (body to
      world), in the model's ``tracked`` order.
    """

    t: float
    q: np.ndarray
    qd: np.ndarray
    poses: np.ndarray


@dataclass
class ObjectState:
    """A scene object's state: ``pose`` (7: centre and orientation, body to
    world), ``v`` (3: the centre's velocity, m/s, world frame) and ``w``
    (3: angular velocity, rad/s, world frame)."""

    name: str
    pose: np.ndarray
    v: np.ndarray
    w: np.ndarray


@dataclass
class FullState:
    """A reading's joints and time, the objects' states, and the engine's
    own numbers (``native``, or ``None``): everything to restore the
    simulation exactly when ``native`` is given back."""

    t: float
    q: np.ndarray
    qd: np.ndarray
    objects: list[ObjectState] = field(default_factory=list)
    native: np.ndarray | None = None


@dataclass
class StabilityIssue:
    """A setting the engine knows to be unstable for the loaded model.

    ``joint`` (a name or ``None``), the ``quantity`` bounded
    (``kv*dt/I_eff``), its ``value`` and ``bound``, and a ``message`` with
    the fix.
    """

    joint: str | None
    quantity: str
    value: float
    bound: float
    message: str

    def to_json(self) -> dict:
        return {
            "joint": self.joint,
            "quantity": self.quantity,
            "value": float(self.value),
            "bound": float(self.bound),
            "message": self.message,
        }


# --------------------------------------------------------------------------
# Numbers


def bits(vec: Any) -> str:
    """The protocol text of a vector of f64: the hexadecimal text of its
    little-endian IEEE 754 bytes, 16 hex digits per number (``[1.0]`` is
    ``"000000000000f03f"``). A scalar is a vector of one; arrays are
    flattened in C order. Exact for every value (subnormals, -0.0, NaN
    payloads); finiteness is checked by :func:`serve`, not here."""
    return np.ascontiguousarray(np.asarray(vec, dtype="<f8").ravel()).tobytes().hex()


def floats(text: str) -> np.ndarray:
    """The vector of f64 whose protocol text is ``text`` (see :func:`bits`),
    as a new writable array. A ``ValueError`` when it is not hexadecimal or
    not a multiple of 16 digits."""
    if not isinstance(text, str):
        raise ValueError(f"expected the hexadecimal text of f64 values, found {type(text).__name__}")
    if len(text) % 16:
        raise ValueError(f"{len(text)} hex digits is not a whole number of f64 values (16 digits each)")
    return np.frombuffer(bytes.fromhex(text), dtype="<f8").astype(np.float64)


def display(x: float) -> str:
    """``x`` as Rust's ``{}`` writes an f64 (the shortest text that reads back,
    never in exponent form: ``1``, ``0.0001``, ``-0``, ``inf``, ``NaN``), so
    that messages read the same as a linked engine's."""
    x = float(x)
    if math.isnan(x):
        return "NaN"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return np.format_float_positional(x, trim="-")


# --------------------------------------------------------------------------
# Settings


class SettingsReader:
    """Reads an engine's settings (the JSON values of ``[engine.NAME]``)
    with the same checks and messages as realitygap's linked engines.

    ``SettingsReader(settings, known)`` refuses a key not among ``known``
    (a list of :class:`Setting`) with the accepted keys; then each method
    returns the value of one key, ``None`` when unset, or raises a
    :class:`SettingError` naming the key: ``must be ..., found ...``.
    """

    def __init__(self, settings: Mapping[str, Any], known: Sequence[Setting]):
        if not isinstance(settings, Mapping):
            raise UsageError(f"settings must be a JSON object, found {json.dumps(settings)}")
        self.settings = settings
        names = [s.key for s in known]
        for key in settings:
            if key not in names:
                raise SettingError(key, f"unknown setting (accepted: {', '.join(names)})")

    @staticmethod
    def _text(value: Any) -> str:
        if isinstance(value, bool):
            return "true" if value else "false"
        if isinstance(value, float):
            return repr(value)
        return str(value)

    def number(self, key: str, ok, what: str) -> float | None:
        """A number (integers convert; the text ``inf`` is infinity); ``ok``
        says which values are accepted, ``what`` describes them. NaN is
        never accepted."""
        if key not in self.settings:
            return None
        value = self.settings[key]
        if isinstance(value, str) and value.strip().lower() in ("inf", "infinity"):
            v = math.inf
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            v = float(value)
        else:
            raise SettingError(key, f'expected a number, found "{self._text(value)}"')
        if math.isnan(v) or not ok(v):
            raise SettingError(key, f"must be {what}, found {display(v)}")
        return v

    def integer(self, key: str, lo: int, hi: int) -> int | None:
        """A whole number (a JSON integer) in ``lo..=hi``."""
        if key not in self.settings:
            return None
        value = self.settings[key]
        if not isinstance(value, int) or isinstance(value, bool):
            raise SettingError(key, f'expected a whole number, found "{self._text(value)}"')
        if not lo <= value <= hi:
            raise SettingError(key, f"must be a whole number from {lo} to {hi}, found {value}")
        return value

    def boolean(self, key: str) -> bool | None:
        """``true`` or ``false``."""
        if key not in self.settings:
            return None
        value = self.settings[key]
        if not isinstance(value, bool):
            raise SettingError(key, f'expected true or false, found "{self._text(value)}"')
        return value

    def choice(self, key: str, choices: Sequence[tuple[str, Any]]) -> Any | None:
        """One of ``choices`` (``(name, value)`` pairs) by name,
        case-insensitive."""
        if key not in self.settings:
            return None
        value = self.settings[key]
        text = value.strip().lower() if isinstance(value, str) else None
        for name, v in choices:
            if name == text:
                return v
        names = ", ".join(n for n, _ in choices)
        raise SettingError(key, f'"{self._text(value)}" is not one of {names}')


# --------------------------------------------------------------------------
# The adapter's classes


class Simulation:
    """One loaded model and its state, driven by :func:`serve`.

    :func:`serve` has already checked what it passes (vector lengths
    against the model's ``actuators`` and ``objects``, finite values, known
    command kinds, a ``kp`` for position commands), and checks every
    number of what comes back before it leaves the process.
    """

    #: The controlled joints' names, actuator order, for messages (set by
    #: the adapter; ``serve`` sets it from the model when left ``None``).
    joint_names: list[str] | None = None

    def stability_issues(self) -> list[StabilityIssue]:
        """Settings the engine knows to be unstable for this model (checked
        once, after load, at the initial state). Default: none."""
        return []

    def step(self, n: int) -> None:
        """Advances ``n`` (>= 1) timesteps under the commands in force. A
        detected instability raises :class:`UnstableError` (with the
        simulated time); any other exception is reported as one too."""
        raise NotImplementedError

    def reading(self) -> Reading:
        """The current :class:`Reading` (time, controlled joints, tracked
        poses), all at the same time: body poses belong to the current
        joint positions."""
        raise NotImplementedError

    def set_commands(self, kinds: list[str], values: np.ndarray) -> None:
        """Sets the servo commands, one per controlled joint in actuator
        order: ``kinds[i]`` in ``velocity`` (rad/s), ``position`` (rad),
        ``effort`` (N m); they hold until the next call. The laws (the
        actuator's ``kv``, ``kp`` and force limit): velocity
        ``tau = kv (value - qd)``, position ``tau = kp (value - q) - kv qd``,
        effort ``tau = value``, each limited to ``[-force_limit,
        force_limit]``. Before the first call every servo is a velocity
        servo with target 0."""
        raise NotImplementedError

    def run_open_loop(self, steps: int, change_at: np.ndarray, values: np.ndarray,
                      read_at: np.ndarray) -> np.ndarray | None:
        """Optional, for speed: ``steps`` (>= 1) steps of a ``run`` (the
        replay of a recording) in the engine's own loop, the command kinds
        (laws) in force throughout. Row ``c`` of ``values`` (joint values,
        actuator order) takes force before step ``change_at[c]`` (ascending,
        in ``[0, steps]``: at one step the last row holds, at ``steps`` it
        holds after the call); the commands in force at the call hold
        before the first. Returns one reading per entry of ``read_at`` (ascending, in
        ``[0, steps]``): the state before that step (``steps``: at the end),
        each row ``t, q, qd, poses`` flat (``1 + 2 joints + 7 tracked``
        numbers), as :meth:`reading` would give it.

        Return ``None``, with the simulation as it was at the call, to have
        :func:`serve` take the same steps a segment at a time through
        :meth:`reading`, :meth:`set_commands` and :meth:`step`: the default,
        and what to do when the engine met something it cannot report from
        its own loop (an instability: the segment-wise run then finds where
        and says what). Non-finite rows are checked by :func:`serve`."""
        return None

    def set_joint_angles(self, q: np.ndarray) -> None:
        """Puts the controlled joints at ``q`` (rad or m), at rest (their
        velocities 0), time and everything else unchanged, and recomputes
        what the reading reports."""
        raise NotImplementedError

    def full_state(self) -> FullState:
        """The current :class:`FullState`; ``native`` holds what restores the
        engine exactly (``None`` if the engine cannot)."""
        raise NotImplementedError

    def set_full_state(self, state: FullState) -> None:
        """Loads ``state``. With ``native`` (from :meth:`full_state` of this
        same model) exactly: stepping on gives the same numbers as if the
        simulation had never left that state, commands included. Without
        it, the portable fields: time, joints, objects; everything else
        reset (warm starts), the servos' commands kept as they are (the
        request may carry new ones, applied after this)."""
        raise NotImplementedError


class Adapter:
    """An engine: what it is, its settings, and how it loads a model.

    Subclasses set the class attributes and implement :meth:`version`,
    :meth:`check_settings` and :meth:`load`.
    """

    #: The engine's name (``realitygap engines``, result folders).
    name: str = "engine"
    #: The timestep when the settings give none, s.
    default_timestep_s: float = 0.002
    #: The accepted settings; every engine has ``timestep_s``.
    settings: list[Setting] = [Setting("timestep_s", "integration timestep, s (> 0)")]
    #: The engine-mapped parameter keys (``joints.*.armature``, ...).
    params: list[Param] = []
    #: kind (``velocity``, ``position``, ``effort``) -> the engine's
    #: mechanism for it, e.g. ``"<velocity> actuator law"``.
    commands: dict[str, str] = {}

    def version(self) -> str:
        """The engine library's version text, e.g. ``MyEngine 1.2``."""
        raise NotImplementedError

    def check_settings(self, settings: Mapping[str, Any]) -> float:
        """Checks ``settings`` (key -> JSON value, ``timeout_s`` removed)
        without loading anything; returns the timestep they select, s.
        A bad key or value raises :class:`SettingError`."""
        raise NotImplementedError

    def load(self, model: Mapping[str, Any]) -> Simulation:
        """Builds the model description of the protocol (plain JSON, parsed:
        numbers as int or float) and returns its :class:`Simulation` at time
        0: every controlled joint at 0 and at rest, objects at their poses
        and twists. Raises :class:`LoadError`, :class:`SettingError` (the
        description's ``settings``) or :class:`ParamError` (its
        ``params``)."""
        raise NotImplementedError


# --------------------------------------------------------------------------
# The loop


class _Session:
    """What :func:`serve` knows between requests."""

    def __init__(self, adapter: Adapter):
        self.adapter = adapter
        self.sim: Simulation | None = None
        self.model: Mapping[str, Any] | None = None
        self.joints = 0
        self.tracked = 0
        self.objects: list[str] = []
        self.kp: list[Any] = []
        self.names: list[str] = []
        self.last_t: float | None = None
        # The last command kinds found valid for this model (a replay
        # sends the same kinds with every step's values).
        self.checked_kinds: list[str] | None = None
        # The command kinds in force (None: not known here, after a native
        # state was loaded).
        self.kinds: list[str] | None = None


def _vector(request: Mapping[str, Any], key: str, what: str, n: int | None, error=UsageError) -> np.ndarray:
    if key not in request:
        raise error(f"{what}: missing `{key}`")
    try:
        v = floats(request[key])
    except ValueError as e:
        raise error(f"{what}: `{key}` is not a bits vector: {e}") from None
    if n is not None and v.size != n:
        raise error(f"{what}: `{key}` has {v.size} values, the model {n}")
    return v


def _finite_or_unstable(t: float, label: str, v: np.ndarray, names: Sequence[str] | None) -> None:
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size:
        i = int(bad[0])
        which = f'joint "{names[i]}"' if names and i < len(names) else f"value {i}"
        raise UnstableError(f"non-finite {label} of {which} ({display(v[i])}) at t = {display(t)} s", t)


def _reading_row(session: _Session, r: Reading) -> np.ndarray:
    """The reading as one checked vector: the time, q, qd, poses (a replay
    reads at every recorded sample). A non-finite number is an
    :class:`UnstableError` saying which; no NaN ever leaves as bits."""
    t = float(r.t)
    q = np.asarray(r.q, dtype=np.float64).ravel()
    qd = np.asarray(r.qd, dtype=np.float64).ravel()
    poses = np.asarray(r.poses, dtype=np.float64).reshape(-1)
    if q.size != session.joints or qd.size != session.joints:
        raise RuntimeError(f"the adapter's reading has {q.size} joint angles and {qd.size} joint velocities "
                           f"for {session.joints} controlled joints")
    if poses.size != 7 * session.tracked:
        raise RuntimeError(f"the adapter's reading has {poses.size} pose numbers for {session.tracked} tracked frames (7 each)")
    flat = np.concatenate(((t,), q, qd, poses))
    if not np.isfinite(flat).all():
        if not math.isfinite(t):
            raise UnstableError(f"non-finite time ({display(t)})", session.last_t)
        _finite_or_unstable(t, "joint angle", q, session.names)
        _finite_or_unstable(t, "joint velocity", qd, session.names)
        i = int(np.flatnonzero(~np.isfinite(poses))[0])
        raise UnstableError(f"non-finite pose of tracked frame {i // 7} (component {i % 7}: "
                            f"{display(poses[i])}) at t = {display(t)} s", t)
    session.last_t = t
    return flat


def _row_reading(session: _Session, row: np.ndarray) -> Reading:
    """The :class:`Reading` that a row of :func:`_reading_row` is."""
    j = session.joints
    return Reading(float(row[0]), row[1:1 + j], row[1 + j:1 + 2 * j], row[1 + 2 * j:])


def _reading_json(session: _Session, r: Reading) -> dict:
    text = bits(_reading_row(session, r))
    a = 16
    b = a + 16 * session.joints
    c = b + 16 * session.joints
    return {"t": text[:a], "q": text[a:b], "qd": text[b:c], "poses": text[c:]}


def _full_state_json(session: _Session, s: FullState) -> dict:
    r = _reading_json(session, Reading(s.t, s.q, s.qd, np.zeros(7 * session.tracked)))
    del r["poses"]
    objects = []
    if [o.name for o in s.objects] != session.objects:
        raise RuntimeError(f"the adapter's state has objects {[o.name for o in s.objects]}, the model {session.objects}")
    for o in s.objects:
        parts = {}
        for key, n in (("pose", 7), ("v", 3), ("w", 3)):
            v = np.asarray(getattr(o, key), dtype=np.float64).ravel()
            if v.size != n:
                raise RuntimeError(f"the adapter's state of object '{o.name}' has {v.size} numbers in `{key}`, not {n}")
            if not np.all(np.isfinite(v)):
                raise UnstableError(f"non-finite {key} of object '{o.name}' at t = {display(s.t)} s", float(s.t))
            parts[key] = bits(v)
        objects.append({"name": o.name, **parts})
    r["objects"] = objects
    if s.native is None:
        r["native"] = None
    else:
        native = np.asarray(s.native, dtype=np.float64).ravel()
        if not np.all(np.isfinite(native)):
            i = int(np.flatnonzero(~np.isfinite(native))[0])
            raise UnstableError(f"non-finite native state (number {i}: {display(native[i])}) at t = {display(s.t)} s", float(s.t))
        r["native"] = bits(native)
    return r


def _parse_full_state(session: _Session, request: Mapping[str, Any]) -> FullState:
    what = "set_state"
    t = _vector(request, "t", what, 1, StateError)[0]
    if not math.isfinite(t) or t < 0:
        raise StateError(f"time {display(t)} s is not a finite time >= 0")
    q = _vector(request, "q", what, session.joints, StateError)
    qd = _vector(request, "qd", what, session.joints, StateError)
    for key, v in (("q", q), ("qd", qd)):
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise StateError(f"{key}[{int(bad[0])}] is not finite")
    raw = request.get("objects", [])
    if not isinstance(raw, list) or not all(isinstance(o, Mapping) for o in raw):
        raise StateError("`objects` must be a list of objects")
    names = [o.get("name") for o in raw]
    if names != session.objects:
        raise StateError(f"the state has objects {names}, the model {session.objects}")
    objects = []
    for o in raw:
        parts = {}
        for key, n in (("pose", 7), ("v", 3), ("w", 3)):
            v = _vector(o, key, f"object '{o['name']}'", n, StateError)
            if not np.all(np.isfinite(v)):
                raise StateError(f"object '{o['name']}' has a non-finite pose or twist")
            parts[key] = v
        if not np.any(parts["pose"][3:] != 0):
            raise StateError(f"object '{o['name']}' has a zero quaternion")
        objects.append(ObjectState(o["name"], parts["pose"], parts["v"], parts["w"]))
    native = request.get("native")
    if native is not None:
        try:
            native = floats(native)
        except ValueError as e:
            raise StateError(f"`native` is not a bits vector: {e}") from None
        if not np.all(np.isfinite(native)):
            raise StateError("`native` holds a non-finite number")
    return FullState(float(t), q, qd, objects, native)


def _parse_commands(session: _Session, raw: Any) -> tuple[list[str], np.ndarray]:
    if not isinstance(raw, (dict, Mapping)):  # dict first: the fast check
        raise UsageError('`commands` must be {"kinds": [...], "values": BITS}')
    kinds = raw.get("kinds")
    if not isinstance(kinds, list) or not all(isinstance(k, str) for k in kinds):
        raise UsageError("`commands.kinds` must be a list of command kinds")
    values = _vector(raw, "values", "commands", None)
    if len(kinds) != session.joints or values.size != session.joints:
        raise UsageError(f"{len(kinds)} command kinds and {values.size} values for {session.joints} controlled joints")

    # The values every time, first (as the linked engines check), the
    # kinds when they change (a replay sends the same kinds at every step).
    if not np.isfinite(values).all():
        i = int(np.flatnonzero(~np.isfinite(values))[0])
        raise UsageError(f'the {kinds[i]} command of joint "{_joint(session, i)}" is {display(values[i])}')
    _check_kinds(session, kinds)
    return list(kinds), values


def _joint(session: _Session, i: int) -> str:
    return session.names[i] if i < len(session.names) else str(i)


def _check_kinds(session: _Session, kinds: list[str]) -> None:
    """Checks command kinds against the engine and the model's gains, when
    they change (a replay sends the same kinds at every step)."""
    if kinds == session.checked_kinds:
        return
    known = session.adapter.commands or {k: "" for k in COMMAND_KINDS}
    for i, k in enumerate(kinds):
        if k not in known:
            raise UsageError(f'joint "{_joint(session, i)}": unknown command kind "{k}" (this engine takes: {", ".join(known)})')
        if k == "position" and i < len(session.kp) and session.kp[i] is None:
            raise UsageError(
                f'joint "{_joint(session, i)}" takes a position command but its actuator has no position gain: '
                f"set kp in the scene's [[actuator]] or joints.{_joint(session, i)}.kp in the parameters")
    session.checked_kinds = list(kinds)


def _need_sim(session: _Session) -> Simulation:
    if session.sim is None:
        raise UsageError("no model is loaded (send `load` first)")
    return session.sim


def _handle(session: _Session, request: Mapping[str, Any]) -> dict:
    adapter = session.adapter
    op = request.get("op")
    if op == "hello":
        protocol = request.get("protocol")
        if protocol != PROTOCOL:
            raise UsageError(f"protocol {json.dumps(protocol)} is not spoken by this adapter (it speaks {PROTOCOL})")
        return {
            "protocol": PROTOCOL,
            "engine": adapter.name,
            "version": adapter.version(),
            "default_timestep_s": float(adapter.default_timestep_s),
            "settings": [{"key": s.key, "help": s.help} for s in adapter.settings],
            "params": [{"key": p.key, "mapping": p.mapping} for p in adapter.params],
            "commands": [{"kind": k, "mechanism": m} for k, m in adapter.commands.items()],
            # `run` in columns (below) is understood.
            "columns": True,
        }
    if op == "check_settings":
        settings = request.get("settings", {})
        if not isinstance(settings, Mapping):
            raise UsageError("`settings` must be a JSON object")
        # realitygap keeps timeout_s itself; never the engine's.
        settings = {k: v for k, v in settings.items() if k != "timeout_s"}
        return {"timestep_s": _checked_bits(float(adapter.check_settings(settings)), "timestep")}
    if op == "load":
        model = request.get("model")
        if not isinstance(model, Mapping):
            raise UsageError("`model` must be a JSON object")
        if isinstance(model.get("settings"), Mapping) and "timeout_s" in model["settings"]:
            model = dict(model, settings={k: v for k, v in model["settings"].items() if k != "timeout_s"})
        # One simulation per process: the old one goes first.
        session.sim = None
        session.last_t = None
        actuators = model.get("actuators") or []
        session.model = model
        session.joints = len(actuators)
        session.names = [str(a.get("joint", i)) for i, a in enumerate(actuators)]
        session.kp = [a.get("kp") for a in actuators]
        session.checked_kinds = None
        session.kinds = ["velocity"] * session.joints
        session.tracked = len(model.get("tracked") or [])
        session.objects = [o.get("name") for o in (model.get("objects") or [])]
        sim = adapter.load(model)
        if not isinstance(sim, Simulation):
            raise LoadError(f"the adapter's load returned {type(sim).__name__}, not a Simulation")
        if sim.joint_names is None:
            sim.joint_names = list(session.names)
        session.names = list(sim.joint_names)
        issues = [i.to_json() if isinstance(i, StabilityIssue) else dict(i) for i in sim.stability_issues()]
        for i in issues:
            if not all(math.isfinite(float(i[k])) for k in ("value", "bound")):
                raise LoadError(f"the stability check gave a non-finite number: {i}")
        state = _reading_json(session, sim.reading())
        session.sim = sim
        return {"state": state, "stability_issues": issues}
    if op == "step":
        sim = _need_sim(session)
        n = request.get("n")
        if not isinstance(n, int) or isinstance(n, bool) or n < 1:
            raise UsageError(f"`n` must be a whole number of steps >= 1, found {json.dumps(n)}")
        if request.get("commands") is not None:
            _set_commands(session, sim, *_parse_commands(session, request["commands"]))
        sim.step(n)
        return {"state": _reading_json(session, sim.reading())}
    if op == "run":
        if "columns" in request:
            return _run_columns(session, request)
        return _run_segments(session, request)
    if op == "set_joint_angles":
        sim = _need_sim(session)
        q = _vector(request, "q", "set_joint_angles", session.joints)
        bad = np.flatnonzero(~np.isfinite(q))
        if bad.size:
            i = int(bad[0])
            raise UsageError(f'joint "{session.names[i]}": angle {display(q[i])} is not finite')
        sim.set_joint_angles(q)
        return {"state": _reading_json(session, sim.reading())}
    if op == "get_state":
        sim = _need_sim(session)
        return _full_state_json(session, sim.full_state())
    if op == "set_state":
        sim = _need_sim(session)
        state = _parse_full_state(session, request)
        commands = None
        if request.get("commands") is not None:
            commands = _parse_commands(session, request["commands"])
        sim.set_full_state(state)
        if state.native is not None:
            session.kinds = None
        if commands is not None:
            _set_commands(session, sim, *commands)
        return {"state": _reading_json(session, sim.reading())}
    raise UsageError(f"unknown op {json.dumps(op)} (accepted: hello, check_settings, load, step, "
                     "run, set_joint_angles, get_state, set_state)")


def _run_segments(session: _Session, request: Mapping[str, Any]) -> dict:
    """The ``run`` request: segments in order, each ``{"read": bool,
    "commands": {...} or null, "steps": n}``: read the state first (when
    ``read``), then set the commands (when given), then step ``n`` times.
    The reply holds the readings taken and the reading at the end
    (``state``); a failure part-way ends the run there and comes back as
    ``error`` beside the readings taken before it (an unexpected exception
    as an ``unstable`` error)."""
    sim = _need_sim(session)
    segments = request.get("segments")
    if not isinstance(segments, list):
        raise UsageError("`segments` must be a list")
    readings: list[dict] = []
    try:
        for i, seg in enumerate(segments):
            if not isinstance(seg, (dict, Mapping)):  # dict first: the fast check
                raise UsageError(f"segment {i} is not a JSON object")
            n = seg.get("steps", 0)
            if not isinstance(n, int) or isinstance(n, bool) or n < 0:
                raise UsageError(f"segment {i}: `steps` must be a whole number >= 0, found {json.dumps(n)}")
            if seg.get("read"):
                readings.append(_reading_json(session, sim.reading()))
            if seg.get("commands") is not None:
                _set_commands(session, sim, *_parse_commands(session, seg["commands"]))
            if n:
                sim.step(n)
    except Exception as e:  # noqa: BLE001 - a failure while stepping is the run's end
        return {"readings": readings, "error": _run_error(session, e)}
    return {"readings": readings, "state": _reading_json(session, sim.reading())}


def _run_error(session: _Session, e: Exception) -> dict:
    """The `error` of a `run` that failed part-way: an engine error as it
    is (an instability at the last reading's time when it has none), any
    other exception as an instability, with its traceback on standard
    error."""
    if isinstance(e, EngineError):
        if isinstance(e, UnstableError) and e.t_s is None:
            e.t_s = session.last_t
        return e.reply()
    traceback.print_exc(file=sys.stderr)
    sys.stderr.flush()
    return UnstableError(f"{type(e).__name__}: {e}", session.last_t).reply()


def _set_commands(session: _Session, sim: Simulation, kinds: list[str], values: np.ndarray) -> None:
    sim.set_commands(kinds, values)
    session.kinds = kinds


def _int_list(raw: Any, what: str) -> np.ndarray:
    if not isinstance(raw, list) or not set(map(type, raw)) <= {int}:
        raise UsageError(f"`columns.{what}` must be a list of whole numbers")
    return np.asarray(raw, dtype=np.int64)


@dataclass
class _Columns:
    """A ``run`` schedule as columns: per segment ``steps`` and ``read``;
    per change of commands its segment (``at``, ascending), its kinds
    (``laws[law[c]]``) and its values (row ``c`` of ``values``)."""

    steps: np.ndarray
    read: np.ndarray
    at: np.ndarray
    laws: list[list[str]]
    law: np.ndarray
    values: np.ndarray


def _parse_columns(session: _Session, raw: Any) -> _Columns:
    if not isinstance(raw, Mapping):
        raise UsageError("`columns` must be a JSON object")
    steps = _int_list(raw.get("steps"), "steps")
    if steps.size and steps.min() < 0:
        raise UsageError(f"segment {int(np.argmax(steps < 0))}: `steps` must be >= 0")
    read_text = raw.get("read")
    if not isinstance(read_text, str) or len(read_text) != steps.size or read_text.strip("01"):
        raise UsageError(f"`columns.read` must be a text of {steps.size} digits 0 or 1, one per segment")
    read = np.frombuffer(read_text.encode("ascii"), dtype=np.uint8) == ord("1")
    at = _int_list(raw.get("at"), "at")
    if at.size and (at.min() < 0 or at.max() >= steps.size or np.any(np.diff(at) <= 0)):
        raise UsageError(f"`columns.at` must name segments (0 to {steps.size - 1}) in ascending order, each once")
    laws = raw.get("laws")
    if not isinstance(laws, list) or not all(
            isinstance(k, list) and len(k) == session.joints and all(isinstance(x, str) for x in k) for k in laws):
        raise UsageError(f"`columns.laws` must be a list of lists of {session.joints} command kinds")
    for kinds in laws:
        _check_kinds(session, kinds)
    law = _int_list(raw.get("law"), "law")
    if law.size != at.size or (law.size and (law.min() < 0 or law.max() >= len(laws))):
        raise UsageError(f"`columns.law` must give each of the {at.size} changes a law (0 to {len(laws) - 1})")
    values = _vector(raw, "values", "columns", at.size * session.joints).reshape(at.size, session.joints)
    if not np.isfinite(values).all():
        c, i = (int(x) for x in np.argwhere(~np.isfinite(values))[0])
        raise UsageError(f'segment {int(at[c])}: the {laws[law[c]][i]} command of joint "{_joint(session, i)}" '
                         f"is {display(values[c, i])}")
    return _Columns(steps, read, at, laws, law, values)


def _run_columns(session: _Session, request: Mapping[str, Any]) -> dict:
    """The ``run`` request in columns (``{"columns": {...}}``): the same
    schedule as ``segments``, its readings back as one vector of rows
    ``t, q, qd, poses``. Where the command kinds stay (a piece), an adapter
    with :meth:`Simulation.run_open_loop` takes the piece's steps in its own
    loop; else, or when it declines, segment by segment."""
    sim = _need_sim(session)
    cols = _parse_columns(session, request.get("columns"))
    width = 1 + 2 * session.joints + 7 * session.tracked
    out = np.empty((int(cols.read.sum()), width))
    count = 0
    native = type(sim).run_open_loop is not Simulation.run_open_loop
    change = np.full(cols.steps.size, -1, dtype=np.int64)
    change[cols.at] = np.arange(cols.at.size)
    # The pieces: from each segment whose change of commands changes the
    # kinds in force (unknown kinds: the first change), to the next.
    starts = [0]
    kinds = session.kinds
    for c, a in enumerate(cols.at.tolist()):
        law = cols.laws[cols.law[c]]
        if law != kinds:
            if a:
                starts.append(a)
            kinds = law
    starts.append(cols.steps.size)
    try:
        for a, b in zip(starts[:-1], starts[1:]):
            rows = None
            if native:
                cum = np.concatenate(((0,), np.cumsum(cols.steps[a:b])))
                total = int(cum[-1])
                if total:
                    c0 = change[a]
                    if c0 >= 0:
                        _set_commands(session, sim, cols.laws[cols.law[c0]], cols.values[c0])
                    inner = change[a + 1:b]
                    inner = inner[inner >= 0]
                    read_at = cum[:-1][cols.read[a:b]]
                    rows = sim.run_open_loop(total, cum[cols.at[inner] - a], cols.values[inner], read_at)
            if rows is None:
                for i in range(a, b):
                    if cols.read[i]:
                        out[count] = _reading_row(session, sim.reading())
                        count += 1
                    c = change[i]
                    if c >= 0:
                        _set_commands(session, sim, cols.laws[cols.law[c]], cols.values[c])
                    if cols.steps[i]:
                        sim.step(int(cols.steps[i]))
                continue
            rows = np.asarray(rows, dtype=np.float64)
            if rows.shape != (read_at.size, width):
                raise RuntimeError(f"the adapter's run_open_loop gave readings of shape {rows.shape}, "
                                   f"not {(read_at.size, width)}")
            if not np.isfinite(rows).all():
                k = int(np.flatnonzero(~np.isfinite(rows).all(axis=1))[0])
                out[count:count + k] = rows[:k]
                count += k
                _reading_row(session, _row_reading(session, rows[k]))  # raises, saying what
                raise AssertionError("a non-finite row passed the reading's check")
            out[count:count + rows.shape[0]] = rows
            count += rows.shape[0]
            if count:
                session.last_t = float(out[count - 1, 0])
    except Exception as e:  # noqa: BLE001 - a failure while stepping is the run's end
        return {"readings": bits(out[:count]), "error": _run_error(session, e)}
    return {"readings": bits(out[:count]), "state": _reading_json(session, sim.reading())}


def _checked_bits(x: float, what: str) -> str:
    if not math.isfinite(x):
        raise UsageError(f"the adapter gave a non-finite {what} ({display(x)})")
    return bits([x])


def _reject_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")


def _reply_for(session: _Session, op: Any, request: Any) -> dict:
    try:
        if not isinstance(request, Mapping):
            raise UsageError("a request must be a JSON object")
        return {"ok": _handle(session, request)}
    except EngineError as e:
        if isinstance(e, UnstableError) and e.t_s is None:
            e.t_s = session.last_t
        if op == "load":
            session.sim = None
        return {"error": e.reply()}
    except Exception as e:  # noqa: BLE001 - every failure becomes a reply
        traceback.print_exc(file=sys.stderr)
        sys.stderr.flush()
        text = f"{type(e).__name__}: {e}"
        if op == "load":
            session.sim = None
            return {"error": LoadError(text).reply()}
        if op == "step":
            return {"error": UnstableError(text, session.last_t).reply()}
        return {"error": UsageError(text).reply()}


def _zygote_listen(request: Mapping[str, Any], stdin, fd: int | None):
    """The ``zygote`` request: a listening socket at ``request["socket"]``
    and the reply, or no socket and an error reply (the process then goes
    on serving requests)."""
    import socket

    path = request.get("socket")
    if not isinstance(path, str) or not path:
        return None, {"error": UsageError("`socket` must be the path of a Unix socket").reply()}
    try:
        own_stdin = stdin.fileno() == 0
    except (AttributeError, OSError, ValueError):
        own_stdin = False
    if not own_stdin or fd != 1 or not hasattr(os, "fork") or not hasattr(os, "pidfd_open"):
        return None, {"error": UsageError("this process cannot fork engine children (a zygote needs "
                                          "its own standard input and output, fork and pidfd_open)").reply()}
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        listener.bind(path)
        listener.listen(64)
    except OSError as e:
        listener.close()
        return None, {"error": UsageError(f"cannot listen on {path}: {e}").reply()}
    return listener, {"ok": {"socket": path, "pid": os.getpid()}}


def _zygote_serve(adapter: Adapter, listener, path: str, private: list[int], saved_stdout) -> int:
    """The zygote's loop: for each connection, the child's standard
    input, output and error arrive as file descriptors (SCM_RIGHTS); a
    forked child takes them as its own, sends back its process id and a
    pidfd of itself (realitygap's handle to kill it), and serves the
    protocol; the zygote only forks. It ends when its standard input ends
    (the realitygap process that started it has exited), removing the
    socket."""
    import select
    import signal
    import socket

    # Forked children are reaped by the kernel: they are not this
    # process's to wait for.
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)
    try:
        while True:
            ready, _, _ = select.select([listener, 0], [], [])
            if 0 in ready and not os.read(0, 4096):
                return 0
            if listener not in ready:
                continue
            conn, _ = listener.accept()
            with conn:
                try:
                    _, fds, _, _ = socket.recv_fds(conn, 64, 3)
                except OSError:
                    continue
                if len(fds) != 3:
                    for f in fds:
                        os.close(f)
                    continue
                pid = os.fork()
                if pid == 0:
                    _forked_child(adapter, listener, conn, fds, private, saved_stdout)
                for f in fds:
                    os.close(f)
    finally:
        listener.close()
        try:
            os.unlink(path)
        except OSError:
            pass


def _forked_child(adapter: Adapter, listener, conn, fds: list[int], private: list[int], saved_stdout) -> None:
    """A zygote's child: takes ``fds`` as its standard input, output and
    error, answers the connection with its process id and pidfd, then
    serves the protocol until its input ends. Never returns."""
    import signal
    import socket

    code = 1
    try:
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
        listener.close()
        for f in private:
            os.close(f)
        for target, f in enumerate(fds):
            os.dup2(f, target)
        for f in fds:
            if f > 2:
                os.close(f)
        pidfd = os.pidfd_open(os.getpid())
        socket.send_fds(conn, [f"{os.getpid()}\n".encode()], [pidfd])
        os.close(pidfd)
        conn.close()
        sys.stdout = saved_stdout
        code = serve(adapter)
    except BaseException:  # noqa: BLE001 - the child ends here whatever happens
        traceback.print_exc(file=sys.stderr)
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:  # noqa: BLE001
                pass
        os._exit(code)


def _lines(stdin) -> Iterable[str]:
    buffer = getattr(stdin, "buffer", None)
    if buffer is not None:
        for raw in buffer:
            yield raw.decode("utf-8", errors="replace")
    else:
        for line in stdin:
            yield line


def serve(adapter: Adapter, stdin=None, stdout=None) -> int:
    """Answers requests until the end of ``stdin``, then returns 0.

    Reads one JSON request per line from ``stdin`` (default: ``sys.stdin``
    at the call), dispatches it to ``adapter`` and its simulation, and
    writes exactly one JSON reply line per request to ``stdout`` (default:
    ``sys.stdout`` at the call), flushed. Blank lines are skipped.

    - Errors: an :class:`EngineError` becomes ``{"error": {"kind",
      "message", ["key"], ["t_s"]}}`` of its kind; any other exception a
      ``load`` error during ``load``, an ``unstable`` error during ``step``,
      else a ``usage`` error, with its traceback on standard error.
    - Every number going out is checked: a non-finite reading or state is
      an ``unstable`` error naming what, never bits of a NaN.
    - Standard output belongs to the protocol: while serving, ``sys.stdout``
      is standard error (stray ``print`` calls), and when ``stdout`` is the
      process's file descriptor 1, that descriptor too (output of native
      libraries); the replies go to a private copy of it.
    - One simulation per process: a second ``load`` replaces the first
      (a failed ``load`` leaves none).
    """
    stdin = sys.stdin if stdin is None else stdin
    stdout = sys.stdout if stdout is None else stdout
    session = _Session(adapter)
    saved_sys_stdout = sys.stdout
    saved_fd1 = None
    try:
        fd = stdout.fileno()
    except (AttributeError, OSError, ValueError):
        fd = None
    if fd == 1:
        stdout.flush()
        private = os.dup(1)
        saved_fd1 = os.dup(1)
        os.dup2(2, 1)
        out = os.fdopen(private, "wb", buffering=0)

        def write(text: str) -> None:
            out.write(text.encode("utf-8"))
    else:
        out = None

        def write(text: str) -> None:
            stdout.write(text)
            stdout.flush()

    sys.stdout = sys.stderr
    # REALITYGAP_ENGINE_PROFILE=DIR: per operation, the requests answered
    # and the seconds spent answering them, in DIR/<pid>.json (where an
    # adapter's time goes), rewritten at most once a second and when the
    # input ends: a child that realitygap kills loses at most a second.
    profile_dir = os.environ.get("REALITYGAP_ENGINE_PROFILE")
    profile: dict[str, list] = {}
    profile_written = [time.monotonic()]

    def write_profile(force: bool) -> None:
        now = time.monotonic()
        if not profile_dir or not profile or (not force and now - profile_written[0] < 1.0):
            return
        profile_written[0] = now
        path = os.path.join(profile_dir, f"{os.getpid()}.json")
        os.makedirs(profile_dir, exist_ok=True)
        with open(path + ".tmp", "w", encoding="utf-8") as f:
            json.dump({"pid": os.getpid(), "adapter": session.adapter.name, "ops": profile}, f)
        os.replace(path + ".tmp", path)

    try:
        for line in _lines(stdin):
            if not line.strip():
                continue
            op = None
            started = time.perf_counter()
            try:
                request = json.loads(line, parse_constant=_reject_constant)
            except ValueError as e:
                reply = {"error": UsageError(f"a request line is not JSON: {e}").reply()}
            else:
                if isinstance(request, Mapping):
                    op = request.get("op")
                if op == "zygote":
                    listener, reply = _zygote_listen(request, stdin, fd)
                    write(json.dumps(reply, separators=(",", ":")) + "\n")
                    if listener is None:
                        continue
                    # From here on this process only forks the children
                    # (each served by serve() itself); its own input is
                    # watched for its end.
                    private = [out.fileno(), saved_fd1] if out is not None else []
                    return _zygote_serve(adapter, listener, request["socket"], private, saved_sys_stdout)
                reply = _reply_for(session, op, request)
            if profile_dir:
                entry = profile.setdefault(str(op), [0, 0.0])
                entry[0] += 1
                entry[1] += time.perf_counter() - started
                write_profile(False)
            try:
                text = json.dumps(reply, allow_nan=False, separators=(",", ":"))
            except ValueError as e:
                text = json.dumps({"error": UsageError(f"the reply holds a non-finite number: {e}").reply()})
            write(text + "\n")
            sys.stderr.flush()
    finally:
        write_profile(True)
        sys.stdout = saved_sys_stdout
        if saved_fd1 is not None:
            out.close()
            os.dup2(saved_fd1, 1)
            os.close(saved_fd1)
    return 0
