"""Drake as a realitygap engine in a child process (the ``drake`` Python
package from PyPI: ``pydrake``).

Run as ``python -m realitygap_engine.adapters.drake``; the engine's name is
``$REALITYGAP_ENGINE_NAME``, else ``drake``.

The model is built natively as a discrete ``MultibodyPlant`` with its
``SceneGraph`` (``AddMultibodyPlant`` with a ``MultibodyPlantConfig``: the
timestep, the contact model and the discrete contact approximation of the
settings, sampled output ports off so that the plant's discrete state
``[q, v]`` is its whole state), from the protocol's model description:

- the robot in a model instance ``robot``: one rigid body per description
  body with the ``SpatialInertia`` of its mass, centre of mass and central
  inertia (Drake refuses an inertia that cannot be physical, e.g. a zero
  principal moment with the other two unequal, and a massless body at the
  end of a moving chain: both are load errors naming the body); a body
  without a joint welded to its parent (the root to the world) at its pose;
  a ``RevoluteJoint`` (hinge) or ``PrismaticJoint`` (slide) from a frame
  fixed in the parent at the body's pose to the body's frame, with the axis,
  the range as position limits and the viscous damping (both handled
  implicitly by Drake's discrete solver);
- collision shapes: ``Box``, ``Sphere``, ``Cylinder``, ``Capsule``, and
  meshes as ``Convex`` (the hull of the given vertices, passed to Drake as
  an in-memory .obj); contacts between a body and its parent are filtered
  (Drake filters them itself too), and ``self_collision = false`` filters
  every pair of robot shapes;
- the ground: a ``HalfSpace`` on the world body at ``height_m``;
- the objects: free bodies (a model instance each) with a box, mass and
  principal inertia about the centre, initial pose and twist;
- friction: ``CoulombFriction(mu, mu)`` on every shape, ``mu`` the given
  coefficient or Drake's default (``DefaultProximityProperties``: 0.5),
  times ``friction_scale``. Drake combines two shapes' coefficients as
  ``2 mu1 mu2 / (mu1 + mu2)``;
- contact model ``hydroelastic_with_fallback`` (Drake's default): the
  objects are compliant hydroelastic (Drake's default modulus, 1e7 Pa, or
  the ``hydroelastic_modulus`` setting; Drake's default resolution hint),
  the ground and the robot's shapes rigid hydroelastic (Drake has no
  contact between a compliant half space and another compliant shape);
  pairs of rigid shapes (the robot against itself and the ground) fall
  back to point contact.
  ``point``: every contact is a point contact (Drake's default point
  stiffness and dissipation, from ``penetration_allowance``); a box then
  touches the ground at a single point, its deepest, and under ``lagged``
  a box sliding on its face digs in (measured: a cube set sliding at 1 m/s
  with friction 0.2 stops within 4 mm; ``sap`` and ``tamsi`` slide it as
  Coulomb's law says);
- the servos: one ``JointActuator`` per servo (gear ratio 1, effort limit
  ``force_limit``: null unlimited; 0 the smallest positive double, Drake
  refusing a zero limit), driven by Drake's PD controllers of the discrete
  solver (SAP: ``sap``, ``similar``, ``lagged``), which compute
  ``clamp(-Kp (q - qd) - Kd (v - vd) + u_ff, -e, e)`` implicitly:
  velocity ``Kp = 0, Kd = kv, vd = value``; position ``Kp = kp, Kd = kv,
  qd = value, vd = 0``; effort ``Kp = 0, Kd = 1e-200`` (zero gains would
  remove a controller the finalized plant counts on; the term is below
  any rounding) and ``u_ff = value``. Under ``tamsi``, which has no PD
  controllers, the laws are computed from the state at the start of each
  step and applied as ``u_ff`` (explicit; the stability check below);
- dry joint friction (``frictionloss``): Drake has no joint friction
  element; a second ``JointActuator`` on the joint with a PD controller
  ``Kp = 0, Kd = 1e12, vd = 0`` and effort limit ``frictionloss`` is
  SAP's implicit, clamped velocity constraint: regularized Coulomb friction
  (Drake's near-rigid regularization bounds its stiffness; the stuck joint
  creeps). Refused under ``tamsi``;
- parameters: ``joints.*.armature`` is the rotor inertia of every
  actuator on the joint (gear ratio 1: the reflected inertia added to the
  joint's diagonal of the mass matrix; Drake takes the last actuator's,
  so the dry-friction actuator carries it too). Drake has no coefficient of restitution (its
  Hunt-Crossley dissipation gives a velocity-dependent one) and its contact
  stiffness and dissipation are absolute (N/m, Pa, s/m or s), not the
  per-unit-mass time constant and damping ratio of ``[contact]``: those
  keys are not listed, so realitygap refuses them.

Stepping applies the discrete update ``n`` times on the diagram's context
(``EvalUniquePeriodicDiscreteUpdate``, time advanced by the timestep), as
Drake's ``Simulator`` does (no faster here: the update itself is the
cost); an exception from Drake (e.g. a solver that fails to converge) or a
non-finite state is an ``unstable`` error. Drake's first update also
checks the articulated inertias (a moving body with nothing massive at or
below it): the adapter evaluates it at load, so such a model is a load
error naming the body. The native state is the plant's discrete state
vector ``[q, v]`` with the time and the servos' command kinds and values:
an exact restore. The portable state's object quaternions are normalized
(Drake integrates them without normalizing).
"""

from __future__ import annotations

import importlib.metadata
import logging
import math
import os
import sys

import numpy as np

from pydrake.common import MemoryFile
from pydrake.geometry import (
    AddCompliantHydroelasticProperties,
    AddContactMaterial,
    AddRigidHydroelasticProperties,
    Box,
    Capsule,
    CollisionFilterDeclaration,
    Convex,
    Cylinder,
    GeometrySet,
    HalfSpace,
    InMemoryMesh,
    ProximityProperties,
    SceneGraphConfig,
    Sphere,
)
from pydrake.math import RigidTransform
from pydrake.common.eigen_geometry import Quaternion
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlantConfig
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    PdControllerGains,
    PrismaticJoint,
    RevoluteJoint,
    RotationalInertia,
    SpatialInertia,
)
from pydrake.systems.framework import DiagramBuilder

import realitygap_engine as rge

#: Drake's own default time step of a discrete plant (MultibodyPlantConfig),
#: s; it divides the study's 0.05 s control period.
DEFAULT_TIMESTEP_S = 1e-3

#: Drake's defaults (MultibodyPlantConfig and DefaultProximityProperties).
_PLANT_DEFAULTS = MultibodyPlantConfig()
_PROXIMITY_DEFAULTS = SceneGraphConfig().default_proximity_properties
DEFAULT_FRICTION = float(_PROXIMITY_DEFAULTS.dynamic_friction)
DEFAULT_MODULUS_PA = float(_PROXIMITY_DEFAULTS.hydroelastic_modulus)

#: The derivative gain of a controller that must exist but act on nothing
#: (an effort command): a zero gain would remove the controller, which the
#: finalized plant counts on. Its torque ``1e-200 v`` is below any rounding.
TINY_GAIN = 1e-200
#: The derivative gain of the dry-friction constraint (capped by SAP's
#: near-rigid regularization: any larger gain gives the same numbers).
FRICTION_GAIN = 1e12
#: Drake refuses a zero effort limit: a servo with force_limit 0 gets the
#: smallest positive double.
ZERO_LIMIT = 5e-324

SETTINGS = [
    rge.Setting("timestep_s", "time step of the discrete plant, s (> 0); default 0.001 (Drake's own)"),
    rge.Setting(
        "contact_model",
        "point | hydroelastic_with_fallback (the objects compliant hydroelastic, the robot and the ground "
        "rigid; rigid pairs as points); default hydroelastic_with_fallback (Drake's)",
    ),
    rge.Setting(
        "discrete_contact_approximation",
        "tamsi | sap | similar | lagged; default lagged (Drake's). tamsi has no PD controllers: "
        "its servos are explicit and it refuses frictionloss",
    ),
    rge.Setting("hydroelastic_modulus", "modulus of the compliant hydroelastic shapes, Pa (> 0); default 1e7 (Drake's)"),
    rge.Setting("penetration_allowance", "Drake's point-contact penetration allowance, m (> 0); default 0.001"),
    rge.Setting("stiction_tolerance", "Drake's stiction tolerance of regularized friction, m/s (> 0); default 0.0001"),
    rge.Setting("sap_near_rigid_threshold", "SAP's near-rigid threshold (>= 0); default 1"),
    rge.Setting(
        "self_collision",
        "the robot's links collide with each other (never a link with its parent): true | false; "
        "default true (Drake's own)",
    ),
]

PARAMS = [
    rge.Param("joints.*.armature", "default_rotor_inertia of the servo's JointActuator (gear ratio 1: reflected inertia)"),
]

COMMANDS = {
    "velocity": "the JointActuator's implicit PD controller: Kp = 0, Kd = kv, desired v = value "
                "(tamsi: u = kv (value - v) each step)",
    "position": "the JointActuator's implicit PD controller: Kp = kp, Kd = kv, desired (value, 0) "
                "(tamsi: u = kp (value - q) - kv v each step)",
    "effort": "the JointActuator's feed-forward actuation u_ff = value, clamped to the effort limit by its PD "
              "controller with Kp = 0, Kd = 1e-200 (a zero gain would remove the controller)",
}

_KIND_CODES = {"velocity": 0.0, "position": 1.0, "effort": 2.0}
_CODE_KINDS = {v: k for k, v in _KIND_CODES.items()}

#: Native layout: [VERSION, state size, servos, t, state..., kind code per
#: servo, value per servo].
_NATIVE_VERSION = 1.0
_HEADER = 4


class _QuietHalfSpace(logging.Filter):
    """Drops Drake's warning, at every load, that a rigid half space takes
    no part in deformable contact (there is no deformable body here)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "half spaces are not currently supported for deformable contact" not in record.getMessage()


logging.getLogger("drake").addFilter(_QuietHalfSpace())


def engine_name() -> str:
    return os.environ.get("REALITYGAP_ENGINE_NAME") or "drake"


def drake_version() -> str:
    try:
        return importlib.metadata.version("drake")
    except importlib.metadata.PackageNotFoundError:
        return "unknown version"


# --------------------------------------------------------------------------
# Settings


def parse_settings(settings) -> dict:
    """The checked settings (key -> value or None)."""
    r = rge.SettingsReader(settings, SETTINGS)
    positive = lambda v: math.isfinite(v) and v > 0  # noqa: E731
    non_negative = lambda v: math.isfinite(v) and v >= 0  # noqa: E731
    return {
        "timestep_s": r.number("timestep_s", positive, "> 0 s and finite"),
        "contact_model": r.choice("contact_model", [
            ("point", "point"),
            ("hydroelastic_with_fallback", "hydroelastic_with_fallback"),
        ]),
        "discrete_contact_approximation": r.choice("discrete_contact_approximation", [
            ("tamsi", "tamsi"), ("sap", "sap"), ("similar", "similar"), ("lagged", "lagged"),
        ]),
        "hydroelastic_modulus": r.number("hydroelastic_modulus", positive, "> 0 Pa and finite"),
        "penetration_allowance": r.number("penetration_allowance", positive, "> 0 m and finite"),
        "stiction_tolerance": r.number("stiction_tolerance", positive, "> 0 m/s and finite"),
        "sap_near_rigid_threshold": r.number("sap_near_rigid_threshold", non_negative, ">= 0 and finite"),
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


def _number(value, what: str, ok=lambda v: True, bound: str = "") -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise rge.LoadError(f"{what}: expected a number, found {value!r}")
    v = float(value)
    if not math.isfinite(v) or not ok(v):
        raise rge.LoadError(f"{what}: must be {bound or 'finite'}, found {rge.display(v)}")
    return v


def _unit_quat(q: np.ndarray, what: str) -> np.ndarray:
    norm = float(np.linalg.norm(q))
    if norm == 0.0:
        raise rge.LoadError(f"{what}: zero quaternion")
    # A quaternion within rounding of unit length stays as it is (a state
    # read back loads bit for bit).
    return q.copy() if abs(norm - 1.0) <= 4e-16 else q / norm


def _transform(value, what: str) -> RigidTransform:
    p = _vec(value, 7, what)
    q = _unit_quat(p[3:], what)
    return RigidTransform(Quaternion(q[0], q[1], q[2], q[3]), p[:3])


def _pose_of(X: RigidTransform) -> np.ndarray:
    q = X.rotation().ToQuaternion()
    return np.concatenate([X.translation(), [q.w(), q.x(), q.y(), q.z()]])


def _inertia(value, what: str) -> RotationalInertia:
    m = _vec(value, 9, what).reshape(3, 3)
    m = 0.5 * (m + m.T)
    return RotationalInertia(m[0, 0], m[1, 1], m[2, 2], m[0, 1], m[0, 2], m[1, 2])


def _drake_message(e: Exception) -> str:
    return " ".join(str(e).split())


def _rust_exp(x: float, digits: int) -> str:
    """Rust's ``{:.Ne}``: ``1.2345e-4`` (no sign or padding on the exponent)."""
    mantissa, exponent = f"{x:.{digits}e}".split("e")
    return f"{mantissa}e{int(exponent)}"


# --------------------------------------------------------------------------
# The model


class _Servo:
    """One servo: its actuator, law parameters and command in force."""

    def __init__(self, joint_name: str, joint, actuator, kv: float, kp: float | None, limit: float):
        self.joint_name = joint_name
        self.joint = joint
        self.actuator = actuator
        self.kv = kv
        self.kp = kp
        self.limit = limit  # the effort limit given to Drake (inf, ZERO_LIMIT or force_limit)
        self.kind = "velocity"
        self.value = 0.0


def _params(model) -> dict:
    params = model.get("params") or {}
    if not isinstance(params, dict):
        raise rge.LoadError("`params` must be a JSON object")
    maps = ", ".join(p.key for p in PARAMS)
    for cat, d in params.items():
        if cat == "armature":
            if not isinstance(d, dict):
                raise rge.LoadError("`params.armature` must be a JSON object")
            continue
        if not d:
            continue  # nothing set (realitygap sends the empty tables)
        if not isinstance(d, dict):
            raise rge.LoadError(f"`params.{cat}` must be a JSON object")
        for key, value in d.items():
            if value is None:
                continue
            full = f"contact.{key}" if cat == "contact" else \
                f"objects.{key}.{cat}" if cat == "restitution" else f"{cat}.{key}"
            raise rge.ParamError(full, f"not a parameter this engine maps (it maps: {maps})")
    return params.get("armature") or {}


def _param_number(key: str, value, ok, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or not ok(value):
        raise rge.ParamError(key, f"must be {what}, found {value!r}")
    return float(value)


def _shape(shape, what: str):
    kind = shape.get("type")
    if kind == "box":
        size = _vec(shape.get("size"), 3, f"{what}: size")
        if not np.all(size > 0):
            raise rge.LoadError(f"{what}: size must be > 0, found {size.tolist()}")
        return Box(*size)
    if kind == "sphere":
        return Sphere(_number(shape.get("radius"), f"{what}: radius", lambda v: v > 0, "> 0"))
    if kind in ("cylinder", "capsule"):
        r = _number(shape.get("radius"), f"{what}: radius", lambda v: v > 0, "> 0")
        length = _number(shape.get("length"), f"{what}: length", lambda v: v >= 0, ">= 0")
        if kind == "cylinder":
            if length <= 0:
                raise rge.LoadError(f"{what}: a cylinder's length must be > 0, found {rge.display(length)}")
            return Cylinder(r, length)
        return Capsule(r, length)
    if kind == "mesh":
        verts = _vec(shape.get("vertices"), None, f"{what}: vertices")
        if verts.size % 3 or verts.size < 12:
            raise rge.LoadError(f"{what}: a mesh needs at least 4 vertices of 3 numbers, found {verts.size} numbers")
        text = "".join(f"v {float(x)!r} {float(y)!r} {float(z)!r}\n" for x, y, z in verts.reshape(-1, 3))
        hint = os.path.basename(str(shape.get("file") or "mesh")) + ".obj"
        try:
            convex = Convex(InMemoryMesh(mesh_file=MemoryFile(text, ".obj", hint)))
            convex.GetConvexHull()
        except Exception as e:  # Drake's hull errors (a flat mesh)
            raise rge.LoadError(f"{what}: Drake cannot make the convex hull of the mesh: {_drake_message(e)}") from None
        return convex
    raise rge.LoadError(f"{what}: type {kind!r} is not box, sphere, cylinder, capsule or mesh")


class _Built:
    """The finalized diagram and what the simulation needs to find in it."""

    def __init__(self):
        self.servos: list[_Servo] = []
        self.friction: list = []  # (actuator, joint) of the dry-friction constraints
        self.tracked: list = []  # (body, offset RigidTransform or None)
        self.objects: list = []  # (name, body, pose7, v, w)


def build(model, options: dict):
    """Builds and finalizes the plant (see the module documentation)."""
    built = _Built()
    dt = options["timestep_s"] if options["timestep_s"] is not None else DEFAULT_TIMESTEP_S
    approximation = options["discrete_contact_approximation"] or _PLANT_DEFAULTS.discrete_contact_approximation
    contact_model = options["contact_model"] or _PLANT_DEFAULTS.contact_model
    hydro = contact_model == "hydroelastic_with_fallback"
    modulus = options["hydroelastic_modulus"] or DEFAULT_MODULUS_PA
    config = MultibodyPlantConfig(
        time_step=dt,
        use_sampled_output_ports=False,
        contact_model=contact_model,
        discrete_contact_approximation=approximation,
    )
    if options["penetration_allowance"] is not None:
        config.penetration_allowance = options["penetration_allowance"]
    if options["stiction_tolerance"] is not None:
        config.stiction_tolerance = options["stiction_tolerance"]
    if options["sap_near_rigid_threshold"] is not None:
        config.sap_near_rigid_threshold = options["sap_near_rigid_threshold"]
    builder = DiagramBuilder()
    try:
        plant, scene_graph = AddMultibodyPlant(config, builder)
    except Exception as e:
        raise rge.LoadError(f"Drake refused the plant's configuration: {_drake_message(e)}") from None
    plant.mutable_gravity_field().set_gravity_vector(_vec(model.get("gravity", [0, 0, -9.81]), 3, "gravity"))
    built.pd = approximation != "tamsi"

    armature = _params(model)
    friction_scale = _number(model.get("friction_scale", 1.0), "friction_scale", lambda v: v >= 0, ">= 0 and finite")

    def properties(mu: float, compliance: str | None) -> ProximityProperties:
        props = ProximityProperties()
        AddContactMaterial(friction=CoulombFriction(mu, mu), properties=props)
        if hydro and compliance == "compliant":
            AddCompliantHydroelasticProperties(float(_PROXIMITY_DEFAULTS.resolution_hint), modulus, props)
        elif hydro and compliance == "rigid":
            AddRigidHydroelasticProperties(float(_PROXIMITY_DEFAULTS.resolution_hint), props)
        return props

    def friction_of(value, what: str) -> float:
        mu = DEFAULT_FRICTION if value is None else _number(value, what, lambda v: v >= 0, ">= 0")
        return mu * friction_scale

    # The ground.
    ground = model.get("ground")
    if ground is not None:
        h = _number(ground.get("height_m", 0.0), "ground.height_m")
        mu = friction_of(ground.get("friction"), "ground.friction")
        plant.RegisterCollisionGeometry(plant.world_body(), RigidTransform([0.0, 0.0, h]), HalfSpace(), "ground",
                                        properties(mu, "rigid"))

    # The robot's bodies.
    robot = plant.AddModelInstance("robot")
    bodies = model.get("bodies") or []
    drake_bodies = []
    names: list[str] = []
    geometry_ids: list[list] = []
    joints: dict[str, object] = {}
    frictionloss: dict[str, float] = {}
    for i, b in enumerate(bodies):
        what = f"body {i}"
        name = b.get("name")
        if not isinstance(name, str) or not name:
            raise rge.LoadError(f"{what}: missing name")
        what = f'body "{name}"'
        if name in names:
            raise rge.LoadError(f"{what}: the name is not unique")
        parent = b.get("parent")
        if not isinstance(parent, int) or isinstance(parent, bool) or not -1 <= parent < i:
            raise rge.LoadError(f"{what}: parent {parent!r} is not -1 or the index of an earlier body")
        X_PB = _transform(b.get("pose"), f"{what}: pose")

        mass = _number(b.get("mass_kg", 0.0), f"{what}: mass_kg", lambda v: v >= 0, ">= 0")
        if mass > 0:
            com = _vec(b.get("com", [0, 0, 0]), 3, f"{what}: com")
            try:
                M = SpatialInertia.MakeFromCentralInertia(mass, com, _inertia(b.get("inertia"), f"{what}: inertia"))
            except Exception as e:
                raise rge.LoadError(
                    f"{what}: Drake refuses its inertia (mass {rge.display(mass)} kg): {_drake_message(e)}") from None
        else:
            M = SpatialInertia.Zero()
        body = plant.AddRigidBody(name, robot, M)
        drake_bodies.append(body)
        names.append(name)
        parent_frame = plant.world_frame() if parent == -1 else drake_bodies[parent].body_frame()

        j = b.get("joint")
        if j is None:
            plant.WeldFrames(parent_frame, body.body_frame(), X_PB)
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
            lo, hi = (-math.inf, math.inf) if rng is None else _vec(rng, 2, f'joint "{jname}": range')
            damping = _number(j.get("damping", 0.0), f'joint "{jname}": damping', lambda v: v >= 0, ">= 0")
            friction = _number(j.get("frictionloss", 0.0), f'joint "{jname}": frictionloss', lambda v: v >= 0, ">= 0")
            F = plant.AddFrame(FixedOffsetFrame(f"{jname}:parent", parent_frame, X_PB))
            cls = RevoluteJoint if kind == "hinge" else PrismaticJoint
            try:
                joint = plant.AddJoint(cls(jname, F, body.body_frame(), axis, lo, hi, damping))
            except Exception as e:
                raise rge.LoadError(f'joint "{jname}": Drake refused it: {_drake_message(e)}') from None
            joints[jname] = joint
            if friction > 0:
                if not built.pd:
                    raise rge.ParamError(
                        f"joints.{jname}.frictionloss",
                        f"{rge.display(friction)} N m: Drake has no joint friction element, and its dry friction "
                        "here is an implicit PD constraint, which the tamsi approximation lacks; use "
                        "discrete_contact_approximation = sap, similar or lagged")
                frictionloss[jname] = friction

        ids = []
        for k, shape in enumerate(b.get("shapes") or []):
            swhat = f"{what}: shape {k}"
            X_BG = _transform(shape.get("pose", [0, 0, 0, 1, 0, 0, 0]), f"{swhat}: pose")
            geometry = _shape(shape, swhat)
            ids.append(plant.RegisterCollisionGeometry(
                body, X_BG, geometry, f"{name}:{k}", properties(friction_of(None, ""), "rigid")))
        geometry_ids.append(ids)

    # The servos, then the dry-friction constraints (actuator order).
    seen = set()
    for a in model.get("actuators") or []:
        jname = a.get("joint")
        if jname not in joints:
            raise rge.LoadError(f'the servo of joint {jname!r}: no hinge or slide joint of that name in the bodies')
        if jname in seen:
            raise rge.LoadError(f'joint "{jname}" has two servos')
        seen.add(jname)
        kv = _number(a.get("kv", 0.0), f'joint "{jname}": kv', lambda v: v >= 0, ">= 0")
        kp = a.get("kp")
        if kp is not None:
            kp = _number(kp, f'joint "{jname}": kp', lambda v: v >= 0, ">= 0")
        limit = a.get("force_limit")
        if limit is None:
            limit = math.inf
        else:
            limit = _number(limit, f'joint "{jname}": force_limit', lambda v: v >= 0, ">= 0")
            if limit == 0:
                limit = ZERO_LIMIT
        actuator = plant.AddJointActuator(f"servo:{jname}", joints[jname], limit)
        built.servos.append(_Servo(jname, joints[jname], actuator, kv, kp, limit))
    for jname, f in frictionloss.items():
        actuator = plant.AddJointActuator(f"friction:{jname}", joints[jname], f)
        actuator.set_controller_gains(PdControllerGains(p=0.0, d=FRICTION_GAIN))
        built.friction.append(actuator)
    if built.pd:
        for s in built.servos:
            p, d = _gains(s, "velocity")
            s.actuator.set_controller_gains(PdControllerGains(p=p, d=d))

    # Drake gives a DOF the reflected inertia of the last actuator on its
    # joint (each actuator's value replaces the one before; measured on
    # Drake 1.51.1), so a joint with a servo and a dry-friction actuator
    # takes the armature only if every actuator on it carries it.
    on_joint: dict[str, list] = {}
    for s in built.servos:
        on_joint.setdefault(s.joint_name, []).append(s.actuator)
    for jname, actuator in zip(frictionloss, built.friction):
        on_joint.setdefault(jname, []).append(actuator)
    for jname, value in armature.items():
        key = f"joints.{jname}.armature"
        a = _param_number(key, value, lambda v: v >= 0, ">= 0 and finite")
        if jname not in joints:
            raise rge.ParamError(key, f"{jname} is not a joint of the model: held and fixed joints are welded there; "
                                 "Drake honours joint parameters on the controlled joints")
        if jname not in on_joint:
            on_joint[jname] = [plant.AddJointActuator(f"armature:{jname}", joints[jname])]
        for actuator in on_joint[jname]:
            actuator.set_default_gear_ratio(1.0)
            actuator.set_default_rotor_inertia(a)

    # The objects.
    object_names = []
    for k, o in enumerate(model.get("objects") or []):
        oname = o.get("name")
        if not isinstance(oname, str) or not oname or oname in object_names:
            raise rge.LoadError(f"object {k}: name {oname!r} missing or not unique")
        what = f'object "{oname}"'
        if o.get("shape") != "box":
            raise rge.LoadError(f"{what}: shape {o.get('shape')!r} is not box")
        mass = _number(o.get("mass_kg"), f"{what}: mass_kg", lambda v: v > 0, "> 0")
        ix, iy, iz = _vec(o.get("inertia"), 3, f"{what}: inertia")
        try:
            M = SpatialInertia.MakeFromCentralInertia(mass, [0.0, 0.0, 0.0], RotationalInertia(ix, iy, iz))
        except Exception as e:
            raise rge.LoadError(f"{what}: Drake refuses its inertia: {_drake_message(e)}") from None
        instance = plant.AddModelInstance(f"object:{oname}")
        body = plant.AddRigidBody(oname, instance, M)
        size = _vec(o.get("size"), 3, f"{what}: size")
        if not np.all(size > 0):
            raise rge.LoadError(f"{what}: size must be > 0, found {size.tolist()}")
        mu = friction_of(o.get("friction"), f"{what}: friction")
        plant.RegisterCollisionGeometry(body, RigidTransform(), Box(*size), oname, properties(mu, "compliant"))
        pose = _vec(o.get("pose"), 7, f"{what}: pose")
        pose[3:] = _unit_quat(pose[3:], f"{what}: pose")
        built.objects.append((oname, body, pose,
                              _vec(o.get("linear_velocity", [0, 0, 0]), 3, f"{what}: linear_velocity"),
                              _vec(o.get("angular_velocity", [0, 0, 0]), 3, f"{what}: angular_velocity")))
        object_names.append(oname)

    # Tracked frames.
    for k, t in enumerate(model.get("tracked") or []):
        if "body" in t:
            b = t["body"]
            if not isinstance(b, int) or isinstance(b, bool) or not 0 <= b < len(drake_bodies):
                raise rge.LoadError(f"tracked {k}: body {b!r} is not a body index")
            built.tracked.append((drake_bodies[b], _transform(t.get("offset", [0, 0, 0, 1, 0, 0, 0]),
                                                              f"tracked {k}: offset")))
        elif "object" in t:
            o = t["object"]
            if not isinstance(o, int) or isinstance(o, bool) or not 0 <= o < len(built.objects):
                raise rge.LoadError(f"tracked {k}: object {o!r} is not an object index")
            built.tracked.append((built.objects[o][1], None))
        else:
            raise rge.LoadError(f"tracked {k}: neither a body nor an object")

    try:
        plant.Finalize()
    except Exception as e:
        raise rge.LoadError(f"Drake rejected the model: {_drake_message(e)}") from None

    # Collision filters: a body and its parent, and with self_collision =
    # false every pair of robot shapes.
    manager = scene_graph.collision_filter_manager()
    for i, b in enumerate(bodies):
        parent = b["parent"]
        if parent >= 0 and geometry_ids[i] and geometry_ids[parent]:
            manager.Apply(CollisionFilterDeclaration().ExcludeBetween(
                GeometrySet(geometry_ids[parent]), GeometrySet(geometry_ids[i])))
    if options["self_collision"] is False:
        every = [g for ids in geometry_ids for g in ids]
        if every:
            manager.Apply(CollisionFilterDeclaration().ExcludeWithin(GeometrySet(every)))

    built.plant = plant
    built.robot = robot
    built.body_names = names
    try:
        built.diagram = builder.Build()
    except Exception as e:
        raise rge.LoadError(f"Drake rejected the model: {_drake_message(e)}") from None
    built.dt = dt
    return built


def _gains(s: _Servo, kind: str) -> tuple[float, float]:
    """The PD gains (Kp, Kd) of servo ``s`` under a ``kind`` command."""
    if kind == "velocity":
        return 0.0, (s.kv or TINY_GAIN)
    if kind == "position":
        kp = s.kp or 0.0
        return kp, (s.kv if s.kv > 0 else (0.0 if kp > 0 else TINY_GAIN))
    return 0.0, TINY_GAIN


# --------------------------------------------------------------------------
# The simulation


class DrakeSimulation(rge.Simulation):
    def __init__(self, model, options: dict, engine: str):
        self.engine = engine
        b = build(model, options)
        self.b = b
        self.plant = b.plant
        self.diagram = b.diagram
        self.dt = b.dt
        self.servos = b.servos
        self.joint_names = [s.joint_name for s in b.servos]
        plant = self.plant
        self.context = self.diagram.CreateDefaultContext()
        self.pc = plant.GetMyMutableContextFromRoot(self.context)
        self.nq = plant.num_positions()
        self.nv = plant.num_velocities()
        self.q_idx = np.array([s.joint.position_start() for s in self.servos], dtype=np.intp)
        self.v_idx = np.array([s.joint.velocity_start() for s in self.servos], dtype=np.intp)
        # The robot instance's desired state port: [qd per actuator; vd per
        # actuator], actuators by increasing index (the servos, then the
        # friction constraints).
        self.robot_actuators = list(plant.GetJointActuatorIndices(b.robot))
        self.n_robot_act = len(self.robot_actuators)
        self.desired_slot = {int(a): k for k, a in enumerate(self.robot_actuators)}
        self.nu = plant.num_actuated_dofs()
        self.objects = []
        for name, body, pose, v, w in b.objects:
            self.objects.append((name, body, body.floating_positions_start(),
                                 body.floating_velocities_start_in_v()))
        x = self._state()
        for (name, body, qa, va), (_n, _b, pose, v, w) in zip(self.objects, b.objects):
            x[qa:qa + 4] = pose[3:]
            x[qa + 4:qa + 7] = pose[:3]
            x[self.nq + va:self.nq + va + 3] = w
            x[self.nq + va + 3:self.nq + va + 6] = v
        self._set_state(x)
        self._apply_commands()
        # Drake checks the articulated inertias when it first steps (a
        # moving body with nothing massive at or below it): try it now.
        try:
            self.diagram.EvalUniquePeriodicDiscreteUpdate(self.context)
        except Exception as e:
            raise rge.LoadError(f"Drake rejected the model at its initial state: {_drake_message(e)}") from None
        self.issues = self._stability()

    # -- plant state

    def _state(self) -> np.ndarray:
        return np.array(self.context.get_discrete_state_vector().CopyToVector(), dtype=np.float64)

    def _set_state(self, x: np.ndarray) -> None:
        self.context.SetDiscreteState(np.asarray(x, dtype=np.float64))

    # -- stability

    def _stability(self) -> list[rge.StabilityIssue]:
        """Under tamsi the servo laws are explicit: kv dt / I_eff at the
        initial pose (I_eff = 1/(M^-1)_jj, rotor inertia included) against
        2, the explicit Euler bound of a first-order law; SAP's PD
        controllers are implicit (nothing to check)."""
        if self.b.pd or not self.servos:
            return []
        M = self.plant.CalcMassMatrix(self.pc)
        try:
            inv_diag = np.diag(np.linalg.inv(M))
        except np.linalg.LinAlgError:
            return []
        issues = []
        for s, dof in zip(self.servos, self.v_idx):
            if s.kv <= 0 or inv_diag[dof] <= 0:
                continue
            i_eff = 1.0 / inv_diag[dof]
            ratio = s.kv * self.dt / i_eff
            if ratio >= 2.0:
                issues.append(rge.StabilityIssue(
                    joint=s.joint_name, quantity="kv*dt/I_eff", value=ratio, bound=2.0,
                    message=(
                        f'joint "{s.joint_name}": kv*dt/I_eff = {rge.display(s.kv)} N m s/rad * {rge.display(self.dt)} s / '
                        f"{_rust_exp(i_eff, 4)} kg m^2 = {ratio:.3f}, past the bound 2 of {self.engine}'s tamsi "
                        "approximation, whose servos are explicit (I_eff = 1/(M^-1)_jj at the initial pose); fix: "
                        'set discrete_contact_approximation = "lagged" (implicit PD controllers), or timestep_s '
                        f"below {_rust_exp(i_eff / s.kv, 3)} s (kv*dt/I_eff <= 1)"),
                ))
        issues.sort(key=lambda i: -i.value)
        return issues

    def stability_issues(self):
        return self.issues

    # -- commands

    def _apply_commands(self) -> None:
        """The servos' commands into the plant: gains, desired state and
        feed-forward actuation (under tamsi the feed-forward is set per step)."""
        plant, pc = self.plant, self.pc
        if self.b.pd:
            desired = np.zeros(2 * self.n_robot_act)
            u = np.zeros(self.nu)
            for s in self.servos:
                p, d = _gains(s, s.kind)
                gains = s.actuator.get_controller_gains()
                if gains.p != p or gains.d != d:
                    s.actuator.set_controller_gains(PdControllerGains(p=p, d=d))
                k = self.desired_slot[int(s.actuator.index())]
                if s.kind == "velocity":
                    desired[self.n_robot_act + k] = s.value
                elif s.kind == "position":
                    desired[k] = s.value
                else:
                    u[s.actuator.input_start()] = s.value
            plant.get_desired_state_input_port(self.b.robot).FixValue(pc, desired)
            plant.get_actuation_input_port().FixValue(pc, u)
        else:
            self._explicit_actuation()
        # Neither a new fixed input value nor new gains (which are not in
        # the context) invalidate a discrete update Drake has already
        # evaluated at this state (measured: the step after a command
        # change would use the old command); setting the state does.
        self._set_state(self._state())

    def _explicit_actuation(self) -> None:
        x = self._state()
        q, v = x[self.q_idx], x[self.nq + self.v_idx]
        u = np.zeros(self.nu)
        for i, s in enumerate(self.servos):
            if s.kind == "velocity":
                tau = s.kv * (s.value - v[i])
            elif s.kind == "position":
                tau = (s.kp or 0.0) * (s.value - q[i]) - s.kv * v[i]
            else:
                tau = s.value
            u[s.actuator.input_start()] = min(max(tau, -s.limit), s.limit)
        self.plant.get_actuation_input_port().FixValue(self.pc, u)

    def set_commands(self, kinds, values) -> None:
        for s, kind, value in zip(self.servos, kinds, values):
            if kind == "position" and s.kp is None:
                raise rge.UsageError(f'joint "{s.joint_name}" takes a position command but its actuator has no position gain')
            s.kind = kind
            s.value = float(value)
        self._apply_commands()

    # -- stepping

    def step(self, n: int) -> None:
        diagram, context, dt = self.diagram, self.context, self.dt
        explicit = not self.b.pd
        t = context.get_time()
        for _ in range(n):
            if explicit:
                self._explicit_actuation()
            try:
                x = diagram.EvalUniquePeriodicDiscreteUpdate(context)
                context.SetDiscreteState(x)
            except Exception as e:
                raise rge.UnstableError(f"Drake failed to step at t = {rge.display(t)} s: {_drake_message(e)}", t) from None
            t += dt
            context.SetTime(t)
        x = self._state()
        if not np.all(np.isfinite(x)):
            raise rge.UnstableError(
                f"non-finite state within the {n} steps to t = {rge.display(t)} s", t)

    # -- reading

    def reading(self) -> rge.Reading:
        plant, pc = self.plant, self.pc
        x = self._state()
        poses = []
        for body, offset in self.b.tracked:
            X = plant.EvalBodyPoseInWorld(pc, body)
            if offset is not None:
                X = X.multiply(offset)
            poses.append(_pose_of(X))
        poses = np.array(poses).reshape(-1)
        return rge.Reading(float(self.context.get_time()), x[self.q_idx].copy(), x[self.nq + self.v_idx].copy(), poses)

    def set_joint_angles(self, q) -> None:
        x = self._state()
        x[self.q_idx] = q
        x[self.nq + self.v_idx] = 0.0
        self._set_state(x)

    # -- states

    def full_state(self) -> rge.FullState:
        x = self._state()
        t = float(self.context.get_time())
        objects = []
        for name, body, qa, va in self.objects:
            # Drake integrates the quaternion without normalizing it: the
            # pose reports the rotation it stands for (as Drake's own body
            # poses do).
            quat = x[qa:qa + 4] / np.linalg.norm(x[qa:qa + 4])
            objects.append(rge.ObjectState(name, np.concatenate([x[qa + 4:qa + 7], quat]),
                                           x[self.nq + va + 3:self.nq + va + 6].copy(),
                                           x[self.nq + va:self.nq + va + 3].copy()))
        native = np.concatenate([
            [_NATIVE_VERSION, float(x.size), float(len(self.servos)), t],
            x,
            [_KIND_CODES[s.kind] for s in self.servos],
            [s.value for s in self.servos],
        ])
        return rge.FullState(t, x[self.q_idx].copy(), x[self.nq + self.v_idx].copy(), objects, native)

    def set_full_state(self, state: rge.FullState) -> None:
        if state.native is not None:
            self._restore_native(state)
        else:
            self._load_portable(state)

    def _restore_native(self, state: rge.FullState) -> None:
        native = state.native
        nx = self.nq + self.nv
        ns = len(self.servos)
        expected = [_NATIVE_VERSION, float(nx), float(ns)]
        if native.size != _HEADER + nx + 2 * ns or list(native[:3]) != expected:
            raise rge.StateError(
                f"the native Drake state does not fit this model (header {list(native[:3])}, {native.size} numbers; "
                f"this model: {expected}, {_HEADER + nx + 2 * ns} numbers); load its portable part instead")
        t = float(native[3])
        x = native[_HEADER:_HEADER + nx]
        codes = native[_HEADER + nx:_HEADER + nx + ns]
        values = native[_HEADER + nx + ns:]
        if any(c not in _CODE_KINDS for c in codes):
            raise rge.StateError(f"the native Drake state has unknown command kinds {codes.tolist()}")
        if t != state.t or np.any(x[self.q_idx] != state.q):
            raise rge.StateError("the time or joint angles differ from those in the native Drake state; "
                                 "to load edited values, drop the native part")
        self._set_state(x)
        self.context.SetTime(t)
        for s, c, v in zip(self.servos, codes, values):
            s.kind = _CODE_KINDS[float(c)]
            s.value = float(v)
        self._apply_commands()

    def _load_portable(self, state: rge.FullState) -> None:
        x = np.zeros(self.nq + self.nv)
        # Every position at its zero (quaternions at identity), every
        # velocity 0, then the state's joints and objects.
        x[:self.nq] = self.plant.GetDefaultPositions() if hasattr(self.plant, "GetDefaultPositions") else 0.0
        x[self.q_idx] = state.q
        x[self.nq + self.v_idx] = state.qd
        for (name, body, qa, va), o in zip(self.objects, state.objects):
            pose = np.array(o.pose, dtype=np.float64)
            try:
                quat = _unit_quat(pose[3:], f'object "{name}"')
            except rge.LoadError as e:
                raise rge.StateError(str(e)) from None
            x[qa:qa + 4] = quat
            x[qa + 4:qa + 7] = pose[:3]
            x[self.nq + va:self.nq + va + 3] = o.w
            x[self.nq + va + 3:self.nq + va + 6] = o.v
        self._set_state(x)
        self.context.SetTime(state.t)
        self._apply_commands()


class DrakeAdapter(rge.Adapter):
    default_timestep_s = DEFAULT_TIMESTEP_S
    settings = SETTINGS
    params = PARAMS
    commands = COMMANDS

    def __init__(self):
        self.name = engine_name()

    def version(self) -> str:
        return f"Drake {drake_version()}"

    def check_settings(self, settings) -> float:
        ts = parse_settings(settings)["timestep_s"]
        return DEFAULT_TIMESTEP_S if ts is None else ts

    def load(self, model) -> DrakeSimulation:
        settings = model.get("settings") or {}
        return DrakeSimulation(model, parse_settings(settings), self.name)


def main() -> int:
    return rge.serve(DrakeAdapter())


if __name__ == "__main__":
    sys.exit(main())
