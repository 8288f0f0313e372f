"""The engine-adapter SDK (realitygap_engine) and its MuJoCo adapter.

``scripts/test-python`` runs it against the installed wheel, which ships
the SDK beside ``realitygap``. Run alone from the source tree, with the
dependencies' environment (numpy, mujoco, pytest), it falls back to the
source tree's copy:

    ~/.cache/realitygap/py-deps-venv/bin/python -m pytest python/tests/test_engine_sdk.py

The SDK is tested in process on in-memory streams with a toy adapter (a
point mass on one slide joint); the MuJoCo adapter as the child process
realitygap starts (``python -m realitygap_engine.adapters.mujoco``).
"""

import io
import json
import math
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

# The SDK's folder in the source tree (scripts/test-python runs a copy of
# the tests from a scratch folder, with REALITYGAP_ROOT set).
PYTHON_DIR = (Path(os.environ["REALITYGAP_ROOT"]) / "python" if os.environ.get("REALITYGAP_ROOT")
              else Path(__file__).resolve().parents[1])
try:
    import realitygap_engine as rge
except ImportError:  # not installed: the source tree's copy
    sys.path.insert(0, str(PYTHON_DIR))
    import realitygap_engine as rge  # noqa: E402


def child_env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(PYTHON_DIR) + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("REALITYGAP_ENGINE_NAME", None)
    return env


# --------------------------------------------------------------------------
# Bits


def test_the_sdk_ships_in_the_wheel_beside_realitygap():
    """``pip install realitygap`` gives an adapter's author the SDK, as
    ``realitygap_engine`` and as ``realitygap.engine``: the source tree's
    files (those the binary embeds for its children), adapters included."""
    if not os.environ.get("REALITYGAP_ROOT"):
        pytest.skip("run from the source tree, not by scripts/test-python: no wheel to check")
    installed = Path(rge.__file__).resolve().parent
    assert "site-packages" in installed.parts, installed
    assert PYTHON_DIR.resolve() not in installed.parents
    source = PYTHON_DIR / "realitygap_engine"
    ours = sorted(p.relative_to(source) for p in source.rglob("*.py"))
    assert ours == sorted(p.relative_to(installed) for p in installed.rglob("*.py"))
    for rel in ours:
        assert (installed / rel).read_bytes() == (source / rel).read_bytes(), rel
    import realitygap.engine as packaged

    assert packaged.Adapter is rge.Adapter and packaged.serve is rge.serve
    assert sorted(packaged.__all__) == sorted(rge.__all__)


def test_bits_round_trip_is_exact():
    values = [1.0, -0.0, 0.0, 5e-324, 2.2250738585072014e-308 / 3, 0.1 + 0.2, -1e-300,
              1.7976931348623157e308, math.pi, -2.5]
    text = rge.bits(values)
    assert text[:16] == "000000000000f03f"
    assert text[16:32] == "0000000000000080"  # -0.0: only the sign bit
    assert len(text) == 16 * len(values)
    back = rge.floats(text)
    assert back.dtype == np.float64 and back.flags.writeable
    for a, b in zip(values, back):
        assert np.float64(a).tobytes() == np.float64(b).tobytes(), (a, b)
    assert math.copysign(1.0, back[1]) == -1.0
    assert back[3] == 5e-324 and back[3] > 0  # the smallest subnormal
    assert rge.floats(text.upper()).tobytes() == back.tobytes()
    assert rge.bits(np.array([[1.0, 2.0], [3.0, 4.0]])) == rge.bits([1.0, 2.0, 3.0, 4.0])
    assert rge.bits(2.0) == rge.bits([2.0])
    assert rge.floats("").size == 0
    with pytest.raises(ValueError):
        rge.floats("00")
    with pytest.raises(ValueError):
        rge.floats("000000000000f03g")


def test_display_writes_numbers_as_rust_does():
    assert rge.display(1.0) == "1"
    assert rge.display(-1.0) == "-1"
    assert rge.display(1e-4) == "0.0001"
    assert rge.display(0.1 + 0.2) == "0.30000000000000004"
    assert rge.display(float("inf")) == "inf"


# --------------------------------------------------------------------------
# The SDK with a toy adapter


class PointMass(rge.Simulation):
    """One slide joint moving a point mass, explicit Euler, the servo laws
    of the protocol; object states held as given."""

    def __init__(self, model, dt):
        a = model["actuators"][0]
        self.kv, self.kp, self.limit = a["kv"], a["kp"], a["force_limit"]
        self.mass = model["bodies"][0]["mass_kg"]
        self.dt = dt
        self.t = 0.0
        self.q = 0.0
        self.qd = 0.0
        self.kind, self.value = "velocity", 0.0
        self.objects = [rge.ObjectState(o["name"], np.array(o["pose"], float),
                                        np.array(o["linear_velocity"], float),
                                        np.array(o["angular_velocity"], float))
                        for o in model["objects"]]
        self.fail_step = model.get("fail_step")
        self.poison = model.get("poison")
        self.noise = model.get("noise")

    def stability_issues(self):
        if self.kv * self.dt / self.mass >= 2:
            return [rge.StabilityIssue("x", "kv*dt/m", self.kv * self.dt / self.mass, 2.0, "too stiff")]
        return []

    def step(self, n):
        if self.noise:
            print("stray print from the adapter")
        if self.fail_step == "exception":
            raise RuntimeError("the toy engine broke")
        if self.fail_step == "unstable":
            raise rge.UnstableError("the toy engine blew up", self.t)
        for _ in range(n):
            if self.kind == "velocity":
                tau = self.kv * (self.value - self.qd)
            elif self.kind == "position":
                tau = self.kp * (self.value - self.q) - self.kv * self.qd
            else:
                tau = self.value
            if self.limit is not None:
                tau = min(max(tau, -self.limit), self.limit)
            self.qd += self.dt * tau / self.mass
            self.q += self.dt * self.qd
            self.t += self.dt
        if self.poison:
            self.qd = math.nan

    def reading(self):
        return rge.Reading(self.t, np.array([self.q]), np.array([self.qd]),
                           np.array([self.q, 0, 0, 1, 0, 0, 0], float))

    def set_commands(self, kinds, values):
        self.kind, self.value = kinds[0], float(values[0])

    def set_joint_angles(self, q):
        self.q, self.qd = float(q[0]), 0.0

    def full_state(self):
        native = np.array([self.t, self.q, self.qd, ["velocity", "position", "effort"].index(self.kind), self.value])
        return rge.FullState(self.t, np.array([self.q]), np.array([self.qd]), list(self.objects), native)

    def set_full_state(self, s):
        if s.native is not None:
            self.t, self.q, self.qd, k, self.value = s.native
            self.kind = ["velocity", "position", "effort"][int(k)]
        else:
            self.t, self.q, self.qd = s.t, float(s.q[0]), float(s.qd[0])
        self.objects = list(s.objects)


class Toy(rge.Adapter):
    name = "toy"
    default_timestep_s = 0.01
    settings = [rge.Setting("timestep_s", "integration timestep, s (> 0); default 0.01"),
                rge.Setting("iterations", "whole number >= 1")]
    params = [rge.Param("joints.*.armature", "added to the mass")]
    commands = {"velocity": "tau = kv (v - qd)", "position": "tau = kp (q* - q) - kv qd", "effort": "tau = value"}

    def version(self):
        return "Toy 1.0"

    def check_settings(self, settings):
        r = rge.SettingsReader(settings, self.settings)
        r.integer("iterations", 1, 100)
        dt = r.number("timestep_s", lambda v: math.isfinite(v) and v > 0, "> 0 s and finite")
        return self.default_timestep_s if dt is None else dt

    def load(self, model):
        dt = self.check_settings(model.get("settings", {}))
        if model.get("fail_load") == "exception":
            raise KeyError("no such thing")
        if model["bodies"][0]["shapes"]:
            raise rge.LoadError("the toy engine has no collision shapes")
        for joint in model["params"].get("armature", {}):
            raise rge.ParamError(f"joints.{joint}.armature", "the toy engine has no armature")
        return PointMass(model, dt)


def toy_model(**extra):
    model = {
        "settings": {"timestep_s": 0.01},
        "gravity": [0, 0, 0],
        "ground": None,
        "bodies": [{"name": "cart", "parent": -1, "pose": [0, 0, 0, 1, 0, 0, 0],
                    "joint": {"name": "x", "type": "slide", "axis": [1, 0, 0], "range": None,
                              "damping": 0.0, "frictionloss": 0.0},
                    "mass_kg": 2.0, "com": [0, 0, 0], "inertia": [0] * 9, "shapes": []}],
        "actuators": [{"joint": "x", "body": 0, "kv": 4.0, "kp": None, "force_limit": None}],
        "objects": [{"name": "cube", "shape": "box", "size": [0.1, 0.1, 0.1], "mass_kg": 1.0,
                     "inertia": [1e-3] * 3, "pose": [1, 0, 0.05, 1, 0, 0, 0],
                     "linear_velocity": [0, 0, 0], "angular_velocity": [0, 0, 0], "friction": None}],
        "tracked": [{"body": 0, "offset": [0, 0, 0, 1, 0, 0, 0]}],
        "friction_scale": 1.0,
        "params": {"armature": {}, "restitution": {}, "contact": {"time_constant_s": None, "damping_ratio": None}},
    }
    model.update(extra)
    return model


def serve_lines(requests, adapter=None):
    """Replies of serve() to `requests` (dicts, or raw text lines)."""
    lines = [r if isinstance(r, str) else json.dumps(r) for r in requests]
    out = io.StringIO()
    assert rge.serve(adapter or Toy(), io.StringIO("\n".join(lines) + "\n"), out) == 0
    text = out.getvalue()
    assert text.endswith("\n")
    replies = [json.loads(line) for line in text.splitlines()]
    assert len(replies) == len([x for x in lines if x.strip()]), text
    return replies


def ok(reply):
    assert "ok" in reply, reply
    return reply["ok"]


def err(reply, kind):
    assert "error" in reply, reply
    assert reply["error"]["kind"] == kind, reply
    return reply["error"]


def reading(r):
    return {k: rge.floats(v) for k, v in r["state"].items()}


def test_serve_answers_every_op(capsys):
    v = rge.bits([0.5])
    replies = serve_lines([
        {"op": "hello", "protocol": 1},
        {"op": "check_settings", "settings": {"timestep_s": 0.001, "timeout_s": 5}},
        {"op": "check_settings", "settings": {}},
        {"op": "load", "model": toy_model(noise=True)},
        {"op": "step", "n": 100, "commands": {"kinds": ["velocity"], "values": v}},
        {"op": "get_state"},
        {"op": "step", "n": 100},
        {"op": "set_joint_angles", "q": rge.bits([3.0])},
        "",
        {"op": "set_state", "t": rge.bits([0.25]), "q": rge.bits([1.0]), "qd": rge.bits([-1.0]),
         "objects": [{"name": "cube", "pose": rge.bits([2, 0, 0.05, 1, 0, 0, 0]), "v": rge.bits([0, 0, 0]),
                      "w": rge.bits([0, 0, 0])}], "native": None,
         "commands": {"kinds": ["effort"], "values": rge.bits([2.0])}},
        {"op": "step", "n": 1},
    ])
    hello = ok(replies[0])
    assert hello["protocol"] == 1 and hello["engine"] == "toy" and hello["version"] == "Toy 1.0"
    assert hello["default_timestep_s"] == 0.01
    assert hello["settings"][0] == {"key": "timestep_s", "help": "integration timestep, s (> 0); default 0.01"}
    assert hello["params"] == [{"key": "joints.*.armature", "mapping": "added to the mass"}]
    assert [c["kind"] for c in hello["commands"]] == ["velocity", "position", "effort"]
    assert rge.floats(ok(replies[1])["timestep_s"])[0] == 0.001  # timeout_s is realitygap's
    assert rge.floats(ok(replies[2])["timestep_s"])[0] == 0.01

    loaded = ok(replies[3])
    assert loaded["stability_issues"] == []
    r = reading(loaded)
    assert r["t"][0] == 0 and r["q"][0] == 0 and r["poses"].tolist() == [0, 0, 0, 1, 0, 0, 0]

    # 100 steps of 0.01 s towards 0.5 m/s with kv/m = 2/s (explicit Euler).
    r = reading(ok(replies[4]))
    assert r["t"][0] == pytest.approx(1.0)
    assert r["qd"][0] == pytest.approx(0.5 * (1 - 0.98**100), abs=1e-12)
    state = ok(replies[5])
    assert rge.floats(state["t"])[0] == r["t"][0]
    assert state["objects"][0]["name"] == "cube"
    assert rge.floats(state["objects"][0]["pose"]).tolist() == [1, 0, 0.05, 1, 0, 0, 0]
    assert rge.floats(state["native"]).size == 5
    # The velocity command holds over the next step without commands.
    assert reading(ok(replies[6]))["qd"][0] == pytest.approx(0.5 * (1 - 0.98**200), abs=1e-12)
    r = reading(ok(replies[7]))
    assert r["q"][0] == 3.0 and r["qd"][0] == 0.0
    r = reading(ok(replies[8]))
    assert r["t"][0] == 0.25 and r["q"][0] == 1.0 and r["qd"][0] == -1.0
    r = reading(ok(replies[9]))  # effort 2 N on 2 kg: +0.01 m/s
    assert r["qd"][0] == pytest.approx(-0.99, abs=1e-12)

    captured = capsys.readouterr()
    assert "stray print from the adapter" in captured.err


def test_profile_counts_and_times_each_operation(tmp_path, monkeypatch):
    """REALITYGAP_ENGINE_PROFILE=DIR: DIR/<pid>.json, per operation the
    requests answered (refused ones too) and their seconds; a second
    serve() in the same process rewrites it."""
    profile = tmp_path / "profile"
    monkeypatch.setenv("REALITYGAP_ENGINE_PROFILE", str(profile))
    serve_lines([{"op": "hello", "protocol": 1}, {"op": "load", "model": toy_model()},
                 {"op": "step", "n": 3}, {"op": "step", "n": 2}, {"op": "nonsense"}, "not json"])
    written = json.loads((profile / ("%d.json" % os.getpid())).read_text())
    assert written["pid"] == os.getpid() and written["adapter"] == "toy"
    ops = written["ops"]
    assert {k: v[0] for k, v in ops.items()} == {"hello": 1, "load": 1, "step": 2, "nonsense": 1, "None": 1}
    assert all(v[1] >= 0 for v in ops.values())
    serve_lines([{"op": "hello", "protocol": 1}])
    assert json.loads((profile / ("%d.json" % os.getpid())).read_text())["ops"] == {"hello": [1, pytest.approx(0, abs=1)]}
    assert [p.name for p in profile.iterdir()] == ["%d.json" % os.getpid()]
    monkeypatch.delenv("REALITYGAP_ENGINE_PROFILE")
    (profile / ("%d.json" % os.getpid())).unlink()
    serve_lines([{"op": "hello", "protocol": 1}])
    assert list(profile.iterdir()) == []


def test_native_state_round_trips_through_serve():
    model = toy_model()
    replies = serve_lines([
        {"op": "load", "model": model},
        {"op": "step", "n": 10, "commands": {"kinds": ["effort"], "values": rge.bits([1.0])}},
        {"op": "get_state"},
    ])
    state = ok(replies[2])
    request = {"op": "set_state", **state}
    again = serve_lines([
        {"op": "load", "model": model},
        request,
        {"op": "step", "n": 10},
    ])
    first = serve_lines([
        {"op": "load", "model": model},
        {"op": "step", "n": 10, "commands": {"kinds": ["effort"], "values": rge.bits([1.0])}},
        {"op": "step", "n": 10},
    ])
    assert ok(again[2]) == ok(first[2])  # the effort command came back with the native state


def test_error_kinds(capsys):
    replies = serve_lines([
        {"op": "step", "n": 1},                                               # 0 usage: nothing loaded
        {"op": "hello", "protocol": 2},                                       # 1 usage
        {"op": "check_settings", "settings": {"bogus": 1}},                   # 2 setting
        {"op": "check_settings", "settings": {"timestep_s": -1}},             # 3 setting
        {"op": "check_settings", "settings": {"iterations": 2.5}},            # 4 setting
        {"op": "check_settings", "settings": {"timestep_s": "fast"}},         # 5 setting
        {"op": "load", "model": toy_model(bodies=[dict(toy_model()["bodies"][0], shapes=[{"type": "box"}])])},  # 6 load
        {"op": "load", "model": toy_model(params={"armature": {"x": 0.1}})},  # 7 param
        {"op": "load", "model": toy_model(fail_load="exception")},            # 8 load (unexpected)
        {"op": "load", "model": toy_model()},                                 # 9 ok
        "this is not json",                                                   # 10 usage
        {"op": "fly"},                                                        # 11 usage
        {"op": "set_joint_angles", "q": rge.bits([1.0, 2.0])},                # 12 usage: length
        {"op": "set_joint_angles", "q": rge.bits([math.nan])},                # 13 usage: not finite
        {"op": "step", "n": 0},                                               # 14 usage
        {"op": "step", "n": 1, "commands": {"kinds": ["position"], "values": rge.bits([1.0])}},  # 15 usage: no kp
        {"op": "step", "n": 1, "commands": {"kinds": ["torque"], "values": rge.bits([1.0])}},    # 16 usage
        {"op": "set_state", "t": rge.bits([0.0]), "q": rge.bits([0.0]), "qd": rge.bits([0.0]),
         "objects": [], "native": None},                                      # 17 state: objects
        {"op": "set_state", "t": rge.bits([-1.0]), "q": rge.bits([0.0]), "qd": rge.bits([0.0]),
         "objects": [], "native": None},                                      # 18 state: time
        {"op": "load", "model": toy_model(fail_step="exception")},            # 19 ok
        {"op": "step", "n": 1},                                               # 20 unstable (unexpected)
        {"op": "load", "model": toy_model(fail_step="unstable")},             # 21 ok
        {"op": "step", "n": 1},                                               # 22 unstable
    ])
    assert "no model is loaded" in err(replies[0], "usage")["message"]
    assert "protocol 2" in err(replies[1], "usage")["message"]
    e = err(replies[2], "setting")
    assert e["key"] == "bogus" and e["message"] == "unknown setting (accepted: timestep_s, iterations)"
    e = err(replies[3], "setting")
    assert e["key"] == "timestep_s" and e["message"] == "must be > 0 s and finite, found -1"
    assert err(replies[4], "setting")["message"] == 'expected a whole number, found "2.5"'
    assert err(replies[5], "setting")["message"] == 'expected a number, found "fast"'
    assert "no collision shapes" in err(replies[6], "load")["message"]
    e = err(replies[7], "param")
    assert e["key"] == "joints.x.armature"
    assert "KeyError" in err(replies[8], "load")["message"]
    ok(replies[9])
    assert "not JSON" in err(replies[10], "usage")["message"]
    assert "unknown op" in err(replies[11], "usage")["message"]
    assert "2 values" in err(replies[12], "usage")["message"]
    assert "not finite" in err(replies[13], "usage")["message"]
    err(replies[14], "usage")
    assert "no position gain" in err(replies[15], "usage")["message"]
    assert "unknown command kind" in err(replies[16], "usage")["message"]
    assert "objects" in err(replies[17], "state")["message"]
    assert "time" in err(replies[18], "state")["message"]
    ok(replies[19])
    e = err(replies[20], "unstable")
    assert "the toy engine broke" in e["message"] and e["t_s"] == 0.0
    e = err(replies[22], "unstable")
    assert e["message"] == "the toy engine blew up" and e["t_s"] == 0.0
    stderr = capsys.readouterr().err
    assert "Traceback" in stderr and "KeyError" in stderr and "RuntimeError: the toy engine broke" in stderr


def test_a_nan_reading_is_an_unstable_error():
    replies = serve_lines([
        {"op": "load", "model": toy_model(poison=True)},
        {"op": "step", "n": 2},
    ])
    ok(replies[0])
    e = err(replies[1], "unstable")
    assert e["message"] == 'non-finite joint velocity of joint "x" (NaN) at t = 0.02 s', e
    assert e["t_s"] == 0.02
    # A huge effort on a tiny mass overflows to inf.
    replies = serve_lines([
        {"op": "load", "model": toy_model(bodies=[dict(toy_model()["bodies"][0], mass_kg=1e-300)])},
        {"op": "step", "n": 3, "commands": {"kinds": ["effort"], "values": rge.bits([1e300])}},
        {"op": "get_state"},
    ])
    ok(replies[0])
    e = err(replies[1], "unstable")
    assert e["message"].startswith('non-finite joint angle of joint "x" (inf) at t = 0.03'), e
    assert e["t_s"] == pytest.approx(0.03)
    e = err(replies[2], "unstable")
    assert "non-finite joint angle" in e["message"]
    for r in replies[1:]:
        assert "ok" not in r


def test_stability_issues_are_reported():
    replies = serve_lines([{"op": "load", "model": toy_model(settings={"timestep_s": 1.0})}])
    issues = ok(replies[0])["stability_issues"]
    assert issues == [{"joint": "x", "quantity": "kv*dt/m", "value": 2.0, "bound": 2.0, "message": "too stiff"}]


# A replay's schedule: segments (read first, then commands, then steps),
# with laws that change, reads at the end and segments without steps.
SCHEDULE = [
    {"read": True, "steps": 3},
    {"read": True, "commands": {"kinds": ["velocity"], "values": rge.bits([0.5])}, "steps": 4},
    {"read": False, "commands": {"kinds": ["velocity"], "values": rge.bits([-0.25])}, "steps": 2},
    {"read": True, "steps": 0},
    {"read": True, "commands": {"kinds": ["position"], "values": rge.bits([0.1])}, "steps": 5},
    {"read": False, "commands": {"kinds": ["position"], "values": rge.bits([0.2])}, "steps": 0},
    {"read": True, "commands": {"kinds": ["position"], "values": rge.bits([0.3])}, "steps": 6},
    {"read": True, "commands": {"kinds": ["effort"], "values": rge.bits([1.5])}, "steps": 2},
    {"read": True, "commands": {"kinds": ["effort"], "values": rge.bits([-1.0])}, "steps": 0},
]


def as_columns(segments):
    """The same schedule in columns (docs/engine-protocol.md)."""
    laws, law, at, values = [], [], [], ""
    for i, s in enumerate(segments):
        c = s.get("commands")
        if c is not None:
            if c["kinds"] not in laws:
                laws.append(c["kinds"])
            law.append(laws.index(c["kinds"]))
            at.append(i)
            values += c["values"]
    return {"steps": [s["steps"] for s in segments], "read": "".join("1" if s["read"] else "0" for s in segments),
            "at": at, "laws": laws, "law": law, "values": values}


def rows_of(reply):
    """A `run` reply's readings as rows t, q, qd, poses (either form)."""
    if isinstance(reply["readings"], str):
        return rge.floats(reply["readings"]).reshape(-1, 10).tolist()
    return [np.concatenate([rge.floats(r[k]) for k in ("t", "q", "qd", "poses")]).tolist() for r in reply["readings"]]


def kp_model(**extra):
    return toy_model(actuators=[{"joint": "x", "body": 0, "kv": 4.0, "kp": 3.0, "force_limit": None}], **extra)


class OwnLoop(PointMass):
    """The point mass with run_open_loop: its own loop over a piece's
    steps, the calls recorded (or declined, or poisoned at a step)."""

    calls: list = []
    decline = False
    poison_at = None

    def run_open_loop(self, steps, change_at, values, read_at):
        OwnLoop.calls.append((self.kind, steps, list(change_at), list(read_at)))
        if OwnLoop.decline:
            return None
        rows, c = [], 0
        for k in range(steps + 1):
            while c < len(change_at) and change_at[c] == k:
                self.value = float(values[c][0])
                c += 1
            for _ in range(list(read_at).count(k)):
                r = self.reading()
                rows.append(np.concatenate(([r.t], r.q, r.qd, r.poses)))
            if k < steps:
                self.step(1)
                if OwnLoop.poison_at is not None and k + 1 == OwnLoop.poison_at:
                    self.qd = math.nan
        return np.array(rows).reshape(len(read_at), 10)


class OwnLoopToy(Toy):
    def load(self, model):
        sim = super().load(model)
        own = OwnLoop.__new__(OwnLoop)
        own.__dict__.update(sim.__dict__)
        return own


def test_run_in_columns_gives_the_segments_readings():
    """The schedule in columns, served segment by segment (an adapter
    without run_open_loop) and through run_open_loop in pieces where the
    laws stay: the same numbers as in segments, the readings as one
    vector."""
    segments = serve_lines([{"op": "load", "model": kp_model()}, {"op": "run", "segments": SCHEDULE}])
    want = ok(segments[1])
    assert len(want["readings"]) == 7
    hello, _, columns = serve_lines([{"op": "hello", "protocol": 1}, {"op": "load", "model": kp_model()},
                                     {"op": "run", "columns": as_columns(SCHEDULE)}])
    assert ok(hello)["columns"] is True
    got = ok(columns)
    assert rows_of(got) == rows_of(want) and got["state"] == want["state"]
    OwnLoop.calls, OwnLoop.decline, OwnLoop.poison_at = [], False, None
    _, own = serve_lines([{"op": "load", "model": kp_model()}, {"op": "run", "columns": as_columns(SCHEDULE)}],
                         OwnLoopToy())
    assert rows_of(ok(own)) == rows_of(want) and ok(own)["state"] == want["state"]
    # One piece per law: velocity (its first change after the first
    # segment's read at step 3, the second at 7, a read at 9), position
    # (two changes at step 5, the later holding), effort (a change at
    # the end, holding after the run).
    assert OwnLoop.calls == [
        ("velocity", 9, [3, 7], [0, 3, 9]),
        ("position", 11, [5, 5], [0, 5]),
        ("effort", 2, [2], [0, 2]),
    ], OwnLoop.calls
    # Declined: served segment by segment, the same numbers.
    OwnLoop.calls, OwnLoop.decline = [], True
    _, declined = serve_lines([{"op": "load", "model": kp_model()},
                               {"op": "run", "columns": as_columns(SCHEDULE)}], OwnLoopToy())
    assert rows_of(ok(declined)) == rows_of(want) and len(OwnLoop.calls) == 3


def test_a_failure_in_columns_keeps_the_readings_before_it():
    # A non-finite reading from run_open_loop: the rows before it, and the
    # reason, as segment by segment.
    OwnLoop.calls, OwnLoop.decline, OwnLoop.poison_at = [], False, 6
    _, own = serve_lines([{"op": "load", "model": kp_model()}, {"op": "run", "columns": as_columns(SCHEDULE)}],
                         OwnLoopToy())
    got = ok(own)
    assert len(rows_of(got)) == 2 and "state" not in got
    assert got["error"]["kind"] == "unstable"
    assert got["error"]["message"] == 'non-finite joint angle of joint "x" (NaN) at t = 0.09 s'
    # An engine failing while stepping, segment by segment.
    _, failed = serve_lines([{"op": "load", "model": kp_model(fail_step="unstable")},
                             {"op": "run", "columns": as_columns(SCHEDULE)}])
    got = ok(failed)
    assert len(rows_of(got)) == 1 and got["error"]["message"] == "the toy engine blew up"


@pytest.mark.parametrize("change, message", [
    ({"steps": [1, -2]}, "segment 1: `steps` must be >= 0"),
    ({"steps": [1, True]}, "`columns.steps` must be a list of whole numbers"),
    ({"read": "12"}, "`columns.read` must be a text of 2 digits 0 or 1, one per segment"),
    ({"read": "1"}, "`columns.read` must be a text of 2 digits 0 or 1"),
    ({"at": [1, 1]}, "`columns.at` must name segments (0 to 1) in ascending order, each once"),
    ({"at": [2]}, "`columns.at` must name segments (0 to 1)"),
    ({"law": [1]}, "`columns.law` must give each of the 1 changes a law (0 to 0)"),
    ({"laws": [["sideways"]]}, 'joint "x": unknown command kind "sideways"'),
    ({"laws": [["position"]]}, 'joint "x" takes a position command but its actuator has no position gain'),
    ({"laws": [["velocity", "velocity"]]}, "`columns.laws` must be a list of lists of 1 command kinds"),
    ({"values": rge.bits([math.nan])}, 'segment 0: the velocity command of joint "x" is NaN'),
    ({"values": rge.bits([1.0, 2.0])}, "columns: `values` has 2 values, the model 1"),
    ({"values": "zz"}, "columns: `values` is not a bits vector"),
])
def test_bad_columns_are_usage_errors(change, message):
    columns = {"steps": [1, 2], "read": "10", "at": [0], "laws": [["velocity"]], "law": [0],
               "values": rge.bits([1.0])}
    columns.update(change)
    _, reply = serve_lines([{"op": "load", "model": toy_model()}, {"op": "run", "columns": columns}])
    assert message in err(reply, "usage")["message"], reply


def test_native_output_goes_to_stderr_in_a_child_process():
    """Writes to file descriptor 1 (as a C library's printf) and print()
    never reach the protocol's standard output."""
    script = textwrap.dedent("""
        import os, sys
        sys.path.insert(0, %r)
        import realitygap_engine as rge

        class Noisy(rge.Adapter):
            name = "noisy"
            def version(self):
                os.write(1, b"native noise\\n")
                print("python noise")
                return "Noisy 0"

        rge.serve(Noisy())
    """) % str(PYTHON_DIR)
    p = subprocess.run([sys.executable, "-c", script], input='{"op": "hello", "protocol": 1}\n',
                       capture_output=True, text=True, timeout=30)
    assert p.returncode == 0, p.stderr
    lines = p.stdout.splitlines()
    assert len(lines) == 1 and json.loads(lines[0])["ok"]["version"] == "Noisy 0"
    assert "native noise" in p.stderr and "python noise" in p.stderr


def test_a_zygote_forks_children_that_serve_the_protocol(tmp_path):
    """The `zygote` request as realitygap sends it: the process listens on
    a Unix socket; each connection brings a child's standard input, output
    and error (SCM_RIGHTS) and gets back the forked child's process id and
    pidfd; each child serves the protocol on those pipes (stray output to
    its own standard error), is killed through its pidfd, and the zygote
    ends with its input, removing the socket."""
    import signal
    import socket

    script = textwrap.dedent("""
        import os, sys
        sys.path.insert(0, %r)
        import realitygap_engine as rge

        class Forks(rge.Adapter):
            name = "forks"
            def version(self):
                print("python noise")
                return "Forks %%d" %% os.getpid()

        sys.exit(rge.serve(Forks()))
    """) % str(PYTHON_DIR)
    zygote = subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    path = str(tmp_path / "z.sock")
    zygote.stdin.write(json.dumps({"op": "zygote", "socket": path}) + "\n")
    zygote.stdin.flush()
    assert ok(json.loads(zygote.stdout.readline())) == {"socket": path, "pid": zygote.pid}

    def fork():
        pipes = [os.pipe() for _ in range(3)]
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as conn:
            conn.connect(path)
            socket.send_fds(conn, [b"fork\n"], [pipes[0][0], pipes[1][1], pipes[2][1]])
            for fd in (pipes[0][0], pipes[1][1], pipes[2][1]):
                os.close(fd)
            text, fds, _, _ = socket.recv_fds(conn, 64, 1)
        assert len(fds) == 1, text
        return int(text), fds[0], os.fdopen(pipes[0][1], "w"), os.fdopen(pipes[1][0]), os.fdopen(pipes[2][0])

    children = [fork() for _ in range(2)]
    pids = [c[0] for c in children]
    assert len({zygote.pid, *pids}) == 3
    for pid, _, stdin, stdout, _ in children:
        stdin.write(json.dumps({"op": "hello", "protocol": 1}) + "\n")
        stdin.flush()
        assert ok(json.loads(stdout.readline()))["version"] == f"Forks {pid}"
    # A child ends with its input, and dies by its pidfd.
    pid, pidfd, stdin, stdout, stderr = children[0]
    stdin.close()
    assert stdout.read() == "" and "python noise" in stderr.read()
    pid, pidfd, stdin, stdout, stderr = children[1]
    signal.pidfd_send_signal(pidfd, signal.SIGKILL)
    assert stdout.read() == ""
    stdin.close()
    assert zygote.poll() is None
    zygote.stdin.close()
    assert zygote.wait(timeout=30) == 0, zygote.stderr.read()
    assert not os.path.exists(path)
    # serve() over files that are not the process's own cannot fork.
    reply, = serve_lines([{"op": "zygote", "socket": str(tmp_path / "y.sock")}])
    assert "cannot fork" in err(reply, "usage")["message"]


# --------------------------------------------------------------------------
# The MuJoCo adapter as a child process


class Child:
    """The MuJoCo adapter as realitygap runs it."""

    def __init__(self, python=sys.executable):
        self.p = subprocess.Popen([python, "-m", "realitygap_engine.adapters.mujoco"],
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                  text=True, env=child_env(), cwd=PYTHON_DIR.parent)

    def call(self, request):
        self.p.stdin.write(json.dumps(request) + "\n")
        self.p.stdin.flush()
        line = self.p.stdout.readline()
        assert line, f"the child ended: {self.p.stderr.read()}"
        return json.loads(line)

    def ok(self, request):
        reply = self.call(request)
        assert "ok" in reply, (request.get("op"), reply)
        return reply["ok"]

    def close(self):
        self.p.stdin.close()
        rc = self.p.wait(timeout=30)
        self.p.stdout.close()
        self.p.stderr.close()
        return rc


@pytest.fixture
def child():
    c = Child()
    yield c
    assert c.close() == 0


IDENTITY = [0, 0, 0, 1, 0, 0, 0]


def quat_about(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return [math.cos(angle / 2), *(math.sin(angle / 2) * axis)]


def rotation(q):
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def pendulum(kv=0.1, force_limit=10.0, gravity=(0, 0, 0), com=(0, 0, 0), settings=None, armature=0.005,
             objects=(), ground=None, kp=20.0):
    """One link on a hinge about y, 0.5 m above the world, inertia 0.005
    about its centre of mass (plus the armature)."""
    return {
        "settings": settings or {"timestep_s": 1e-4},
        "gravity": list(gravity),
        "ground": ground,
        "bodies": [
            {"name": "base", "parent": -1, "pose": [0, 0, 0.5, 1, 0, 0, 0], "joint": None,
             "mass_kg": 1.0, "com": [0, 0, 0], "inertia": [0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01],
             "shapes": [{"type": "box", "pose": IDENTITY, "size": [0.1, 0.1, 0.1]}]},
            {"name": "link", "parent": 0, "pose": [0, 0, 0.1, 1, 0, 0, 0],
             "joint": {"name": "j1", "type": "hinge", "axis": [0, 1, 0], "range": None,
                       "damping": 0.0, "frictionloss": 0.0},
             "mass_kg": 1.0, "com": list(com), "inertia": [0.005, 0, 0, 0, 0.005, 0, 0, 0, 0.005],
             "shapes": [{"type": "capsule", "pose": [0, 0, 0.1, 1, 0, 0, 0], "radius": 0.02, "length": 0.2}]},
        ],
        "actuators": [{"joint": "j1", "body": 1, "kv": kv, "kp": kp, "force_limit": force_limit}],
        "objects": list(objects),
        "tracked": [{"body": 1, "offset": [0, 0, 0.2, 1, 0, 0, 0]}],
        "friction_scale": 1.0,
        "params": {"armature": {"j1": armature} if armature else {}, "restitution": {},
                   "contact": {"time_constant_s": None, "damping_ratio": None}},
    }


def cube(name="cube", pose=(0, 0, 0.3, 1, 0, 0, 0), v=(0, 0, 0), w=(0, 0, 0), size=0.1, mass=0.5):
    i = mass * size * size / 6
    return {"name": name, "shape": "box", "size": [size] * 3, "mass_kg": mass, "inertia": [i] * 3,
            "pose": list(pose), "linear_velocity": list(v), "angular_velocity": list(w), "friction": None}


def test_hello_settings_and_params_errors(child):
    hello = child.ok({"op": "hello", "protocol": 1})
    assert hello["engine"] == "mujoco4"
    import importlib.metadata

    import mujoco
    try:
        importlib.metadata.version("mujoco-core")
        dist = "mujoco-core"
    except importlib.metadata.PackageNotFoundError:
        dist = "mujoco"
    assert hello["version"] == f"MuJoCo {mujoco.__version__} (Python, {dist})"
    assert hello["default_timestep_s"] == 0.002
    assert [s["key"] for s in hello["settings"]] == [
        "timestep_s", "integrator", "solver", "iterations", "tolerance", "cone", "impratio",
        "noslip_iterations", "self_collision"]
    assert [p["key"] for p in hello["params"]] == [
        "joints.*.armature", "objects.*.restitution", "contact.time_constant_s", "contact.damping_ratio"]
    assert rge.floats(child.ok({"op": "check_settings", "settings": {
        "timestep_s": 1e-4, "integrator": "RK4", "solver": "pgs", "iterations": 50, "cone": "elliptic",
        "impratio": 10, "noslip_iterations": 0, "tolerance": 0.0, "self_collision": False}})["timestep_s"])[0] == 1e-4
    for settings, key, message in [
        ({"timestep_s": 0.0}, "timestep_s", "must be > 0 s and finite, found 0"),
        ({"integrator": "verlet"}, "integrator", '"verlet" is not one of euler, rk4, implicit, implicitfast'),
        ({"iterations": 2.5}, "iterations", 'expected a whole number, found "2.5"'),
        ({"iterations": 0}, "iterations", "must be a whole number from 1 to 2147483647, found 0"),
        ({"self_collision": "no"}, "self_collision", 'expected true or false, found "no"'),
        ({"gravity": 1.0}, "gravity", "unknown setting (accepted: timestep_s, integrator"),
    ]:
        e = child.call({"op": "check_settings", "settings": settings})["error"]
        assert e["kind"] == "setting" and e["key"] == key and e["message"].startswith(message), e
    # Engine-mapped parameters out of range; a shape the adapter lacks.
    model = pendulum(objects=[cube()])
    model["params"]["restitution"] = {"cube": 1.0}
    e = child.call({"op": "load", "model": model})["error"]
    assert e["kind"] == "param" and e["key"] == "objects.cube.restitution", e
    model = pendulum()
    model["params"]["contact"]["time_constant_s"] = 1e-4
    e = child.call({"op": "load", "model": model})["error"]
    assert e["kind"] == "param" and e["key"] == "contact.time_constant_s" and "below two timesteps" in e["message"]
    model = pendulum()
    model["params"]["armature"] = {"nope": 0.1}
    e = child.call({"op": "load", "model": model})["error"]
    assert e["kind"] == "param" and e["key"] == "joints.nope.armature"
    model = pendulum()
    model["bodies"][1]["shapes"] = [{"type": "cone", "pose": IDENTITY}]
    assert child.call({"op": "load", "model": model})["error"]["kind"] == "load"
    # A massless moving body: MuJoCo's own refusal.
    model = pendulum()
    model["bodies"][1].update(mass_kg=0.0, inertia=[0] * 9)
    e = child.call({"op": "load", "model": model})["error"]
    assert e["kind"] == "load" and "mass" in e["message"], e
    e = child.call({"op": "step", "n": 1})["error"]
    assert e["kind"] == "usage"  # the failed load left no simulation


def test_velocity_servo_reaches_its_target_as_a_first_order_system(child):
    # I dw/dt = kv (v - w): w = v (1 - exp(-t kv / I)), I = 0.005 + armature 0.005.
    kv, inertia, v = 0.1, 0.01, 2.0
    tau = inertia / kv
    loaded = child.ok({"op": "load", "model": pendulum(kv=kv)})
    assert loaded["stability_issues"] == []
    r = reading(loaded)
    assert r["t"][0] == 0 and r["q"][0] == 0 and r["qd"][0] == 0
    assert np.allclose(r["poses"], [0, 0, 0.8, 1, 0, 0, 0], atol=1e-15)
    commands = {"kinds": ["velocity"], "values": rge.bits([v])}
    worst = 0.0
    for k in range(100):
        r = reading(child.ok({"op": "step", "n": 100, **({"commands": commands} if k == 0 else {})}))
        t = r["t"][0]
        worst = max(worst, abs(r["qd"][0] - v * (1 - math.exp(-t / tau))))
        assert abs(r["q"][0] - v * (t - tau * (1 - math.exp(-t / tau)))) < 1e-3
    assert r["t"][0] == pytest.approx(1.0)
    # Euler integrates the servo explicitly: kv dt / I = 1e-3 per step.
    assert worst < 5e-4, worst
    assert abs(r["qd"][0] - v) < 1e-3
    # The tracked frame 0.2 m along the link's z, rotated about y by q.
    q = r["q"][0]
    assert np.allclose(r["poses"][:3], [0.2 * math.sin(q), 0, 0.6 + 0.2 * math.cos(q)], atol=1e-12)
    assert np.allclose(r["poses"][3:], quat_about([0, 1, 0], q) if math.cos(q / 2) > 0
                       else -np.array(quat_about([0, 1, 0], q)), atol=1e-9)

    # Effort: I dw/dt = tau exactly (Euler, no damping).
    w0 = r["qd"][0]
    r = reading(child.ok({"op": "step", "n": 1000, "commands": {"kinds": ["effort"], "values": rge.bits([0.05])}}))
    assert r["qd"][0] == pytest.approx(w0 + 0.05 / inertia * 0.1, abs=1e-9)
    # Position: the PD servo settles at its target.
    r = reading(child.ok({"op": "step", "n": 40000, "commands": {"kinds": ["position"], "values": rge.bits([1.0])}}))
    assert abs(r["q"][0] - 1.0) < 1e-6 and abs(r["qd"][0]) < 1e-6


def test_a_link_never_touches_its_parent(child):
    # At q = 2.8 the link's capsule cuts into the base's box (welded to the
    # world, so MuJoCo's own parent filter does not apply): excluded,
    # nothing pushes it.
    child.ok({"op": "load", "model": pendulum()})
    child.ok({"op": "set_joint_angles", "q": rge.bits([2.8])})
    r = reading(child.ok({"op": "step", "n": 100}))
    assert r["q"][0] == 2.8 and r["qd"][0] == 0.0


def test_zero_force_limit_turns_the_servo_off(child):
    child.ok({"op": "load", "model": pendulum(force_limit=0.0)})
    r = reading(child.ok({"op": "step", "n": 100, "commands": {"kinds": ["velocity"], "values": rge.bits([2.0])}}))
    assert r["qd"][0] == 0.0 and r["q"][0] == 0.0


def test_a_dropped_box_comes_to_rest_on_a_face(child):
    drop = cube(pose=[0.5, 0, 0.3, *quat_about([1, 0.3, 0], 0.4)], w=[0, 0, 1.0])
    model = pendulum(gravity=[0, 0, -9.81], objects=[drop], ground={"height_m": 0.0, "friction": None},
                     settings={"timestep_s": 0.002})
    model["tracked"].append({"object": 0})
    child.ok({"op": "load", "model": model})
    for _ in range(40):
        r = reading(child.ok({"op": "step", "n": 50}))
    assert r["t"][0] == pytest.approx(4.0)
    pose = r["poses"][7:]
    assert abs(pose[2] - 0.05) < 1e-3, pose
    up = np.abs(rotation(pose[3:]).T @ [0, 0, 1])  # the world's up in the box's axes
    assert up.max() > 1 - 1e-4, up
    s = child.ok({"op": "get_state"})
    o = s["objects"][0]
    assert np.linalg.norm(rge.floats(o["v"])) < 1e-3 and np.linalg.norm(rge.floats(o["w"])) < 1e-2
    assert np.allclose(rge.floats(o["pose"]), pose, atol=1e-12)


def test_free_flight_follows_the_parabola(child):
    # RK4 integrates a constant acceleration exactly.
    q0 = quat_about([1, 2, 3], 0.7)
    x0, v0, w0 = np.array([0.1, -0.2, 1.0]), np.array([1.0, 0.5, 3.0]), np.array([0.3, -0.2, 1.0])
    g = np.array([0, 0, -9.81])
    flying = cube(pose=[*x0, *q0], v=v0, w=w0)
    model = pendulum(gravity=g, objects=[flying], settings={"timestep_s": 1e-3, "integrator": "rk4"})
    model["tracked"] = [{"object": 0}]
    r = reading(child.ok({"op": "load", "model": model}))
    assert np.array_equal(r["poses"][:3], x0)
    s = child.ok({"op": "get_state"})
    assert np.allclose(rge.floats(s["objects"][0]["w"]), w0, atol=1e-15)  # world frame, as given
    assert np.array_equal(rge.floats(s["objects"][0]["v"]), v0)
    worst = 0.0
    for _ in range(50):
        r = reading(child.ok({"op": "step", "n": 10}))
        t = r["t"][0]
        worst = max(worst, np.abs(r["poses"][:3] - (x0 + v0 * t + 0.5 * g * t * t)).max())
    assert t == pytest.approx(0.5)
    assert worst < 1e-9, worst
    s = child.ok({"op": "get_state"})
    o = s["objects"][0]
    assert np.allclose(rge.floats(o["v"]), v0 + g * t, atol=1e-9)
    # A cube's inertia is isotropic: its angular velocity stays constant
    # in the world frame while its body axes turn.
    assert np.allclose(rge.floats(o["w"]), w0, atol=1e-9)
    assert not np.allclose(rge.floats(o["pose"])[3:], q0, atol=1e-2)
    # The portable fields load back as they were (world-frame twist).
    child.ok({"op": "set_state", **dict(s, native=None)})
    back = child.ok({"op": "get_state"})["objects"][0]
    assert np.array_equal(rge.floats(back["pose"]), rge.floats(o["pose"]))
    assert np.array_equal(rge.floats(back["v"]), rge.floats(o["v"]))
    assert np.allclose(rge.floats(back["w"]), rge.floats(o["w"]), atol=1e-14)


def test_native_state_restores_bit_exactly(child):
    model = pendulum(gravity=[0, 0, -9.81], com=[0, 0, 0.1], kv=2.0, objects=[cube(pose=[0.3, 0, 0.2, 1, 0, 0, 0])],
                     ground={"height_m": 0.0, "friction": 0.8}, settings={"timestep_s": 0.002})
    model["tracked"].append({"object": 0})
    model["params"]["restitution"] = {"cube": 0.3}
    child.ok({"op": "load", "model": model})
    child.ok({"op": "step", "n": 60, "commands": {"kinds": ["position"], "values": rge.bits([0.8])}})
    state = child.ok({"op": "get_state"})
    assert state["native"] is not None
    later = [child.ok({"op": "step", "n": 10, **({"commands": {"kinds": ["velocity"], "values": rge.bits([-1.0])}}
                                                  if k == 5 else {})})["state"] for k in range(20)]
    # The cube is in contact (warm starts matter) and the servo moved.
    assert rge.floats(later[-1]["poses"])[9] < 0.06 and rge.floats(later[-1]["q"])[0] != 0

    def replay(c):
        back = c.ok({"op": "set_state", **state})["state"]
        assert back["t"] == state["t"] and back["q"] == state["q"] and back["qd"] == state["qd"]
        return [c.ok({"op": "step", "n": 10, **({"commands": {"kinds": ["velocity"], "values": rge.bits([-1.0])}}
                                                 if k == 5 else {})})["state"] for k in range(20)]

    assert replay(child) == later  # bit for bit, the position command restored with the state
    fresh = Child()
    try:
        fresh.ok({"op": "load", "model": model})
        assert replay(fresh) == later
    finally:
        assert fresh.close() == 0
    # The portable fields alone: accepted, close but warm starts reset.
    portable = dict(state, native=None, commands={"kinds": ["position"], "values": rge.bits([0.8])})
    back = child.ok({"op": "set_state", **portable})["state"]
    assert back["t"] == state["t"] and back["q"] == state["q"]
    # A native state edited away from its portable fields is refused.
    edited = dict(state, q=rge.bits(rge.floats(state["q"]) + 0.1))
    e = child.call({"op": "set_state", **edited})["error"]
    assert e["kind"] == "state" and "differ" in e["message"]


def test_unstable_settings_are_reported_and_blow_ups_refused(child):
    # kv dt / I = 10 * 0.01 / 0.01 = 10 under Euler (past 2).
    loaded = child.ok({"op": "load", "model": pendulum(kv=10.0, force_limit=None, settings={"timestep_s": 0.01})})
    issues = loaded["stability_issues"]
    assert len(issues) == 1 and issues[0]["joint"] == "j1" and issues[0]["bound"] == 2.0
    assert issues[0]["value"] == pytest.approx(10.0, rel=1e-9)
    assert "implicitfast" in issues[0]["message"] and "mujoco4's Euler integrator" in issues[0]["message"]
    assert child.ok({"op": "load", "model": pendulum(kv=10.0, settings={
        "timestep_s": 0.01, "integrator": "implicitfast"})})["stability_issues"] == []
    # Run anyway: the error grows 9-fold per step until MuJoCo gives up.
    child.ok({"op": "load", "model": pendulum(kv=10.0, force_limit=None, settings={"timestep_s": 0.01})})
    e = child.call({"op": "step", "n": 500, "commands": {"kinds": ["velocity"], "values": rge.bits([1.0])}})["error"]
    assert e["kind"] == "unstable" and "MuJoCo" in e["message"] and e["t_s"] == 0.0, e


def stepwise(child, model, segments):
    """Loads `model` and takes `segments` with `step` requests (MuJoCo's
    loop driven from Python): the readings, rows t, q, qd, poses, and the
    state at the end or the error that ended them."""
    state = child.ok({"op": "load", "model": model})["state"]
    rows, pending = [], None
    for s in segments:
        if s["read"]:
            rows.append(np.concatenate([rge.floats(state[k]) for k in ("t", "q", "qd", "poses")]).tolist())
        pending = s.get("commands", pending)
        if s["steps"]:
            reply = child.call({"op": "step", "n": s["steps"], **({"commands": pending} if pending else {})})
            pending = None
            if "error" in reply:
                return rows, reply["error"]
            state = reply["ok"]["state"]
    return rows, state


def test_a_replay_in_mujocos_own_loop_gives_the_step_by_step_numbers(child):
    """`run` in columns goes through MuJoCo's rollout (run_open_loop) where
    the laws stay: bit for bit the numbers of the same steps taken one
    request at a time; a blow-up part-way is reported as there, with the
    readings before it."""
    model = pendulum(gravity=(0, 0, -9.81), kv=2.0)
    velocity = lambda v: {"kinds": ["velocity"], "values": rge.bits([v])}  # noqa: E731
    position = lambda v: {"kinds": ["position"], "values": rge.bits([v])}  # noqa: E731
    segments = ([{"read": True, "steps": 5, "commands": velocity(0.3 * np.sin(k))} for k in range(40)]
                + [{"read": True, "steps": 7, "commands": position(0.2 * np.cos(k))} for k in range(30)]
                + [{"read": True, "steps": 3} for _ in range(10)])
    want, end = stepwise(child, model, segments)
    child.ok({"op": "load", "model": model})
    got = child.ok({"op": "run", "columns": as_columns(segments)})
    assert rge.floats(got["readings"]).reshape(-1, 10).tolist() == want and len(want) == len(segments)
    assert got["state"] == end
    # Unstable: kv dt / I = 10 under Euler; stepwise and in columns, the
    # same readings, then the same error.
    model = pendulum(kv=10.0, force_limit=None, settings={"timestep_s": 0.01})
    segments = [{"read": True, "steps": 2, "commands": velocity(1.0)}] + [{"read": True, "steps": 2}] * 200
    want, error = stepwise(child, model, segments)
    assert error["kind"] == "unstable" and 3 < len(want) < 200, (error, len(want))
    child.ok({"op": "load", "model": model})
    got = child.ok({"op": "run", "columns": as_columns(segments)})
    assert got["error"] == error and "state" not in got
    assert rge.floats(got["readings"]).reshape(-1, 10).tolist() == want


def test_the_adapters_process_runs_mujoco_without_its_timer():
    """MuJoCo's Python bindings install a timer (mjcb_time) that reads the
    clock at every stage of every step; the adapter's process (``main``)
    turns it off, as a program linking MuJoCo has it, and the physics stays
    the same to the bit."""
    code = textwrap.dedent("""
        import io, sys
        import mujoco
        from realitygap_engine.adapters import mujoco as adapter
        sys.stdin = io.StringIO("")
        assert adapter.main() == 0
        xml = ('<mujoco><worldbody><body><joint type="hinge" axis="0 1 0"/>'
               '<geom size=".1" pos="0 0 -.3" mass="1"/></body></worldbody></mujoco>')
        m = mujoco.MjModel.from_xml_string(xml)

        def run():
            d = mujoco.MjData(m)
            d.qpos[0] = 0.5
            mujoco.mj_step(m, d, nstep=200)
            return d.qpos.tobytes(), d.timer[mujoco.mjtTimer.mjTIMER_STEP]

        # Models and data made after main() stay untimed.
        q_off, timer = run()
        assert timer.number == 200 and timer.duration == 0, (timer.number, timer.duration)
        # The bindings' default timer back: the same numbers, timed.
        mujoco.set_mjcb_time(None)
        q_on, timer = run()
        assert timer.number == 200 and timer.duration > 0, (timer.number, timer.duration)
        assert q_off == q_on
        print("checked")
    """)
    done = subprocess.run([sys.executable, "-c", code], env=child_env(), capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "checked", done.stderr
    assert "timer callback stays on" not in done.stderr


def test_self_collision_setting_stops_robot_contacts(child):
    # Two links stacked on the base: the second sweeps through the base's
    # box only when robot-robot contacts are off.
    def model(self_collision):
        m = pendulum(settings={"timestep_s": 1e-3, "self_collision": self_collision}, kv=1.0)
        m["bodies"][1]["pose"] = [0, 0, 0.15, 1, 0, 0, 0]
        m["bodies"].append({"name": "tip", "parent": 1, "pose": [0, 0, 0.2, 1, 0, 0, 0], "joint": None,
                            "mass_kg": 0.1, "com": [0, 0, 0], "inertia": [1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4],
                            "shapes": [{"type": "sphere", "pose": IDENTITY, "radius": 0.05}]})
        return m

    finals = {}
    for flag in (True, False):
        child.ok({"op": "load", "model": model(flag)})
        r = reading(child.ok({"op": "step", "n": 3000, "commands": {"kinds": ["velocity"], "values": rge.bits([2.0])}}))
        finals[flag] = r["q"][0]
    assert finals[False] > 4.0  # swept on round
    assert finals[True] < 3.0  # stopped by the base


def test_the_description_and_parameters_reach_the_compiled_model():
    import mujoco
    from realitygap_engine.adapters.mujoco import MujocoSimulation, damping_ratio_for_restitution, parse_settings

    model = pendulum(objects=[dict(cube(), friction=0.8), cube("plain", pose=[1, 0, 0.05, 1, 0, 0, 0])],
                     ground={"height_m": -0.1, "friction": None}, kv=3.0, force_limit=7.0, armature=0.02,
                     settings={"timestep_s": 0.004, "integrator": "implicitfast", "self_collision": False})
    model["bodies"][1]["joint"].update(range=[-1.5, 2.0], damping=0.3, frictionloss=0.05)
    model["bodies"][1]["inertia"] = [0.004, 0.001, 0, 0.001, 0.005, 0, 0, 0, 0.006]
    model["friction_scale"] = 0.5
    model["params"]["restitution"] = {"cube": 0.5}
    model["params"]["contact"] = {"time_constant_s": 0.03, "damping_ratio": 0.9}
    sim = MujocoSimulation(model, parse_settings(model["settings"]), "t")
    m = sim.m
    assert m.opt.timestep == 0.004 and m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert m.opt.gravity.tolist() == [0, 0, 0]
    j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "j1")
    dof = m.jnt_dofadr[j]
    assert m.jnt_limited[j] and m.jnt_range[j].tolist() == [-1.5, 2.0]
    assert (m.dof_armature[dof], m.dof_damping[dof], m.dof_frictionloss[dof]) == (0.02, 0.3, 0.05)
    u = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, "servo:j1")
    assert m.actuator_gainprm[u, 0] == 3.0 and m.actuator_biasprm[u, :3].tolist() == [0, 0, -3.0]
    assert m.actuator_forcelimited[u] and m.actuator_forcerange[u].tolist() == [-7.0, 7.0]
    assert not m.actuator_ctrllimited[u]
    link = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "link")
    assert m.body_mass[link] == 1.0
    assert np.allclose(np.sort(m.body_inertia[link]), np.sort(np.linalg.eigvalsh(
        [[0.004, 0.001, 0], [0.001, 0.005, 0], [0, 0, 0.006]])), atol=1e-15)
    geom = {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, m.geom_bodyid[g]) or "ground": g for g in range(m.ngeom)}
    ground, box, plain = geom["world"], geom["object:cube"], geom["object:plain"]
    assert m.geom_pos[ground].tolist() == [0, 0, -0.1]
    assert m.geom_friction[ground, 0] == 0.5 and m.geom_friction[plain, 0] == 0.5  # MuJoCo's 1, scaled
    assert m.geom_friction[box, 0] == 0.4 and m.geom_priority[box] == 1 and m.geom_priority[plain] == 0
    zeta = damping_ratio_for_restitution(0.5)
    assert zeta == pytest.approx(0.2154, abs=1e-4)
    assert m.geom_solref[box].tolist() == [0.03, zeta]
    assert all(m.geom_solref[g].tolist() == [0.03, 0.9] for g in range(m.ngeom) if g != box)
    robot = [g for g in range(m.ngeom) if m.geom_bodyid[g] in (1, 2)]
    assert all((m.geom_contype[g], m.geom_conaffinity[g]) == (2, 1) for g in robot)
    assert all((m.geom_contype[g], m.geom_conaffinity[g]) == (1, 3) for g in (ground, box, plain))
    assert m.geom_size[box].tolist() == [0.05, 0.05, 0.05]


def test_timing_printout():
    """Wall time per 1000 steps of the pendulum: the child with 10 steps a
    message against mj_step in this process (printed, not asserted)."""
    import mujoco
    c = Child()
    try:
        c.ok({"op": "load", "model": pendulum(settings={"timestep_s": 1e-3})})
        c.ok({"op": "step", "n": 10, "commands": {"kinds": ["velocity"], "values": rge.bits([1.0])}})
        start = time.perf_counter()
        for _ in range(300):
            c.ok({"op": "step", "n": 10})
        child_s = (time.perf_counter() - start) / 3
    finally:
        c.close()
    from realitygap_engine.adapters.mujoco import MujocoSimulation, parse_settings
    sim = MujocoSimulation(pendulum(settings={"timestep_s": 1e-3}), parse_settings({"timestep_s": 1e-3}), "t")
    start = time.perf_counter()
    for _ in range(3000):
        mujoco.mj_step(sim.m, sim.d)
    single_s = (time.perf_counter() - start) / 3
    start = time.perf_counter()
    for _ in range(300):
        sim.step(10)
        sim.reading()
    sim_s = (time.perf_counter() - start) / 3
    print(f"\nper 1000 pendulum steps: child, 10 steps a message: {1e3 * child_s:.2f} ms; "
          f"in process: mj_step one at a time {1e3 * single_s:.2f} ms, "
          f"adapter step(10) + reading {1e3 * sim_s:.2f} ms")
