"""MuJoCo as a realitygap engine in a child process (the `mujoco` Python
package: MuJoCo 3.x from PyPI's ``mujoco``, MuJoCo 4 from ``mujoco-core``).

Run as ``python -m realitygap_engine.adapters.mujoco``; the engine's name is
``$REALITYGAP_ENGINE_NAME``, else ``mujoco4``.

The model is built natively with MjSpec from the protocol's model
description, as realitygap's linked MuJoCo engine builds its MJCF
(crates/engine-mujoco):

- compiler: angles in radians, masses and inertias only from the
  description (a massless body has no inertial: MuJoCo then refuses a moving
  body with nothing massive below it, as it refuses the linked engine's);
- the ground: a plane at ``height_m`` (its friction, else MuJoCo's default);
- one body per description body, nested by ``parent`` at ``pose``; a hinge or
  slide joint with the axis, range (limited), damping, friction loss and
  the ``joints.*.armature`` parameter; collision shapes: box (half sizes),
  sphere, cylinder and capsule (half lengths), mesh (a user mesh of the
  vertices, collided as its convex hull);
- contacts between a body and its parent excluded explicitly (MuJoCo skips
  them itself except next to bodies welded to the world); the setting
  ``self_collision = false`` gives robot geoms contype 2 / conaffinity 1 and
  the environment's (ground, objects) 1 / 3, so the robot touches the
  environment and never itself;
- one general actuator per servo on its joint, switched between MuJoCo's
  ``<velocity>``, ``<position>`` (with damping) and ``<motor>`` laws by its
  gain and bias, force range ``[-F, F]`` (0: no torque; null: unlimited);
- the objects: bodies ``object:NAME`` with a free joint, a box geom, mass and
  principal inertia, initial pose and twist; a given friction with
  priority 1 (the object's coefficient is the contact's);
- parameters: armature (``dof_armature``), restitution (the object geoms'
  ``solref`` damping ratio, priority 1), contact time constant and damping
  ratio (every geom's ``solref``); ``friction_scale`` multiplies every geom's
  sliding friction, MuJoCo's default included.

Stepping is ``mj_step`` (``nstep`` at once when the package has it); MuJoCo's
bad-position/velocity/acceleration warnings (it resets the state when they
fire) and non-finite positions become ``unstable`` errors. A reading
brings the kinematics to the current joint positions first (``mj_step``
leaves them at the step's start), so that the body poses belong to the
joint positions of the reading. The native state is ``mj_getState`` of
``mjSTATE_INTEGRATION`` (time, qpos, qvel, act, warm start, controls, ...)
with the servos' command kinds: an exact restore.
"""

from __future__ import annotations

import ctypes
import glob
import importlib.metadata
import math
import os
import sys

import mujoco
import numpy as np

import realitygap_engine as rge

#: MuJoCo's own default timestep, s.
DEFAULT_TIMESTEP_S = 0.002

#: Prefix of the body (and free joint) name of a scene object.
OBJECT_PREFIX = "object:"

SETTINGS = [
    rge.Setting("timestep_s", "integration timestep, s (> 0); default 0.002"),
    rge.Setting("integrator", "euler | rk4 | implicit | implicitfast; default euler"),
    rge.Setting("solver", "constraint solver: pgs | cg | newton; default newton"),
    rge.Setting("iterations", "maximum solver iterations (>= 1); default 100"),
    rge.Setting("tolerance", "solver tolerance (>= 0); default 1e-8"),
    rge.Setting("cone", "friction cone: pyramidal | elliptic; default pyramidal"),
    rge.Setting("impratio", "frictional-to-normal impedance ratio (> 0); default 1"),
    rge.Setting("noslip_iterations", "no-slip solver iterations (>= 0); default 0"),
    rge.Setting(
        "self_collision",
        "the robot's links collide with each other (never a link with its parent): true | false; "
        "default true (MuJoCo's own); false as in Bullet, ODE and DART",
    ),
]

PARAMS = [
    rge.Param("joints.*.armature", "dof_armature of the joint's DOF"),
    rge.Param(
        "objects.*.restitution",
        "solref[1] (dampratio) of the object's geoms = -ln e / sqrt(pi^2 + ln^2 e), the damping ratio "
        "of a linear spring-damper with restitution e, and geom_priority 1 (e < 1)",
    ),
    rge.Param("contact.time_constant_s", "solref[0] (timeconst) of every geom (>= 2 timesteps)"),
    rge.Param("contact.damping_ratio", "solref[1] (dampratio) of every geom"),
]

COMMANDS = {
    "velocity": "<velocity> actuator law: ctrl = v, gainprm[0] = kv, biasprm = [0, 0, -kv]",
    "position": "<position> actuator law with damping: ctrl = q, gainprm[0] = kp, biasprm = [0, -kp, -kv]",
    "effort": "<motor> actuator law: ctrl = tau, gainprm[0] = 1, biasprm = 0",
}

_KIND_CODES = {"velocity": 0.0, "position": 1.0, "effort": 2.0}
_CODE_KINDS = {v: k for k, v in _KIND_CODES.items()}

_INSTABILITY_WARNINGS = [
    (mujoco.mjtWarning.mjWARN_BADQPOS, "bad joint position (NaN or huge), state reset by MuJoCo"),
    (mujoco.mjtWarning.mjWARN_BADQVEL, "bad joint velocity (NaN or huge), state reset by MuJoCo"),
    (mujoco.mjtWarning.mjWARN_BADQACC, "bad joint acceleration (NaN or huge), state reset by MuJoCo"),
]

#: What mj_getState saves for the native state: everything mj_step reads.
_NATIVE_SPEC = int(mujoco.mjtState.mjSTATE_INTEGRATION)
#: Native layout: [VERSION, spec, state size, servos, state..., kind code per servo].
_NATIVE_VERSION = 1.0
_HEADER = 4

#: mj_getState's spec of a rollout's states, and of its controls.
_FULL = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
_CTRL = int(mujoco.mjtState.mjSTATE_CTRL)

try:  # MuJoCo's open-loop rollout (3.1.1 and later): run_open_loop.
    from mujoco import _rollout
except ImportError:
    _rollout = None

#: Whether mj_step takes nstep (MuJoCo >= 3.?; the loop otherwise).
_HAS_NSTEP = "nstep" in (mujoco.mj_step.__doc__ or "")

#: MuJoCo's warnings since the last step (its log file and console stay
#: untouched: they go to standard error here).
_MESSAGES: list[str] = []


def _warning_handler(message: str) -> None:
    text = str(message).strip()
    if len(_MESSAGES) < 64:
        _MESSAGES.append(text)
    print(f"MuJoCo warning: {text}", file=sys.stderr, flush=True)


def _loaded_libmujoco() -> list[str]:
    """The paths of the MuJoCo library this process has loaded (from
    /proc/self/maps), else those beside the ``mujoco`` package."""
    found: list[str] = []
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as f:
            for line in f:
                path = line.split(maxsplit=5)[-1].strip()
                if os.path.basename(path).startswith("libmujoco.so") and path not in found:
                    found.append(path)
    except OSError:
        pass
    return found or sorted(glob.glob(os.path.join(os.path.dirname(mujoco.__file__), "libmujoco.so*")))


def timers_off() -> bool:
    """Turns MuJoCo's timers off in this process and says whether it could.

    MuJoCo's Python bindings install a timer callback (``mjcb_time``) at
    import, so every step reads the clock at each of its stages for
    ``mjData.timer``; ``mujoco.set_mjcb_time(None)`` puts that default
    back. Nothing here reads the timers, and the linked engine runs
    without them. On this machine they cost a fifth to a quarter of a step
    of the iiwa and of small arms, and 8-9 % of a step of the Mico2, in
    MuJoCo 3.17 and 4.0.1 alike (docs/engine-protocol.md). The library's own
    ``mjcb_time`` pointer is set to null, as a program that links MuJoCo
    has it. The physics is the same to the bit."""
    done = False
    for path in _loaded_libmujoco():
        try:
            pointer = ctypes.c_void_p.in_dll(ctypes.CDLL(path), "mjcb_time")
        except (OSError, ValueError):
            continue
        pointer.value = None
        done = True
    if not done:
        print("realitygap: MuJoCo's timer callback stays on (no libmujoco with mjcb_time found)",
              file=sys.stderr, flush=True)
    return done


def engine_name() -> str:
    return os.environ.get("REALITYGAP_ENGINE_NAME") or "mujoco4"


def distribution() -> str:
    """The installed distribution that provides the `mujoco` module:
    ``mujoco`` or ``mujoco-core``."""
    here = os.path.realpath(mujoco.__file__)
    for name in ("mujoco-core", "mujoco"):
        try:
            dist = importlib.metadata.distribution(name)
        except importlib.metadata.PackageNotFoundError:
            continue
        for f in dist.files or []:
            if str(f).replace("\\", "/").endswith("mujoco/__init__.py"):
                if os.path.realpath(str(dist.locate_file(f))) == here:
                    return name
    found = importlib.metadata.packages_distributions().get("mujoco") or ["unknown distribution"]
    return found[0]


# --------------------------------------------------------------------------
# Settings


def parse_settings(settings) -> dict:
    """The checked settings (key -> value or None), as the linked engine."""
    r = rge.SettingsReader(settings, SETTINGS)
    positive = lambda v: math.isfinite(v) and v > 0  # noqa: E731
    non_negative = lambda v: math.isfinite(v) and v >= 0  # noqa: E731
    i32 = 2**31 - 1
    return {
        "timestep_s": r.number("timestep_s", positive, "> 0 s and finite"),
        "integrator": r.choice("integrator", [
            ("euler", mujoco.mjtIntegrator.mjINT_EULER),
            ("rk4", mujoco.mjtIntegrator.mjINT_RK4),
            ("implicit", mujoco.mjtIntegrator.mjINT_IMPLICIT),
            ("implicitfast", mujoco.mjtIntegrator.mjINT_IMPLICITFAST),
        ]),
        "solver": r.choice("solver", [
            ("pgs", mujoco.mjtSolver.mjSOL_PGS),
            ("cg", mujoco.mjtSolver.mjSOL_CG),
            ("newton", mujoco.mjtSolver.mjSOL_NEWTON),
        ]),
        "iterations": r.integer("iterations", 1, i32),
        "tolerance": r.number("tolerance", non_negative, ">= 0 and finite"),
        "cone": r.choice("cone", [
            ("pyramidal", mujoco.mjtCone.mjCONE_PYRAMIDAL),
            ("elliptic", mujoco.mjtCone.mjCONE_ELLIPTIC),
        ]),
        "impratio": r.number("impratio", positive, "> 0 and finite"),
        "noslip_iterations": r.integer("noslip_iterations", 0, i32),
        "self_collision": r.boolean("self_collision"),
    }


# --------------------------------------------------------------------------
# Small numerics


def _vec(value, n: int | None, what: str) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise rge.LoadError(f"{what}: expected numbers, found {value!r}") from None
    if n is not None and v.size != n:
        raise rge.LoadError(f"{what}: expected {n} numbers, found {v.size}")
    if not np.all(np.isfinite(v)):
        raise rge.LoadError(f"{what}: not finite: {v.tolist()}")
    return v


def _pose(value, what: str) -> tuple[np.ndarray, np.ndarray]:
    p = _vec(value, 7, what)
    if not np.any(p[3:] != 0):
        raise rge.LoadError(f"{what}: zero quaternion")
    return p[:3].copy(), p[3:].copy()


def _number(value, what: str, ok=lambda v: True, bound: str = "") -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise rge.LoadError(f"{what}: expected a number, found {value!r}")
    v = float(value)
    if not math.isfinite(v) or not ok(v):
        raise rge.LoadError(f"{what}: must be {bound or 'finite'}, found {rge.display(v)}")
    return v


def _rotation(q: np.ndarray) -> np.ndarray:
    """The rotation matrix of the quaternion ``w x y z`` (normalized)."""
    m = np.zeros(9)
    u = np.array(q, dtype=np.float64)
    mujoco.mju_normalize4(u)
    mujoco.mju_quat2Mat(m, u)
    return m.reshape(3, 3)


def damping_ratio_for_restitution(e: float) -> float:
    """The damping ratio of a linear mass-spring-damper contact whose
    coefficient of restitution is ``e`` in ``[0, 1)``:
    ``-ln e / sqrt(pi^2 + ln^2 e)``; ``e = 0`` gives 1 (critical)."""
    if e <= 0:
        return 1.0
    ln = math.log(e)
    return -ln / math.sqrt(math.pi**2 + ln * ln)


def _rust_exp(x: float, digits: int) -> str:
    """Rust's ``{:.Ne}``: ``1.2345e-4`` (no sign or padding on the exponent)."""
    mantissa, exponent = f"{x:.{digits}e}".split("e")
    return f"{mantissa}e{int(exponent)}"


# --------------------------------------------------------------------------
# The model


def body_name(name: str) -> str:
    """MuJoCo reserves `world`: a body of that name becomes `urdf:world`."""
    return "urdf:world" if name == "world" else name


class _Built:
    """The compiled model and what the simulation needs to find in it."""

    def __init__(self):
        self.joint_names: list[str] = []
        self.kv: list[float] = []
        self.kp: list[float | None] = []
        self.zero_force: list[str] = []
        #: Per tracked frame: the site at its offset in a robot body, or an
        #: object's body; each with a framepos and a framequat sensor.
        self.tracked: list[tuple[mujoco.mjtObj, str]] = []
        self.objects: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]] = []


def _params(model) -> tuple[dict, dict, dict]:
    params = model.get("params") or {}
    if not isinstance(params, dict):
        raise rge.LoadError("`params` must be a JSON object")
    known = {"armature", "restitution", "contact"}
    for cat in params:
        if cat not in known:
            raise rge.ParamError(
                f"{cat}", f"not a parameter this engine maps (it maps: {', '.join(p.key for p in PARAMS)})")
    armature = params.get("armature") or {}
    restitution = params.get("restitution") or {}
    contact = params.get("contact") or {}
    for name, d in (("armature", armature), ("restitution", restitution), ("contact", contact)):
        if not isinstance(d, dict):
            raise rge.LoadError(f"`params.{name}` must be a JSON object")
    for key in contact:
        if key not in ("time_constant_s", "damping_ratio"):
            raise rge.ParamError(f"contact.{key}", "not a parameter this engine maps "
                                 f"(it maps: {', '.join(p.key for p in PARAMS)})")
    return armature, restitution, contact


def _param_number(key: str, value, ok, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or not ok(value):
        raise rge.ParamError(key, f"must be {what}, found {value!r}")
    return float(value)


def build(model, options: dict) -> tuple[mujoco.MjModel, _Built]:
    """Compiles the model description (see the module documentation)."""
    built = _Built()
    spec = mujoco.MjSpec()
    spec.modelname = "realitygap"
    spec.compiler.degree = False
    spec.compiler.autolimits = True
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE

    opt = spec.option
    opt.timestep = options["timestep_s"] if options["timestep_s"] is not None else DEFAULT_TIMESTEP_S
    for key in ("integrator", "solver", "iterations", "tolerance", "cone", "impratio", "noslip_iterations"):
        if options[key] is not None:
            setattr(opt, key, options[key])
    opt.gravity = _vec(model.get("gravity", [0, 0, -9.81]), 3, "gravity")
    dt = float(opt.timestep)

    armature, restitution, contact = _params(model)
    tc = contact.get("time_constant_s")
    dr = contact.get("damping_ratio")
    if tc is not None:
        tc = _param_number("contact.time_constant_s", tc, lambda v: v > 0, "> 0 s and finite")
        if tc < 2 * dt:
            raise rge.ParamError(
                "contact.time_constant_s",
                f"{rge.display(tc)} s is below two timesteps ({rge.display(2 * dt)} s at timestep {rge.display(dt)} s): "
                "MuJoCo would clamp it to that; use a larger value or a smaller timestep")
    if dr is not None:
        dr = _param_number("contact.damping_ratio", dr, lambda v: v > 0, "> 0 and finite")

    friction_scale = _number(model.get("friction_scale", 1.0), "friction_scale",
                             lambda v: v >= 0, ">= 0 and finite")
    no_self = options["self_collision"] is False
    robot_geoms = []
    environment_geoms = []

    # The ground.
    ground = model.get("ground")
    if ground is not None:
        g = spec.worldbody.add_geom(name="ground", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 1])
        g.pos = [0, 0, _number(ground.get("height_m", 0.0), "ground.height_m")]
        if ground.get("friction") is not None:
            g.friction = [_number(ground["friction"], "ground.friction", lambda v: v >= 0, ">= 0"), 0.005, 0.0001]
        environment_geoms.append(g)

    # The robot's bodies.
    bodies = model.get("bodies") or []
    spec_bodies = []
    names = []
    joints: dict[str, object] = {}
    mesh_count = 0
    for i, b in enumerate(bodies):
        what = f"body {i}"
        raw_name = b.get("name")
        if not isinstance(raw_name, str) or not raw_name:
            raise rge.LoadError(f"{what}: missing name")
        name = body_name(raw_name)
        what = f'body "{raw_name}"'
        if raw_name.startswith(OBJECT_PREFIX) or raw_name == "urdf:world" or name in names:
            raise rge.LoadError(f"{what}: the name clashes with another body or the scene objects' bodies")
        parent = b.get("parent")
        if not isinstance(parent, int) or isinstance(parent, bool) or not -1 <= parent < i:
            raise rge.LoadError(f"{what}: parent {parent!r} is not -1 or the index of an earlier body")
        pos, quat = _pose(b.get("pose"), f"{what}: pose")
        holder = spec.worldbody if parent == -1 else spec_bodies[parent]
        body = holder.add_body(name=name, pos=pos, quat=quat)
        spec_bodies.append(body)
        names.append(name)
        if parent >= 0:
            spec.add_exclude(bodyname1=names[parent], bodyname2=name)

        j = b.get("joint")
        if j is not None:
            jname = j.get("name")
            if not isinstance(jname, str) or not jname or jname in joints:
                raise rge.LoadError(f"{what}: joint name {jname!r} missing or not unique")
            kind = {"hinge": mujoco.mjtJoint.mjJNT_HINGE, "slide": mujoco.mjtJoint.mjJNT_SLIDE}.get(j.get("type"))
            if kind is None:
                raise rge.LoadError(f'joint "{jname}": type {j.get("type")!r} is not hinge or slide')
            joint = body.add_joint(name=jname, type=kind, axis=_vec(j.get("axis"), 3, f'joint "{jname}": axis'))
            rng = j.get("range")
            if rng is not None:
                lo, hi = _vec(rng, 2, f'joint "{jname}": range')
                joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
                joint.range = [lo, hi]
            else:
                joint.limited = mujoco.mjtLimited.mjLIMITED_FALSE
            damping = _number(j.get("damping", 0.0), f'joint "{jname}": damping', lambda v: v >= 0, ">= 0")
            friction = _number(j.get("frictionloss", 0.0), f'joint "{jname}": frictionloss', lambda v: v >= 0, ">= 0")
            if damping > 0:
                # (a vector in MuJoCo >= 3.x's spec: linear damping first)
                if np.ndim(joint.damping):
                    coefficients = np.zeros(len(joint.damping))
                    coefficients[0] = damping
                    joint.damping = coefficients
                else:
                    joint.damping = damping
            if friction > 0:
                joint.frictionloss = friction
            joints[jname] = joint

        mass = _number(b.get("mass_kg", 0.0), f"{what}: mass_kg", lambda v: v >= 0, ">= 0")
        if mass > 0:
            inertia = _vec(b.get("inertia"), 9, f"{what}: inertia").reshape(3, 3)
            body.mass = mass
            body.ipos = _vec(b.get("com", [0, 0, 0]), 3, f"{what}: com")
            body.fullinertia = [inertia[0, 0], inertia[1, 1], inertia[2, 2],
                                inertia[0, 1], inertia[0, 2], inertia[1, 2]]
            body.explicitinertial = True

        for k, shape in enumerate(b.get("shapes") or []):
            swhat = f"{what}: shape {k}"
            spos, squat = _pose(shape.get("pose", [0, 0, 0, 1, 0, 0, 0]), f"{swhat}: pose")
            kind = shape.get("type")
            g = body.add_geom(pos=spos, quat=squat)
            if kind == "box":
                g.type = mujoco.mjtGeom.mjGEOM_BOX
                g.size = 0.5 * _vec(shape.get("size"), 3, f"{swhat}: size")
            elif kind == "sphere":
                g.type = mujoco.mjtGeom.mjGEOM_SPHERE
                g.size = [_number(shape.get("radius"), f"{swhat}: radius", lambda v: v > 0, "> 0"), 0, 0]
            elif kind in ("cylinder", "capsule"):
                g.type = mujoco.mjtGeom.mjGEOM_CYLINDER if kind == "cylinder" else mujoco.mjtGeom.mjGEOM_CAPSULE
                r = _number(shape.get("radius"), f"{swhat}: radius", lambda v: v > 0, "> 0")
                length = _number(shape.get("length"), f"{swhat}: length", lambda v: v >= 0, ">= 0")
                g.size = [r, length / 2, 0]
            elif kind == "mesh":
                verts = _vec(shape.get("vertices"), None, f"{swhat}: vertices")
                if verts.size % 3 or verts.size < 12:
                    raise rge.LoadError(f"{swhat}: a mesh needs at least 4 vertices of 3 numbers, found {verts.size} numbers")
                mesh = spec.add_mesh(name=f"mesh{mesh_count}")
                mesh.uservert = verts
                mesh_count += 1
                g.type = mujoco.mjtGeom.mjGEOM_MESH
                g.meshname = mesh.name
            else:
                raise rge.LoadError(f"{swhat}: type {kind!r} is not box, sphere, cylinder, capsule or mesh")
            robot_geoms.append(g)

    # The servos.
    for a in model.get("actuators") or []:
        jname = a.get("joint")
        if jname not in joints:
            raise rge.LoadError(f'the servo of joint {jname!r}: no hinge or slide joint of that name in the bodies')
        kv = _number(a.get("kv", 0.0), f'joint "{jname}": kv', lambda v: v >= 0, ">= 0")
        kp = a.get("kp")
        if kp is not None:
            kp = _number(kp, f'joint "{jname}": kp', lambda v: v >= 0, ">= 0")
        limit = a.get("force_limit")
        act = spec.add_actuator(name=f"servo:{jname}", target=jname, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.dyntype = mujoco.mjtDyn.mjDYN_NONE
        act.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        act.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        gain = np.zeros(len(act.gainprm))
        gain[0] = kv
        bias = np.zeros(len(act.biasprm))
        bias[2] = -kv
        act.gainprm = gain
        act.biasprm = bias
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
        if limit is None:
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_FALSE
        else:
            limit = _number(limit, f'joint "{jname}": force_limit', lambda v: v >= 0, ">= 0")
            if limit > 0:
                act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
                act.forcerange = [-limit, limit]
            else:
                # MuJoCo refuses an empty range in the spec: set on the model.
                act.forcelimited = mujoco.mjtLimited.mjLIMITED_FALSE
                built.zero_force.append(jname)
        built.joint_names.append(jname)
        built.kv.append(kv)
        built.kp.append(kp)

    for jname, value in armature.items():
        key = f"joints.{jname}.armature"
        if jname not in joints:
            raise rge.ParamError(key, f"{jname} is not a joint of the model: held and fixed joints are welded there; "
                                 "MuJoCo honours joint parameters on the controlled joints")
        joints[jname].armature = _param_number(key, value, lambda v: v >= 0, ">= 0 and finite")

    # The objects.
    object_geoms: dict[str, object] = {}
    for k, o in enumerate(model.get("objects") or []):
        oname = o.get("name")
        if not isinstance(oname, str) or not oname or oname in object_geoms:
            raise rge.LoadError(f"object {k}: name {oname!r} missing or not unique")
        what = f'object "{oname}"'
        if o.get("shape") != "box":
            raise rge.LoadError(f"{what}: shape {o.get('shape')!r} is not box")
        pos, quat = _pose(o.get("pose"), f"{what}: pose")
        body = spec.worldbody.add_body(name=OBJECT_PREFIX + oname, pos=pos, quat=quat)
        body.add_freejoint(name=OBJECT_PREFIX + oname)
        body.mass = _number(o.get("mass_kg"), f"{what}: mass_kg", lambda v: v > 0, "> 0")
        body.ipos = [0, 0, 0]
        body.inertia = _vec(o.get("inertia"), 3, f"{what}: inertia")
        body.explicitinertial = True
        g = body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=0.5 * _vec(o.get("size"), 3, f"{what}: size"))
        if o.get("friction") is not None:
            g.friction = [_number(o["friction"], f"{what}: friction", lambda v: v >= 0, ">= 0"), 0.005, 0.0001]
            g.priority = 1
        environment_geoms.append(g)
        object_geoms[oname] = g
        built.objects.append((oname, quat / np.linalg.norm(quat),
                              _vec(o.get("linear_velocity", [0, 0, 0]), 3, f"{what}: linear_velocity"),
                              _vec(o.get("angular_velocity", [0, 0, 0]), 3, f"{what}: angular_velocity")))

    # Contact softness, then restitution (which overrides the damping ratio).
    if tc is not None or dr is not None:
        for g in robot_geoms + environment_geoms:
            solref = np.array(g.solref, dtype=np.float64)
            g.solref = [tc if tc is not None else solref[0], dr if dr is not None else solref[1]]
    for oname, e in restitution.items():
        key = f"objects.{oname}.restitution"
        if oname not in object_geoms:
            raise rge.ParamError(key, f'the model has no object "{oname}"')
        if isinstance(e, bool) or not isinstance(e, (int, float)) or not (0.0 <= e < 1.0):
            raise rge.ParamError(key, f"{e!r} is not below 1: MuJoCo's contact needs a damping ratio above 0 "
                                 "(restitution 1 would be an infinitely stiff contact)")
        g = object_geoms[oname]
        g.solref = [float(g.solref[0]), damping_ratio_for_restitution(float(e))]
        g.priority = 1

    for g in robot_geoms + environment_geoms:
        friction = np.array(g.friction, dtype=np.float64)
        friction[0] *= friction_scale
        g.friction = friction
    if no_self:
        for g in robot_geoms:
            g.contype, g.conaffinity = 2, 1
        for g in environment_geoms:
            g.contype, g.conaffinity = 1, 3

    # Tracked frames.
    for k, t in enumerate(model.get("tracked") or []):
        if "body" in t:
            b = t["body"]
            if not isinstance(b, int) or isinstance(b, bool) or not 0 <= b < len(names):
                raise rge.LoadError(f"tracked {k}: body {b!r} is not a body index")
            opos, oquat = _pose(t.get("offset", [0, 0, 0, 1, 0, 0, 0]), f"tracked {k}: offset")
            spec_bodies[b].add_site(name=f"tracked:{k}", pos=opos, quat=oquat)
            built.tracked.append((mujoco.mjtObj.mjOBJ_SITE, f"tracked:{k}"))
        elif "object" in t:
            o = t["object"]
            if not isinstance(o, int) or isinstance(o, bool) or not 0 <= o < len(built.objects):
                raise rge.LoadError(f"tracked {k}: object {o!r} is not an object index")
            built.tracked.append((mujoco.mjtObj.mjOBJ_XBODY, OBJECT_PREFIX + built.objects[o][0]))
        else:
            raise rge.LoadError(f"tracked {k}: neither a body nor an object")
    # The tracked poses as sensors too, in the reading's layout (x y z, then
    # qw qx qy qz): a rollout (run_open_loop) records them at every step.
    for objtype, objname in built.tracked:
        for sensor in (mujoco.mjtSensor.mjSENS_FRAMEPOS, mujoco.mjtSensor.mjSENS_FRAMEQUAT):
            spec.add_sensor(type=sensor, objtype=objtype, objname=objname)

    try:
        compiled = spec.compile()
    except Exception as e:  # MuJoCo's compiler errors (ValueError)
        raise rge.LoadError(f"MuJoCo rejected the model: {str(e).strip()}") from None
    return compiled, built


# --------------------------------------------------------------------------
# The simulation


class MujocoSimulation(rge.Simulation):
    def __init__(self, model, options: dict, engine: str):
        self.engine = engine
        self.m, built = build(model, options)
        m = self.m
        self.d = mujoco.MjData(m)
        self.joint_names = built.joint_names
        jid = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in built.joint_names]
        self.qpos_adr = np.array([m.jnt_qposadr[j] for j in jid], dtype=np.intp)
        self.dof_adr = np.array([m.jnt_dofadr[j] for j in jid], dtype=np.intp)
        self.ctrl = np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"servo:{n}")
                              for n in built.joint_names], dtype=np.intp)
        # Where each servo's control is in d.ctrl (its own index before
        # MuJoCo had actuator_ctrladr).
        ctrladr = getattr(m, "actuator_ctrladr", None)
        self.ctrl_adr = self.ctrl.copy() if ctrladr is None else np.array(ctrladr, dtype=np.intp)[self.ctrl]
        for n in built.zero_force:
            u = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"servo:{n}")
            m.actuator_forcelimited[u] = 1
            m.actuator_forcerange[u] = [0.0, 0.0]
        self.kv = list(built.kv)
        self.kp = list(built.kp)
        self.gain0 = [m.actuator_gainprm[u].copy() for u in self.ctrl]
        self.bias0 = [m.actuator_biasprm[u].copy() for u in self.ctrl]
        self.ctrllimited0 = [int(m.actuator_ctrllimited[u]) for u in self.ctrl]
        self.kinds = ["velocity"] * len(self.ctrl)
        # Per tracked frame (site or -1, body): a site's pose is the
        # framepos and framequat sensors' (site_xpos, and xquat times the
        # site's quat), bit for bit.
        self.tracked = []
        for objtype, name in built.tracked:
            if objtype == mujoco.mjtObj.mjOBJ_SITE:
                site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)
                self.tracked.append((site, int(m.site_bodyid[site])))
            else:
                self.tracked.append((-1, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)))
        self._site_xpos, self._site_quat = self.d.site_xpos, m.site_quat
        self._quat = np.empty(4)
        self._roller = _rollout.Rollout(nthread=0) if _rollout is not None and self._rollout_fits() else None
        self.objects = []
        for name, _quat, _v, _w in built.objects:
            b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, OBJECT_PREFIX + name)
            j = m.body_jntadr[b]
            self.objects.append((name, int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])))
        # Initial twists: MuJoCo's free joint takes the angular velocity in
        # the body frame.
        for (name, qa, da), (_n, quat, v, w) in zip(self.objects, built.objects):
            self.d.qvel[da:da + 3] = v
            self.d.qvel[da + 3:da + 6] = _rotation(quat).T @ w
        # Views into mjData, read and cleared at every step: the
        # instability warnings' counts, the joint positions and velocities.
        self._warnings = self.d.warning.number
        self._warning_kinds = np.array([int(kind) for kind, _ in _INSTABILITY_WARNINGS], dtype=np.intp)
        self._qpos, self._qvel = self.d.qpos, self.d.qvel
        self._xpos, self._xquat = self.d.xpos, self.d.xquat
        # Whether the body poses (mj_kinematics) lag qpos: a step leaves
        # them at the step's start, and a reading brings them up to date.
        self._poses_stale = False
        mujoco.mj_forward(m, self.d)
        self._clear_warnings()
        self.issues = self._stability()

    # -- stability

    def _stability(self) -> list[rge.StabilityIssue]:
        """The explicit-integration check of the velocity servos (the linked
        engine's): kv dt / I_eff at the initial pose, I_eff = 1/(M^-1)_jj,
        against 2 (Euler) or 2.785 (RK4); nothing under the implicit ones."""
        m = self.m
        integrator = int(m.opt.integrator)
        if integrator == int(mujoco.mjtIntegrator.mjINT_EULER):
            bound, name = 2.0, "Euler"
        elif integrator == int(mujoco.mjtIntegrator.mjINT_RK4):
            bound, name = 2.785, "RK4"
        else:
            return []
        if m.nv == 0 or len(self.dof_adr) == 0:
            return []
        dense = np.zeros((m.nv, m.nv))
        try:
            mujoco.mj_fullM(m, self.d, dense)  # MuJoCo >= 3.3: (m, d, dst)
        except TypeError:
            mujoco.mj_fullM(m, dense, self.d.qM)  # older: (m, dst, M)
        try:
            low = np.linalg.cholesky(dense)
        except np.linalg.LinAlgError:
            return []
        inv_low = np.linalg.solve(low, np.eye(m.nv))
        inv_diag = np.sum(inv_low * inv_low, axis=0)
        dt = float(m.opt.timestep)
        issues = []
        for jname, dof, u in zip(self.joint_names, self.dof_adr, self.ctrl):
            gear = float(m.actuator_gear[u, 0])
            affine = int(m.actuator_biastype[u]) == int(mujoco.mjtBias.mjBIAS_AFFINE)
            kv = -float(m.actuator_biasprm[u, 2]) * gear * gear if affine else 0.0
            i_eff = 1.0 / inv_diag[dof]
            ratio = kv * dt / i_eff
            if ratio >= bound:
                safe_dt = i_eff / kv
                issues.append(rge.StabilityIssue(
                    joint=jname, quantity="kv*dt/I_eff", value=ratio, bound=bound,
                    message=(
                        f'joint "{jname}": kv*dt/I_eff = {rge.display(kv)} N m s/rad * {rge.display(dt)} s / '
                        f"{_rust_exp(i_eff, 4)} kg m^2 = {ratio:.3f}, past the bound {rge.display(bound)} of "
                        f"{self.engine}'s {name} integrator, which integrates the velocity servo's damping "
                        "explicitly (I_eff = 1/(M^-1)_jj at the initial pose, armature included); fix: set "
                        f'integrator = "implicitfast", or timestep_s below {_rust_exp(safe_dt, 3)} s (kv*dt/I_eff <= 1)'),
                ))
        issues.sort(key=lambda i: -i.value)
        return issues

    def stability_issues(self):
        return self.issues

    # -- stepping

    def _clear_warnings(self) -> None:
        self._warnings[self._warning_kinds] = 0
        if _MESSAGES:
            _MESSAGES.clear()

    def _unstable(self, t0: float, n: int) -> rge.UnstableError | None:
        # The cheap test first (a step's cost is a few microseconds): no
        # warning and finite sums of squares mean every value is finite
        # (MuJoCo resets a state past mjMAXVAL = 1e10 with a warning).
        warnings, qpos, qvel = self._warnings, self._qpos, self._qvel
        if warnings[self._warning_kinds].any():
            text = next(text for (_, text), code in zip(_INSTABILITY_WARNINGS, self._warning_kinds)
                        if warnings[code] > 0)
        else:
            if math.isfinite(np.dot(qpos, qpos) + np.dot(qvel, qvel)) or \
                    (np.isfinite(qpos).all() and np.isfinite(qvel).all()):
                return None
            text = "non-finite joint position or velocity"
        where = f"at t = {rge.display(t0)} s" if n == 1 else \
            f"within the {n} steps from t = {rge.display(t0)} s"
        message = f"{text} ({where})"
        if _MESSAGES:
            message += f" (MuJoCo warning: {_MESSAGES[-1]})"
        return rge.UnstableError(message, t0)

    def step(self, n: int) -> None:
        m, d = self.m, self.d
        self._clear_warnings()
        # mj_step computes the body poses before integrating (and a
        # failed step resets qpos): they are brought to qpos when read.
        self._poses_stale = True
        if _HAS_NSTEP:
            t0 = float(d.time)
            mujoco.mj_step(m, d, nstep=n)
            error = self._unstable(t0, n)
            if error is not None:
                raise error
        else:
            for _ in range(n):
                t0 = float(d.time)
                mujoco.mj_step(m, d)
                if d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number or \
                        d.warning[mujoco.mjtWarning.mjWARN_BADQPOS].number or \
                        d.warning[mujoco.mjtWarning.mjWARN_BADQVEL].number:
                    raise self._unstable(t0, 1)
            error = self._unstable(t0, 1)
            if error is not None:
                raise error

    def _poses_now(self) -> None:
        if self._poses_stale:
            mujoco.mj_kinematics(self.m, self.d)
            self._poses_stale = False

    # -- reading

    def _frame_pose(self, site: int, b: int) -> np.ndarray:
        if site < 0:
            return np.concatenate([self._xpos[b], self._xquat[b]])
        mujoco.mju_mulQuat(self._quat, self._xquat[b], self._site_quat[site])
        return np.concatenate([self._site_xpos[site], self._quat])

    def reading(self) -> rge.Reading:
        d = self.d
        self._poses_now()
        poses = np.concatenate([self._frame_pose(site, b) for site, b in self.tracked]) if self.tracked \
            else np.zeros(0)
        # (Indexing with an array copies.)
        return rge.Reading(float(d.time), self._qpos[self.qpos_adr], self._qvel[self.dof_adr], poses)

    # -- a replay in MuJoCo's own loop

    def _rollout_fits(self) -> bool:
        """Whether mj_getState's full physics starts with the time, qpos
        and qvel (read back from a rollout's states) and the sensors are the
        tracked poses."""
        m, d = self.m, self.d
        state = np.empty(mujoco.mj_stateSize(m, _FULL))
        mujoco.mj_getState(m, d, state, _FULL)
        return (state[0] == d.time and np.array_equal(state[1:1 + m.nq], d.qpos)
                and np.array_equal(state[1 + m.nq:1 + m.nq + m.nv], d.qvel)
                and m.nsensordata == 7 * len(self.tracked))

    def run_open_loop(self, steps, change_at, values, read_at):
        if self._roller is None:
            return None
        m, d = self.m, self.d
        servos = self.ctrl_adr
        # Each step's controls: the change in force there (-1: those now).
        table = np.vstack([d.ctrl[servos][None], values])
        in_force = np.searchsorted(change_at, np.arange(steps), side="right")
        control = np.empty((1, steps, m.nu))
        control[0] = d.ctrl
        control[0][:, servos] = table[in_force]
        state0 = np.empty(mujoco.mj_stateSize(m, _FULL))
        mujoco.mj_getState(m, d, state0, _FULL)
        warmstart0 = d.qacc_warmstart.copy()
        ctrl0 = d.ctrl.copy()
        states = np.empty((1, steps, state0.size))
        sensors = np.empty((1, steps, m.nsensordata))
        # (MuJoCo's rollout resets mjData, then loads the state.)
        self._roller.rollout([m], [d], steps, _CTRL, state0[None], warmstart0[None], control, states, sensors, None)
        self._poses_stale = True
        if self._warnings.any():
            # A rollout stops at its first warning: take the steps again
            # one segment at a time, which says where and what.
            mujoco.mj_setState(m, d, state0, _FULL)
            d.qacc_warmstart[:] = warmstart0
            d.ctrl[:] = ctrl0
            self._warnings[:] = 0
            _MESSAGES.clear()
            return None
        if len(change_at) and change_at[-1] == steps:
            d.ctrl[servos] = values[-1]
        _MESSAGES.clear()
        nq, nj = m.nq, len(self.qpos_adr)
        rows = np.empty((len(read_at), 1 + 2 * nj + 7 * len(self.tracked)))
        # The state before step k is the state after step k - 1 (the start
        # for k = 0), its poses the sensors computed in step k.
        inside = read_at < steps
        k = read_at[inside]
        before = states[0][np.maximum(k - 1, 0)]
        before[k == 0] = state0
        rows[inside, 0] = before[:, 0]
        rows[inside, 1:1 + nj] = before[:, 1 + self.qpos_adr]
        rows[inside, 1 + nj:1 + 2 * nj] = before[:, 1 + nq + self.dof_adr]
        rows[inside, 1 + 2 * nj:] = sensors[0][k]
        if not inside.all():
            r = self.reading()
            rows[~inside] = np.concatenate(((r.t,), r.q, r.qd, r.poses))
        return rows

    # -- commands

    def _switch_law(self, i: int, kind: str) -> None:
        if self.kinds[i] == kind:
            return
        m = self.m
        u = self.ctrl[i]
        gain = np.zeros_like(m.actuator_gainprm[u])
        bias = np.zeros_like(m.actuator_biasprm[u])
        limited = 0
        if kind == "velocity":
            gain, bias, limited = self.gain0[i].copy(), self.bias0[i].copy(), self.ctrllimited0[i]
        elif kind == "position":
            kp = self.kp[i] or 0.0
            gain[0] = kp
            bias[1] = -kp
            bias[2] = -self.kv[i]
        elif kind == "effort":
            gain[0] = 1.0
        else:
            raise rge.UsageError(f"unknown command kind {kind!r}")
        m.actuator_gainprm[u] = gain
        m.actuator_biasprm[u] = bias
        m.actuator_ctrllimited[u] = limited
        self.kinds[i] = kind

    def set_commands(self, kinds, values) -> None:
        if kinds == self.kinds:
            # The same laws (a replay's every step): the values alone. The
            # SDK hands a list, so this compares without copying it.
            self.d.ctrl[self.ctrl_adr] = values
            return
        for i, (kind, value) in enumerate(zip(kinds, values)):
            if kind == "position" and self.kp[i] is None:
                raise rge.UsageError(f'joint "{self.joint_names[i]}" takes a position command but its actuator has no position gain')
            self._switch_law(i, kind)
            self.d.ctrl[self.ctrl_adr[i]] = value

    def set_joint_angles(self, q) -> None:
        self.d.qpos[self.qpos_adr] = q
        self.d.qvel[self.dof_adr] = 0.0
        mujoco.mj_forward(self.m, self.d)

    # -- states

    def full_state(self) -> rge.FullState:
        m, d = self.m, self.d
        objects = []
        for name, qa, da in self.objects:
            q = d.qpos[qa + 3:qa + 7].copy()
            w_body = d.qvel[da + 3:da + 6]
            objects.append(rge.ObjectState(name, d.qpos[qa:qa + 7].copy(), d.qvel[da:da + 3].copy(),
                                           _rotation(q) @ w_body))
        size = mujoco.mj_stateSize(m, _NATIVE_SPEC)
        state = np.zeros(size)
        mujoco.mj_getState(m, d, state, _NATIVE_SPEC)
        native = np.concatenate([
            [_NATIVE_VERSION, float(_NATIVE_SPEC), float(size), float(len(self.ctrl))],
            state,
            [_KIND_CODES[k] for k in self.kinds],
        ])
        return rge.FullState(float(d.time), d.qpos[self.qpos_adr].copy(), d.qvel[self.dof_adr].copy(),
                             objects, native)

    def set_full_state(self, state: rge.FullState) -> None:
        if state.native is not None:
            self._restore_native(state)
        else:
            self._load_portable(state)
        self._clear_warnings()

    def _restore_native(self, state: rge.FullState) -> None:
        m, d = self.m, self.d
        native = state.native
        size = mujoco.mj_stateSize(m, _NATIVE_SPEC)
        nserv = len(self.ctrl)
        expected = [_NATIVE_VERSION, float(_NATIVE_SPEC), float(size), float(nserv)]
        if native.size != _HEADER + size + nserv or list(native[:_HEADER]) != expected:
            raise rge.StateError(
                f"the native MuJoCo state does not fit this model (header {list(native[:_HEADER])}, {native.size} numbers; "
                f"this model: {expected}, {_HEADER + size + nserv} numbers); load its portable part instead")
        body = native[_HEADER:_HEADER + size]
        codes = native[_HEADER + size:]
        if any(c not in _CODE_KINDS for c in codes):
            raise rge.StateError(f"the native MuJoCo state has unknown command kinds {codes.tolist()}")
        # mj_getState writes the time first, then qpos.
        qpos = body[1:1 + m.nq]
        if body[0] != state.t or np.any(qpos[self.qpos_adr] != state.q):
            raise rge.StateError("the time or joint angles differ from those in the native MuJoCo state; "
                                 "to load edited values, drop the native part")
        mujoco.mj_setState(m, d, body, _NATIVE_SPEC)
        for i, c in enumerate(codes):
            self._switch_law(i, _CODE_KINDS[float(c)])
        mujoco.mj_forward(m, d)

    def _load_portable(self, state: rge.FullState) -> None:
        m, d = self.m, self.d
        ctrl = d.ctrl[self.ctrl_adr].copy()
        mujoco.mj_resetData(m, d)
        d.qpos[self.qpos_adr] = state.q
        d.qvel[self.dof_adr] = state.qd
        for (name, qa, da), o in zip(self.objects, state.objects):
            # As MuJoCo normalizes: a quaternion within 1e-15 of unit length
            # stays as it is (a state read back loads bit for bit).
            q = np.array(o.pose[3:], dtype=np.float64)
            mujoco.mju_normalize4(q)
            d.qpos[qa:qa + 3] = o.pose[:3]
            d.qpos[qa + 3:qa + 7] = q
            d.qvel[da:da + 3] = o.v
            d.qvel[da + 3:da + 6] = _rotation(q).T @ o.w
        d.ctrl[self.ctrl_adr] = ctrl
        d.time = state.t
        mujoco.mj_forward(m, d)


class MujocoAdapter(rge.Adapter):
    default_timestep_s = DEFAULT_TIMESTEP_S
    settings = SETTINGS
    params = PARAMS
    commands = COMMANDS

    def __init__(self):
        self.name = engine_name()

    def version(self) -> str:
        return f"MuJoCo {mujoco.__version__} (Python, {distribution()})"

    def check_settings(self, settings) -> float:
        ts = parse_settings(settings)["timestep_s"]
        return DEFAULT_TIMESTEP_S if ts is None else ts

    def load(self, model) -> MujocoSimulation:
        settings = model.get("settings") or {}
        return MujocoSimulation(model, parse_settings(settings), self.name)


def main() -> int:
    mujoco.set_mju_user_warning(_warning_handler)
    timers_off()
    return rge.serve(MujocoAdapter())


if __name__ == "__main__":
    sys.exit(main())
