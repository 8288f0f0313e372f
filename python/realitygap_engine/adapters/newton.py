"""Newton as a realitygap engine in a child process (the ``newton`` Python
package on Warp, on the CPU: this adapter never asks for a GPU).

Run as ``python -m realitygap_engine.adapters.newton``; the engine's name is
``$REALITYGAP_ENGINE_NAME``, else ``newton``.

The solver is Newton's ``SolverMuJoCo``: Newton's own recommendation for
rigid articulated robots with contact (generalized coordinates, MuJoCo's
soft contacts and constraint solver; the only Newton solver that honours
joint friction, effort limits and target modes). Its default backend is
MuJoCo Warp, MuJoCo's algorithms as Warp kernels, which Warp compiles for
the CPU on first use and caches (``$WARP_CACHE_PATH``, else the folder
``warp-cache`` beside the adapter's venv: the environment owns it). The
setting ``backend = "c"`` runs the same model on MuJoCo's C library through
the same solver (Newton's ``use_mujoco_cpu``). Everything Newton computes is
single precision (float32): positions round to about 1e-7 of their size.

The model is built natively with ``newton.ModelBuilder`` from the protocol's
model description:

- the ground: Newton's ground plane at ``height_m`` (its friction, else
  Newton's default ``mu`` 1); every shape with no detection gap (MuJoCo's
  default: Newton's 0.1 m becomes MuJoCo's geom gap, whose far contact
  candidates fill MuJoCo Warp's contact buffer until real contacts drop);
- one link per description body with its mass, centre of mass and inertia
  (``lock_inertia``: the shapes add no mass; Newton's ``finalize`` validates
  and, where it must, corrects an inertia, as it does for any model; a
  moving body with no mass is MuJoCo's compiler error naming it), the
  root welded to the world at its pose by a fixed joint, every other body
  joined to its parent at ``pose`` by a revolute (``hinge``) or prismatic
  (``slide``) joint along the axis, with its limits, passive damping,
  friction (``joint_friction``: MuJoCo's friction loss) and the
  ``joints.*.armature`` parameter (``joint_armature``), or by a fixed joint;
  the robot is one articulation;
- collision shapes: box (half extents), sphere, cylinder and capsule (half
  lengths, along z), and a mesh as the convex hull of its vertices
  (``add_shape_convex_hull``; the hull's faces come from MuJoCo's compiler,
  the vertices are the description's); no shape adds mass;
- contacts between a body and its parent are filtered (Newton's
  ``collision_filter_parent``); ``self_collision = false`` filters every
  pair of robot shapes, as Newton's URDF importer does for
  ``enable_self_collisions = False``;
- the servos: Newton's joint drives, every controlled DOF in
  ``JointTargetMode.POSITION_VELOCITY`` (a position and a velocity MuJoCo
  actuator on the joint, their sum limited by ``joint_effort_limit``), the
  law switched per joint at run time through ``joint_target_ke`` /
  ``joint_target_kd`` and ``notify_model_changed``: velocity ``ke = 0, kd =
  kv`` (``tau = kv (v - qd)``), position ``ke = kp, kd = kv``, target
  velocity 0 (``tau = kp (q* - q) - kv qd``), effort ``ke = kd = 0`` and the
  torque as ``control.joint_f`` clipped to the force limit (``joint_f`` is
  not an actuator force, so the effort limit does not reach it); a force
  limit of 0 is a servo that never pushes (gains 0, efforts clipped to 0:
  MuJoCo refuses an empty ``actfrcrange``), none an unlimited one (the
  effort limit ``newton.MAXVAL``, 1e10);
- the objects: free bodies with a box shape, mass and principal inertia,
  initial pose and twist; a given friction with ``mujoco:geom_priority`` 1
  (the object's coefficient is the contact's, MuJoCo otherwise takes the
  larger of two); a shape whose friction is 0 makes frictionless contacts
  (``mujoco:condim`` 1, MuJoCo's way: MuJoCo Warp's pyramidal cone turns a
  friction of 0 in a 3-dimensional contact into NaN);
- parameters: armature (``joint_armature``), restitution (the object's
  contact damping ratio, as MuJoCo's adapter maps it, with priority 1),
  contact time constant and damping ratio (every shape's): SolverMuJoCo
  turns a shape's ``ke`` / ``kd`` into MuJoCo's ``solref`` (time constant
  ``2 / kd``, damping ratio ``kd / (2 sqrt(ke))``; Newton's defaults 2500 and
  100 are MuJoCo's default (0.02, 1)), so ``kd = 2 / tau`` and ``ke = 1 /
  (tau zeta)^2``; ``friction_scale`` multiplies every shape's ``mu``,
  Newton's default included.

Stepping is ``SolverMuJoCo.step`` on two states in turn; the solver
recomputes the bodies from the joint coordinates after every step (so
readings agree with their joint angles). A non-finite joint coordinate or
velocity, or one beyond MuJoCo's own bound 1e10 (``mjMAXVAL``, which MuJoCo
Warp does not check), is an ``unstable`` error naming the joint or object.
The native state is every state array (``joint_q``, ``joint_qd``,
``body_q``, ``body_qd``), MuJoCo's warm start (``qacc_warmstart``, the one
array the solver carries from step to step), the time and the servos'
commands: an exact restore. The portable state sets joints and objects,
zeroes the rest and the warm start, and recomputes the bodies (``eval_fk``).
"""

from __future__ import annotations

import math
import os
import sys

import numpy as np


def _warp_cache_dir() -> str | None:
    """The kernel cache beside the venv the adapter runs in
    (``ENGINES/newton/venv`` -> ``ENGINES/newton/warp-cache``), so that the
    engine's environment owns it; ``None`` outside such a venv."""
    prefix = os.path.realpath(sys.prefix)
    if os.path.basename(prefix) != "venv" or prefix == os.path.realpath(sys.base_prefix):
        return None
    return os.path.join(os.path.dirname(prefix), "warp-cache")


if not os.environ.get("WARP_CACHE_PATH") and _warp_cache_dir() is not None:
    os.environ["WARP_CACHE_PATH"] = _warp_cache_dir()

import warp as wp  # noqa: E402

wp.config.log_level = wp.LOG_WARNING

import newton  # noqa: E402

import realitygap_engine as rge  # noqa: E402

#: The default timestep, s: MuJoCo's own (MuJoCo Warp keeps it), a divisor
#: of the study's 0.05 s control period; the servos' damping is implicit
#: under Newton's default integrator (implicitfast), so the stiff velocity
#: servos are stable at it.
DEFAULT_TIMESTEP_S = 0.002

#: MuJoCo's bound on a position or velocity (mjMAXVAL): past it MuJoCo C
#: warns and resets; MuJoCo Warp does not look, so the adapter does.
MAXVAL = 1e10

#: Label prefix of the body (and free joint) of a scene object.
OBJECT_PREFIX = "object:"

SETTINGS = [
    rge.Setting("timestep_s", "integration timestep, s (> 0); default 0.002 (MuJoCo's)"),
    rge.Setting(
        "backend",
        "SolverMuJoCo's backend: warp (MuJoCo Warp kernels compiled for the CPU, Newton's default) | "
        "c (MuJoCo's C library, use_mujoco_cpu); default warp",
    ),
    rge.Setting("integrator", "euler | rk4 | implicit | implicitfast; default implicitfast (Newton's)"),
    rge.Setting("constraint_solver", "MuJoCo's constraint solver: cg | newton; default newton"),
    rge.Setting("iterations", "maximum solver iterations (>= 1); default 100"),
    rge.Setting("ls_iterations", "maximum line-search iterations (>= 1); default 50"),
    rge.Setting("tolerance", "solver tolerance (>= 0); default 1e-8"),
    rge.Setting("cone", "friction cone: pyramidal | elliptic; default pyramidal"),
    rge.Setting("impratio", "frictional-to-normal impedance ratio (> 0); default 1"),
    rge.Setting(
        "self_collision",
        "the robot's links collide with each other (never a link with its parent): true | false; "
        "default true (Newton's URDF importer's own)",
    ),
]

PARAMS = [
    rge.Param("joints.*.armature", "joint_armature of the joint's DOF (MuJoCo's dof_armature)"),
    rge.Param(
        "objects.*.restitution",
        "the object shape's ke / kd (MuJoCo's solref) with damping ratio -ln e / sqrt(pi^2 + ln^2 e), the "
        "damping ratio of a linear spring-damper with restitution e, and mujoco:geom_priority 1 (e < 1)",
    ),
    rge.Param("contact.time_constant_s", "every shape's kd = 2 / tau (MuJoCo's solref time constant; >= 2 timesteps)"),
    rge.Param("contact.damping_ratio", "every shape's ke = 1 / (tau zeta)^2 (MuJoCo's solref damping ratio)"),
]

COMMANDS = {
    "velocity": "joint drive, JointTargetMode.POSITION_VELOCITY with joint_target_ke = 0, joint_target_kd = kv, "
                "control.joint_target_qd = v; limited by joint_effort_limit",
    "position": "joint drive, JointTargetMode.POSITION_VELOCITY with joint_target_ke = kp, joint_target_kd = kv, "
                "control.joint_target_q = q, joint_target_qd = 0; limited by joint_effort_limit",
    "effort": "control.joint_f = tau clipped to the force limit, drive gains 0",
}

_KIND_CODES = {"velocity": 0.0, "position": 1.0, "effort": 2.0}
_CODE_KINDS = {v: k for k, v in _KIND_CODES.items()}
_BACKEND_CODES = {"warp": 0.0, "c": 1.0}

#: Native layout: [VERSION, backend, nq, nqd, bodies, warm start, servos, t, ...].
_NATIVE_VERSION = 1.0
_HEADER = 8


def engine_name() -> str:
    return os.environ.get("REALITYGAP_ENGINE_NAME") or "newton"


# --------------------------------------------------------------------------
# Settings


def parse_settings(settings) -> dict:
    """The checked settings (key -> value or None)."""
    r = rge.SettingsReader(settings, SETTINGS)
    positive = lambda v: math.isfinite(v) and v > 0  # noqa: E731
    non_negative = lambda v: math.isfinite(v) and v >= 0  # noqa: E731
    i32 = 2**31 - 1
    return {
        "timestep_s": r.number("timestep_s", positive, "> 0 s and finite"),
        "backend": r.choice("backend", [("warp", "warp"), ("c", "c")]),
        "integrator": r.choice("integrator", [
            ("euler", "euler"), ("rk4", "rk4"), ("implicit", "implicit"), ("implicitfast", "implicitfast")]),
        "constraint_solver": r.choice("constraint_solver", [("cg", "cg"), ("newton", "newton")]),
        "iterations": r.integer("iterations", 1, i32),
        "ls_iterations": r.integer("ls_iterations", 1, i32),
        "tolerance": r.number("tolerance", non_negative, ">= 0 and finite"),
        "cone": r.choice("cone", [("pyramidal", "pyramidal"), ("elliptic", "elliptic")]),
        "impratio": r.number("impratio", positive, "> 0 and finite"),
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
    """Position and unit quaternion ``w x y z`` of a protocol pose."""
    p = _vec(value, 7, what)
    n = np.linalg.norm(p[3:])
    if n == 0:
        raise rge.LoadError(f"{what}: zero quaternion")
    return p[:3].copy(), p[3:] / n


def _number(value, what: str, ok=lambda v: True, bound: str = "") -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise rge.LoadError(f"{what}: expected a number, found {value!r}")
    v = float(value)
    if not math.isfinite(v) or not ok(v):
        raise rge.LoadError(f"{what}: must be {bound or 'finite'}, found {rge.display(v)}")
    return v


def _xform(pos: np.ndarray, quat_wxyz: np.ndarray) -> wp.transform:
    """A Warp transform (quaternion ``x y z w``) of a position and a
    quaternion ``w x y z``."""
    w, x, y, z = (float(c) for c in quat_wxyz)
    return wp.transform(wp.vec3(*(float(c) for c in pos)), wp.quat(x, y, z, w))


def _rotation(q: np.ndarray) -> np.ndarray:
    """The rotation matrix of the unit quaternion ``w x y z``."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ])


def damping_ratio_for_restitution(e: float) -> float:
    """The damping ratio of a linear mass-spring-damper contact whose
    coefficient of restitution is ``e`` in ``[0, 1)``:
    ``-ln e / sqrt(pi^2 + ln^2 e)``; ``e = 0`` gives 1 (critical)."""
    if e <= 0:
        return 1.0
    ln = math.log(e)
    return -ln / math.sqrt(math.pi**2 + ln * ln)


def _hull_faces(vertices: np.ndarray, what: str) -> np.ndarray:
    """The triangles of the convex hull of ``vertices`` (n x 3), as indices
    into them: MuJoCo's compiler (qhull; the ``mujoco`` package comes with
    MuJoCo Warp) computes the hull of a mesh given without faces and keeps
    its vertices in order."""
    import mujoco  # noqa: PLC0415

    spec = mujoco.MjSpec()
    mesh = spec.add_mesh(name="hull")
    mesh.uservert = vertices.ravel()
    body = spec.worldbody.add_body()
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname="hull")
    try:
        m = spec.compile()
    except Exception as e:  # MuJoCo's compiler errors (ValueError)
        raise rge.LoadError(f"{what}: no convex hull of its {len(vertices)} vertices: {str(e).strip()}") from None
    if m.nmeshvert != len(vertices):
        raise rge.LoadError(f"{what}: MuJoCo's hull kept {m.nmeshvert} of {len(vertices)} vertices")
    return np.array(m.mesh_face, dtype=np.int32).reshape(-1, 3)


# --------------------------------------------------------------------------
# The model


def body_label(name: str) -> str:
    """SolverMuJoCo names MuJoCo's bodies by their Newton labels, and MuJoCo
    reserves `world`: a body of that name is labelled `urdf:world`."""
    return "urdf:world" if name == "world" else name


class _Built:
    """The finalized model and what the simulation needs to find in it."""

    def __init__(self):
        self.joint_names: list[str] = []
        self.joint_index: list[int] = []
        self.kv: list[float] = []
        self.kp: list[float | None] = []
        self.limit: list[float] = []
        self.tracked: list[tuple[int, np.ndarray | None, np.ndarray | None]] = []
        self.objects: list[tuple[str, int, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self.joint_owner: list[str] = []


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


def build(model, options: dict) -> tuple[newton.Model, _Built, float]:
    """Builds and finalizes the model description (see the module
    documentation); returns the model, its index and the timestep."""
    built = _Built()
    dt = options["timestep_s"] if options["timestep_s"] is not None else DEFAULT_TIMESTEP_S
    gravity = _vec(model.get("gravity", [0, 0, -9.81]), 3, "gravity")
    builder = newton.ModelBuilder(up_axis=newton.Axis.Z, gravity=tuple(float(g) for g in gravity))
    newton.solvers.SolverMuJoCo.register_custom_attributes(builder)

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
    # MuJoCo's default solref (0.02, 1) for the key not given.
    solref = None if tc is None and dr is None else (tc if tc is not None else 0.02, dr if dr is not None else 1.0)

    friction_scale = _number(model.get("friction_scale", 1.0), "friction_scale",
                             lambda v: v >= 0, ">= 0 and finite")
    default_mu = newton.ModelBuilder.ShapeConfig().mu
    no_self = options["self_collision"] is False

    def shape_cfg(mu: float | None, damping_ratio: float | None = None) -> newton.ModelBuilder.ShapeConfig:
        """A shape that adds no mass, with friction ``mu`` (else Newton's
        default) times ``friction_scale`` and the contact's solref through
        Newton's ``ke`` / ``kd`` (SolverMuJoCo: ``timeconst = 2 / kd``,
        ``dampratio = kd / (2 sqrt(ke))``)."""
        cfg = newton.ModelBuilder.ShapeConfig()
        cfg.density = 0.0
        # No detection gap (MuJoCo's default): Newton's 0.1 m reaches
        # SolverMuJoCo as MuJoCo's geom gap, and the far, inactive contact
        # candidates it admits fill MuJoCo Warp's contact buffer (nconmax)
        # until real contacts are dropped (the cube falls through the table).
        cfg.gap = 0.0
        cfg.mu = (default_mu if mu is None else mu) * friction_scale
        ref = solref
        if damping_ratio is not None:
            ref = (ref[0] if ref is not None else 0.02, damping_ratio)
        if ref is not None:
            cfg.kd = 2.0 / ref[0]
            cfg.ke = 1.0 / (ref[0] * ref[1]) ** 2
        return cfg

    def shape_attrs(cfg: newton.ModelBuilder.ShapeConfig, priority: int = 0) -> dict | None:
        """SolverMuJoCo's own shape attributes: ``geom_priority``, and a
        frictionless contact (``condim`` 1, MuJoCo's way) for a shape whose
        friction is 0 (MuJoCo Warp's pyramidal cone turns a friction below
        MJ_MINMU with condim 3 into NaN at the first contact)."""
        attrs = {}
        if priority:
            attrs["mujoco:geom_priority"] = priority
        if cfg.mu == 0:
            attrs["mujoco:condim"] = 1
        return attrs or None

    # The ground.
    ground = model.get("ground")
    if ground is not None:
        mu = ground.get("friction")
        if mu is not None:
            mu = _number(mu, "ground.friction", lambda v: v >= 0, ">= 0")
        cfg = shape_cfg(mu)
        # (add_ground_plane, with SolverMuJoCo's attributes)
        builder.add_shape_plane(plane=(0.0, 0.0, 1.0, -_number(ground.get("height_m", 0.0), "ground.height_m")),
                                width=0.0, length=0.0, cfg=cfg, label="ground",
                                custom_attributes=shape_attrs(cfg))

    # The robot's bodies.
    bodies = model.get("bodies") or []
    world_pose: list[tuple[np.ndarray, np.ndarray]] = []
    joints: dict[str, tuple[int, int]] = {}   # name -> (Newton joint, body index)
    robot_joints: list[int] = []
    robot_shapes: list[int] = []
    names: list[str] = []
    for i, b in enumerate(bodies):
        raw_name = b.get("name")
        if not isinstance(raw_name, str) or not raw_name:
            raise rge.LoadError(f"body {i}: missing name")
        what = f'body "{raw_name}"'
        if raw_name.startswith(OBJECT_PREFIX) or raw_name == "urdf:world" or raw_name in names:
            raise rge.LoadError(f"{what}: the name clashes with another body or the scene objects' bodies")
        parent = b.get("parent")
        if not isinstance(parent, int) or isinstance(parent, bool) or not -1 <= parent < i:
            raise rge.LoadError(f"{what}: parent {parent!r} is not -1 or the index of an earlier body")
        pos, quat = _pose(b.get("pose"), f"{what}: pose")
        if parent == -1:
            wpos, wquat = pos, quat
        else:
            ppos, pquat = world_pose[parent]
            wpos, wquat = ppos + _rotation(pquat) @ pos, _quat_mul(pquat, quat)
        world_pose.append((wpos, wquat))

        mass = _number(b.get("mass_kg", 0.0), f"{what}: mass_kg", lambda v: v >= 0, ">= 0")
        if mass > 0:
            inertia = _vec(b.get("inertia"), 9, f"{what}: inertia").reshape(3, 3)
            com = _vec(b.get("com", [0, 0, 0]), 3, f"{what}: com")
        else:
            inertia = np.zeros((3, 3))
            com = np.zeros(3)
        # (SolverMuJoCo names MuJoCo's bodies by label; MuJoCo reserves `world`)
        link = builder.add_link(
            xform=_xform(wpos, wquat), mass=mass, com=wp.vec3(*com.tolist()),
            inertia=wp.mat33(*inertia.ravel().tolist()), label=body_label(raw_name), lock_inertia=True)
        names.append(raw_name)

        j = b.get("joint")
        parent_xform = _xform(pos, quat)
        if j is None:
            jid = builder.add_joint_fixed(parent, link, parent_xform=parent_xform, label=f"weld:{raw_name}")
            built.joint_owner.append(f'body "{raw_name}"')
        else:
            jname = j.get("name")
            if not isinstance(jname, str) or not jname or jname in joints:
                raise rge.LoadError(f"{what}: joint name {jname!r} missing or not unique")
            kind = j.get("type")
            if kind not in ("hinge", "slide"):
                raise rge.LoadError(f'joint "{jname}": type {kind!r} is not hinge or slide')
            axis = _vec(j.get("axis"), 3, f'joint "{jname}": axis')
            if np.linalg.norm(axis) == 0:
                raise rge.LoadError(f'joint "{jname}": zero axis')
            rng = j.get("range")
            if rng is not None:
                lo, hi = _vec(rng, 2, f'joint "{jname}": range')
                if lo > hi:
                    raise rge.LoadError(f'joint "{jname}": range [{rge.display(lo)}, {rge.display(hi)}] is empty')
            else:
                lo, hi = -newton.MAXVAL, newton.MAXVAL
            damping = _number(j.get("damping", 0.0), f'joint "{jname}": damping', lambda v: v >= 0, ">= 0")
            friction = _number(j.get("frictionloss", 0.0), f'joint "{jname}": frictionloss', lambda v: v >= 0, ">= 0")
            args = dict(
                parent_xform=parent_xform, axis=wp.vec3(*axis.tolist()), label=jname,
                limit_lower=float(lo), limit_upper=float(hi),
                damping=damping, friction=friction, armature=0.0,
                target_ke=0.0, target_kd=0.0, effort_limit=0.0,
                actuator_mode=newton.JointTargetMode.NONE,
            )
            add = builder.add_joint_revolute if kind == "hinge" else builder.add_joint_prismatic
            jid = add(parent, link, **args)
            joints[jname] = (jid, i)
            built.joint_owner.append(f'joint "{jname}"')
        robot_joints.append(jid)

        for k, shape in enumerate(b.get("shapes") or []):
            swhat = f"{what}: shape {k}"
            spos, squat = _pose(shape.get("pose", [0, 0, 0, 1, 0, 0, 0]), f"{swhat}: pose")
            xf = _xform(spos, squat)
            kind = shape.get("type")
            cfg = shape_cfg(None)
            attrs = shape_attrs(cfg)
            if kind == "box":
                h = 0.5 * _vec(shape.get("size"), 3, f"{swhat}: size")
                if np.any(h <= 0):
                    raise rge.LoadError(f"{swhat}: box size {(2 * h).tolist()} is not positive")
                sid = builder.add_shape_box(link, xform=xf, hx=float(h[0]), hy=float(h[1]), hz=float(h[2]),
                                            cfg=cfg, custom_attributes=attrs)
            elif kind == "sphere":
                r = _number(shape.get("radius"), f"{swhat}: radius", lambda v: v > 0, "> 0")
                sid = builder.add_shape_sphere(link, xform=xf, radius=r, cfg=cfg, custom_attributes=attrs)
            elif kind in ("cylinder", "capsule"):
                r = _number(shape.get("radius"), f"{swhat}: radius", lambda v: v > 0, "> 0")
                length = _number(shape.get("length"), f"{swhat}: length", lambda v: v >= 0, ">= 0")
                add_shape = builder.add_shape_cylinder if kind == "cylinder" else builder.add_shape_capsule
                sid = add_shape(link, xform=xf, radius=r, half_height=length / 2, cfg=cfg, custom_attributes=attrs)
            elif kind == "mesh":
                verts = _vec(shape.get("vertices"), None, f"{swhat}: vertices")
                if verts.size % 3 or verts.size < 12:
                    raise rge.LoadError(f"{swhat}: a mesh needs at least 4 vertices of 3 numbers, found {verts.size} numbers")
                verts = verts.reshape(-1, 3)
                mesh = newton.Mesh(verts.astype(np.float32), _hull_faces(verts, swhat).ravel(),
                                   compute_inertia=False)
                sid = builder.add_shape_convex_hull(link, xform=xf, mesh=mesh, cfg=cfg, custom_attributes=attrs)
            else:
                raise rge.LoadError(f"{swhat}: type {kind!r} is not box, sphere, cylinder, capsule or mesh")
            robot_shapes.append(sid)
    if robot_joints:
        builder.add_articulation(robot_joints, label="robot")
    if no_self:
        for a, s in enumerate(robot_shapes):
            for t in robot_shapes[a + 1:]:
                builder.add_shape_collision_filter_pair(s, t)

    # The servos: Newton's joint drives (see the module documentation).
    dof_of_joint = {}
    for a in model.get("actuators") or []:
        jname = a.get("joint")
        if jname not in joints:
            raise rge.LoadError(f'the servo of joint {jname!r}: no hinge or slide joint of that name in the bodies')
        kv = _number(a.get("kv", 0.0), f'joint "{jname}": kv', lambda v: v >= 0, ">= 0")
        kp = a.get("kp")
        if kp is not None:
            kp = _number(kp, f'joint "{jname}": kp', lambda v: v >= 0, ">= 0")
        limit = a.get("force_limit")
        limit = math.inf if limit is None else _number(limit, f'joint "{jname}": force_limit', lambda v: v >= 0, ">= 0")
        jid = joints[jname][0]
        dof = builder.joint_qd_start[jid]
        dof_of_joint[jname] = dof
        builder.joint_target_mode[dof] = int(newton.JointTargetMode.POSITION_VELOCITY)
        builder.joint_target_kd[dof] = kv if limit > 0 else 0.0
        # MuJoCo refuses an empty actfrcrange: a servo with force limit 0 gets
        # gains 0 instead (set_commands), and no limit of its own.
        builder.joint_effort_limit[dof] = limit if 0 < limit < math.inf else newton.MAXVAL
        built.joint_names.append(jname)
        built.joint_index.append(jid)
        built.kv.append(kv)
        built.kp.append(kp)
        built.limit.append(limit)

    for jname, value in armature.items():
        key = f"joints.{jname}.armature"
        if jname not in joints:
            raise rge.ParamError(key, f"{jname} is not a joint of the model: held and fixed joints are welded there; "
                                 "Newton honours joint parameters on the controlled joints")
        value = _param_number(key, value, lambda v: v >= 0, ">= 0 and finite")
        builder.joint_armature[builder.joint_qd_start[joints[jname][0]]] = value

    # The objects.
    object_names: list[str] = []
    for k, o in enumerate(model.get("objects") or []):
        oname = o.get("name")
        if not isinstance(oname, str) or not oname or oname in object_names:
            raise rge.LoadError(f"object {k}: name {oname!r} missing or not unique")
        what = f'object "{oname}"'
        if o.get("shape") != "box":
            raise rge.LoadError(f"{what}: shape {o.get('shape')!r} is not box")
        size = _vec(o.get("size"), 3, f"{what}: size")
        if np.any(size <= 0):
            raise rge.LoadError(f"{what}: box size {size.tolist()} is not positive")
        pos, quat = _pose(o.get("pose"), f"{what}: pose")
        mass = _number(o.get("mass_kg"), f"{what}: mass_kg", lambda v: v > 0, "> 0")
        inertia = _vec(o.get("inertia"), 3, f"{what}: inertia")
        body = builder.add_body(xform=_xform(pos, quat), mass=mass, inertia=wp.mat33(
            float(inertia[0]), 0.0, 0.0, 0.0, float(inertia[1]), 0.0, 0.0, 0.0, float(inertia[2])),
            label=OBJECT_PREFIX + oname, lock_inertia=True)
        mu = o.get("friction")
        if mu is not None:
            mu = _number(mu, f"{what}: friction", lambda v: v >= 0, ">= 0")
        e = restitution.get(oname)
        ratio = None
        if e is not None:
            if isinstance(e, bool) or not isinstance(e, (int, float)) or not (0.0 <= e < 1.0):
                raise rge.ParamError(f"objects.{oname}.restitution",
                                     f"{e!r} is not below 1: MuJoCo's contact needs a damping ratio above 0 "
                                     "(restitution 1 would be an infinitely stiff contact)")
            ratio = damping_ratio_for_restitution(float(e))
        priority = 1 if (mu is not None or ratio is not None) else 0
        cfg = shape_cfg(mu, ratio)
        builder.add_shape_box(body, hx=float(size[0] / 2), hy=float(size[1] / 2), hz=float(size[2] / 2),
                              cfg=cfg, custom_attributes=shape_attrs(cfg, priority))
        jid = len(builder.joint_type) - 1
        built.joint_owner.append(f'object "{oname}"')
        object_names.append(oname)
        built.objects.append((oname, body, jid, pos, quat,
                              _vec(o.get("linear_velocity", [0, 0, 0]), 3, f"{what}: linear_velocity"),
                              _vec(o.get("angular_velocity", [0, 0, 0]), 3, f"{what}: angular_velocity")))
    for oname in restitution:
        if oname not in object_names:
            raise rge.ParamError(f"objects.{oname}.restitution", f'the model has no object "{oname}"')

    # Tracked frames.
    for k, t in enumerate(model.get("tracked") or []):
        if "body" in t:
            b = t["body"]
            if not isinstance(b, int) or isinstance(b, bool) or not 0 <= b < len(names):
                raise rge.LoadError(f"tracked {k}: body {b!r} is not a body index")
            opos, oquat = _pose(t.get("offset", [0, 0, 0, 1, 0, 0, 0]), f"tracked {k}: offset")
            built.tracked.append((b, opos, oquat))
        elif "object" in t:
            o = t["object"]
            if not isinstance(o, int) or isinstance(o, bool) or not 0 <= o < len(built.objects):
                raise rge.LoadError(f"tracked {k}: object {o!r} is not an object index")
            built.tracked.append((built.objects[o][1], None, None))
        else:
            raise rge.LoadError(f"tracked {k}: neither a body nor an object")

    try:
        finalized = builder.finalize(device="cpu")
    except Exception as e:  # Newton's validation errors (ValueError)
        raise rge.LoadError(f"Newton rejected the model: {str(e).strip()}") from None
    return finalized, built, dt


# --------------------------------------------------------------------------
# The simulation


def _wxyz(q_xyzw: np.ndarray) -> np.ndarray:
    return np.array([q_xyzw[3], q_xyzw[0], q_xyzw[1], q_xyzw[2]], dtype=np.float64)


class NewtonSimulation(rge.Simulation):
    def __init__(self, model, options: dict, engine: str):
        self.engine = engine
        self.backend = options["backend"] or "warp"
        self.model, built, self.dt = build(model, options)
        m = self.model
        kwargs = {}
        if options["integrator"] is not None:
            kwargs["integrator"] = options["integrator"]
        if options["constraint_solver"] is not None:
            kwargs["solver"] = options["constraint_solver"]
        for key in ("iterations", "ls_iterations", "tolerance", "cone", "impratio"):
            if options[key] is not None:
                kwargs[key] = options[key]
        try:
            self.solver = newton.solvers.SolverMuJoCo(m, use_mujoco_cpu=self.backend == "c", **kwargs)
        except Exception as e:  # MuJoCo's compiler and Newton's conversion errors
            raise rge.LoadError(f"Newton's SolverMuJoCo rejected the model: {type(e).__name__}: {str(e).strip()}") from None
        self.state = m.state()
        self.spare = m.state()
        self.control = m.control()
        self.joint_names = built.joint_names
        self.owner = built.joint_owner
        q_start = m.joint_q_start.numpy()
        qd_start = m.joint_qd_start.numpy()
        self.q_index = np.array([q_start[j] for j in built.joint_index], dtype=np.intp)
        self.qd_index = np.array([qd_start[j] for j in built.joint_index], dtype=np.intp)
        self.kv = np.array(built.kv, dtype=np.float64)
        self.kp = list(built.kp)
        self.limit = np.array(built.limit, dtype=np.float64)
        self.tracked = built.tracked
        self.objects = [(name, body, int(q_start[j]), int(qd_start[j])) for name, body, j, *_ in built.objects]
        # Which joint or object owns each coordinate and DOF (for messages).
        # (joint_q_start and joint_qd_start end with the totals.)
        self.q_owner = np.repeat(np.arange(m.joint_count), np.diff(q_start[:m.joint_count + 1]))
        self.qd_owner = np.repeat(np.arange(m.joint_count), np.diff(qd_start[:m.joint_count + 1]))
        self.t0 = 0.0
        self.steps = 0
        self.kinds = [None] * len(self.joint_names)
        self.values = np.zeros(len(self.joint_names))
        # The initial state: joints at 0 and at rest, objects at their poses
        # and twists.
        joint_q = m.joint_q.numpy()
        joint_qd = m.joint_qd.numpy()
        joint_q[:] = 0.0
        joint_qd[:] = 0.0
        for (name, body, qa, da), (_n, _b, _j, pos, quat, v, w) in zip(self.objects, built.objects):
            joint_q[qa:qa + 7] = [*pos, quat[1], quat[2], quat[3], quat[0]]
            joint_qd[da:da + 3] = v
            joint_qd[da + 3:da + 6] = w
        self.state.joint_q.assign(joint_q)
        self.state.joint_qd.assign(joint_qd)
        newton.eval_fk(m, self.state.joint_q, self.state.joint_qd, self.state)
        self.set_commands(["velocity"] * len(self.joint_names), np.zeros(len(self.joint_names)))

    # -- helpers

    @property
    def t(self) -> float:
        return self.t0 + self.steps * self.dt

    def _warm(self):
        """MuJoCo's warm start (the solver's only memory between steps)."""
        if self.backend == "c":
            return self.solver.mj_data.qacc_warmstart
        return self.solver.mjw_data.qacc_warmstart

    def _get_warm(self) -> np.ndarray:
        w = self._warm()
        return np.array(w if isinstance(w, np.ndarray) else w.numpy(), dtype=np.float64).ravel()

    def _set_warm(self, values: np.ndarray | None) -> None:
        w = self._warm()
        if isinstance(w, np.ndarray):
            w[...] = 0.0 if values is None else values.reshape(w.shape)
        elif values is None:
            w.zero_()
        else:
            w.assign(values.reshape(w.shape).astype(np.float32))

    def _owner(self, index: int, dofs: bool) -> str:
        j = int((self.qd_owner if dofs else self.q_owner)[index])
        return self.owner[j] if j < len(self.owner) else f"joint {j}"

    def _check(self, t0: float, n: int) -> None:
        q = self.state.joint_q.numpy()
        qd = self.state.joint_qd.numpy()
        where = f"at t = {rge.display(t0)} s" if n == 1 else f"within the {n} steps from t = {rge.display(t0)} s"
        for values, what, dofs in ((q, "position", False), (qd, "velocity", True)):
            bad = np.flatnonzero(~np.isfinite(values) | (np.abs(values) > MAXVAL))
            if bad.size:
                i = int(bad[0])
                raise rge.UnstableError(
                    f"{self._owner(i, dofs)}: {what} {rge.display(float(values[i]))} is not finite or beyond "
                    f"MuJoCo's bound {rge.display(MAXVAL)} (mjMAXVAL) {where}", t0)

    # -- stepping

    def step(self, n: int) -> None:
        for _ in range(n):
            t0 = self.t
            self.solver.step(self.state, self.spare, self.control, None, self.dt)
            self.state, self.spare = self.spare, self.state
            self.steps += 1
            self._check(t0, 1)

    # -- reading

    def _pose(self, body: int, opos, oquat, body_q: np.ndarray) -> np.ndarray:
        x = body_q[body].astype(np.float64)
        p, q = x[:3], _wxyz(x[3:])
        q = q / np.linalg.norm(q)
        if opos is None:
            return np.concatenate([p, q])
        return np.concatenate([p + _rotation(q) @ opos, _quat_mul(q, oquat)])

    def reading(self) -> rge.Reading:
        body_q = self.state.body_q.numpy()
        poses = np.array([self._pose(b, p, q, body_q) for b, p, q in self.tracked]).reshape(-1)
        q = self.state.joint_q.numpy()[self.q_index].astype(np.float64)
        qd = self.state.joint_qd.numpy()[self.qd_index].astype(np.float64)
        return rge.Reading(self.t, q, qd, poses)

    # -- commands

    def set_commands(self, kinds, values) -> None:
        m = self.model
        values = np.asarray(values, dtype=np.float64)
        for i, kind in enumerate(kinds):
            if kind == "position" and self.kp[i] is None:
                raise rge.UsageError(f'joint "{self.joint_names[i]}" takes a position command but its actuator has no position gain')
            if kind not in _KIND_CODES:
                raise rge.UsageError(f"unknown command kind {kind!r}")
        changed = list(kinds) != self.kinds
        if changed:
            ke = m.joint_target_ke.numpy()
            kd = m.joint_target_kd.numpy()
            for i, kind in enumerate(kinds):
                dof = self.qd_index[i]
                on = self.limit[i] > 0
                ke[dof] = (self.kp[i] or 0.0) if kind == "position" and on else 0.0
                kd[dof] = self.kv[i] if kind in ("velocity", "position") and on else 0.0
            m.joint_target_ke.assign(ke)
            m.joint_target_kd.assign(kd)
            self.solver.notify_model_changed(newton.ModelFlags.JOINT_DOF_FORCE_PROPERTIES)
        target_q = self.control.joint_target_q.numpy()
        target_qd = self.control.joint_target_qd.numpy()
        joint_f = self.control.joint_f.numpy()
        for i, (kind, value) in enumerate(zip(kinds, values)):
            dof = self.qd_index[i]
            coord = self.q_index[i]
            target_q[coord] = value if kind == "position" else 0.0
            target_qd[dof] = value if kind == "velocity" else 0.0
            joint_f[dof] = float(np.clip(value, -self.limit[i], self.limit[i])) if kind == "effort" else 0.0
        self.control.joint_target_q.assign(target_q)
        self.control.joint_target_qd.assign(target_qd)
        self.control.joint_f.assign(joint_f)
        self.kinds = list(kinds)
        self.values = values.copy()

    def set_joint_angles(self, q) -> None:
        joint_q = self.state.joint_q.numpy()
        joint_qd = self.state.joint_qd.numpy()
        joint_q[self.q_index] = q
        joint_qd[self.qd_index] = 0.0
        self.state.joint_q.assign(joint_q)
        self.state.joint_qd.assign(joint_qd)
        newton.eval_fk(self.model, self.state.joint_q, self.state.joint_qd, self.state)

    # -- states

    def full_state(self) -> rge.FullState:
        s = self.state
        joint_q = s.joint_q.numpy().astype(np.float64)
        joint_qd = s.joint_qd.numpy().astype(np.float64)
        body_q = s.body_q.numpy().astype(np.float64)
        objects = []
        for name, body, qa, da in self.objects:
            x = body_q[body]
            q = _wxyz(x[3:])
            objects.append(rge.ObjectState(name, np.concatenate([x[:3], q / np.linalg.norm(q)]),
                                           joint_qd[da:da + 3].copy(), joint_qd[da + 3:da + 6].copy()))
        body_qd = s.body_qd.numpy().astype(np.float64).ravel()
        warm = self._get_warm()
        native = np.concatenate([
            [_NATIVE_VERSION, _BACKEND_CODES[self.backend], joint_q.size, joint_qd.size, body_q.shape[0],
             warm.size, len(self.kinds), self.t],
            joint_q, joint_qd, body_q.ravel(), body_qd, warm,
            [_KIND_CODES[k] for k in self.kinds], self.values,
        ])
        return rge.FullState(self.t, joint_q[self.q_index].copy(), joint_qd[self.qd_index].copy(), objects, native)

    def set_full_state(self, state: rge.FullState) -> None:
        if state.native is not None:
            self._restore_native(state)
        else:
            self._load_portable(state)

    def _restore_native(self, state: rge.FullState) -> None:
        m = self.model
        native = state.native
        nq, nqd, nb, nw, ns = (m.joint_coord_count, m.joint_dof_count, m.body_count,
                               self._get_warm().size, len(self.kinds))
        expected = [_NATIVE_VERSION, _BACKEND_CODES[self.backend], nq, nqd, nb, nw, ns]
        size = _HEADER + nq + nqd + 13 * nb + nw + 2 * ns
        if native.size != size or list(native[:_HEADER - 1]) != expected:
            raise rge.StateError(
                f"the native Newton state does not fit this model (header {list(native[:_HEADER - 1])}, "
                f"{native.size} numbers; this model: {expected}, {size} numbers); load its portable part instead")
        t = float(native[_HEADER - 1])
        parts = np.split(native[_HEADER:], np.cumsum([nq, nqd, 7 * nb, 6 * nb, nw, ns]))
        joint_q, joint_qd, body_q, body_qd, warm, codes, values = parts
        if any(c not in _CODE_KINDS for c in codes):
            raise rge.StateError(f"the native Newton state has unknown command kinds {codes.tolist()}")
        if t != state.t or np.any(joint_q[self.q_index] != state.q) or np.any(joint_qd[self.qd_index] != state.qd):
            raise rge.StateError("the time or joint angles differ from those in the native Newton state; "
                                 "to load edited values, drop the native part")
        s = self.state
        s.joint_q.assign(joint_q.astype(np.float32))
        s.joint_qd.assign(joint_qd.astype(np.float32))
        s.body_q.assign(body_q.reshape(nb, 7).astype(np.float32))
        s.body_qd.assign(body_qd.reshape(nb, 6).astype(np.float32))
        self._set_warm(warm)
        self.t0, self.steps = t, 0
        self.set_commands([_CODE_KINDS[float(c)] for c in codes], values)

    def _load_portable(self, state: rge.FullState) -> None:
        m = self.model
        joint_q = np.zeros(m.joint_coord_count, dtype=np.float32)
        joint_qd = np.zeros(m.joint_dof_count, dtype=np.float32)
        joint_q[self.q_index] = state.q
        joint_qd[self.qd_index] = state.qd
        for (name, body, qa, da), o in zip(self.objects, state.objects):
            q = np.array(o.pose[3:], dtype=np.float64)
            q = q / np.linalg.norm(q)
            joint_q[qa:qa + 7] = [*o.pose[:3], q[1], q[2], q[3], q[0]]
            joint_qd[da:da + 3] = o.v
            joint_qd[da + 3:da + 6] = o.w
        self.state.joint_q.assign(joint_q)
        self.state.joint_qd.assign(joint_qd)
        newton.eval_fk(m, self.state.joint_q, self.state.joint_qd, self.state)
        self._set_warm(None)
        self.t0, self.steps = float(state.t), 0
        self._check(self.t0, 1)


class NewtonAdapter(rge.Adapter):
    default_timestep_s = DEFAULT_TIMESTEP_S
    settings = SETTINGS
    params = PARAMS
    commands = COMMANDS

    def __init__(self):
        self.name = engine_name()

    def version(self) -> str:
        return f"Newton {newton.__version__} (Warp {wp.__version__}, CPU)"

    def check_settings(self, settings) -> float:
        ts = parse_settings(settings)["timestep_s"]
        return DEFAULT_TIMESTEP_S if ts is None else ts

    def load(self, model) -> NewtonSimulation:
        settings = model.get("settings") or {}
        return NewtonSimulation(model, parse_settings(settings), self.name)


def main() -> int:
    wp.set_device("cpu")
    return rge.serve(NewtonAdapter())


if __name__ == "__main__":
    sys.exit(main())
