#!/usr/bin/env python3
"""Reference trajectory of a realitygap scene, simulated with PyBullet itself.

The Bullet engine of realitygap (crates/engine-bullet) drives Bullet through
the same C API that PyBullet wraps. This script builds the same world with
the `pybullet` package from PyPI and runs the same controller, so that the
Rust engine can be checked against PyBullet (its test reads the CSV this
script writes, see crates/engine-bullet/tests/fixtures/README.md).

What it mirrors, step for step (keep it in sync with
crates/engine-bullet/src/lib.rs and crates/core/src/controller.rs):

- DIRECT mode; gravity (0, 0, -9.81) m/s^2; fixed timestep (default 0.01 s),
  no substeps; numSolverIterations (default 50, Bullet's own);
- bodies created in this order: the ground (a GEOM_PLANE collision shape,
  static, at the scene's ground height), the robot (loadURDF, fixed base at
  the scene's base pose, flag URDF_USE_INERTIA_FROM_FILE unless
  --shape-inertia; self-collision off), then each object (a GEOM_BOX
  collision shape in a createMultiBody of the scene's mass and pose);
  friction coefficients given by the scene are set with changeDynamics;
- mesh file names in the URDF (package:// or relative) are replaced by
  absolute paths in a temporary copy of the URDF (Bullet resolves file names
  itself and does not know ROS packages);
- the scene's held joints are reset to their angles and locked by a
  POSITION_CONTROL motor (position and velocity gains 1, force = the joint's
  URDF effort limit);
- the controlled joints get VELOCITY_CONTROL motors with force = the scene's
  force limit (or --max-force for all) and velocityGain --velocity-gain
  (default 1);
- the controller of METHOD.md: every period, read the joint angles and the
  tracked poses, command v = clamp(gain * (target_deg - angle_deg), -max,
  +max) in rad/s, then step period/timestep times;
- link poses are computed in double precision from getLinkState's
  centre-of-mass and inertial frames (its own link-frame fields are rounded
  to single precision by the C API).

Output: a CSV with '#' provenance lines, a header row, then one row per
control tick: t_s, each tracked body's position (m) and orientation
(quaternion w, x, y, z), each controlled joint's angle (rad).

Usage:
  python3 tools/pybullet_reference.py assets/scenes/scene1_single_joint.toml \
      --urdf ../shared/paper-data/kinova_description/urdf/m1n6s300.urdf \
      --package kinova_description=../shared/paper-data/kinova_description \
      --out crates/engine-bullet/tests/fixtures/pybullet_scene1_official.csv
"""

import argparse
import math
import os
import sys
import tempfile
import tomllib
import xml.etree.ElementTree as ET
from importlib import metadata

import pybullet as p

GRAVITY_M_S2 = 9.81


def fail(message):
    print(f"pybullet_reference: {message}", file=sys.stderr)
    sys.exit(2)


def quat_from_rpy(roll, pitch, yaw):
    """URDF roll-pitch-yaw (radians, fixed axes X then Y then Z) -> (x, y, z, w)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


def quat_mul(a, b):
    """Hamilton product of quaternions (x, y, z, w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def quat_rotate(q, v):
    x, y, z, w = quat_mul(quat_mul(q, (v[0], v[1], v[2], 0.0)), (-q[0], -q[1], -q[2], q[3]))
    return (x, y, z)


def link_frame(state):
    """World pose of a link's URDF frame from getLinkState, in double precision:
    the centre-of-mass frame composed with the inverse of the inertial frame.
    (getLinkState's own link-frame fields are computed by the C API with
    single-precision b3Transform, about 1e-7 m of rounding.)"""
    com_pos, com_orn, inertial_pos, inertial_orn = state[0], state[1], state[2], state[3]
    inv_orn = (-inertial_orn[0], -inertial_orn[1], -inertial_orn[2], inertial_orn[3])
    inv_pos = tuple(-c for c in quat_rotate(inv_orn, inertial_pos))
    rotated = quat_rotate(com_orn, inv_pos)
    pos = tuple(com_pos[i] + rotated[i] for i in range(3))
    return pos, quat_mul(com_orn, inv_orn)


def resolve_mesh(filename, urdf_dir, packages):
    if filename.startswith("package://"):
        rest = filename[len("package://"):]
        name, _, path = rest.partition("/")
        if name not in packages:
            fail(f"mesh {filename}: package '{name}' unknown (give --package {name}=DIR)")
        resolved = os.path.join(packages[name], path)
    elif filename.startswith("file://"):
        resolved = filename[len("file://"):]
    else:
        resolved = os.path.join(urdf_dir, filename)
    resolved = os.path.abspath(resolved)
    if not os.path.isfile(resolved):
        fail(f"mesh {filename}: {resolved} does not exist")
    return resolved


def urdf_with_absolute_meshes(urdf_path, packages):
    """Path of a URDF Bullet can load: the file itself when it has no meshes,
    else a temporary copy whose mesh file names are absolute paths."""
    tree = ET.parse(urdf_path)
    meshes = tree.getroot().findall(".//mesh")
    if not meshes:
        return urdf_path, None
    urdf_dir = os.path.dirname(os.path.abspath(urdf_path))
    for mesh in meshes:
        mesh.set("filename", resolve_mesh(mesh.get("filename", ""), urdf_dir, packages))
    handle, tmp = tempfile.mkstemp(prefix="pybullet_reference_", suffix=".urdf")
    with os.fdopen(handle, "wb") as f:
        tree.write(f, encoding="utf-8", xml_declaration=True)
    return tmp, tmp


def load_scene(path):
    with open(path, "rb") as f:
        scene = tomllib.load(f)
    scene_dir = os.path.dirname(os.path.abspath(path))
    scene["_dir"] = scene_dir
    return scene


def schedule_targets(scene, joints, t_s):
    """Targets (degrees) of the schedule entry in force at t_s (core: Scene::targets_deg_at_tick)."""
    entry = None
    for e in scene["schedule"]:
        if e["t_s"] <= t_s + 1e-9:
            entry = e
    targets = entry.get("targets_deg", {}) if entry else {}
    return [float(targets.get(j, 0.0)) for j in joints]


def run(args):
    scene = load_scene(args.scene)
    packages = {}
    for spec in args.package:
        name, _, directory = spec.partition("=")
        if not name or not directory:
            fail(f"--package {spec}: expected NAME=DIR")
        packages[name] = os.path.abspath(directory)
    robot = scene["robot"]
    urdf = args.urdf or os.path.join(scene["_dir"], robot["urdf"])
    urdf = os.path.abspath(urdf)
    load_path, temporary = urdf_with_absolute_meshes(urdf, packages)

    client = p.connect(p.DIRECT)
    try:
        p.setPhysicsEngineParameter(
            fixedTimeStep=args.timestep, numSubSteps=0, numSolverIterations=args.solver_iterations,
            physicsClientId=client)
        p.setGravity(0, 0, -GRAVITY_M_S2, physicsClientId=client)

        # 1. The ground.
        ground = scene.get("ground")
        if ground is not None:
            shape = p.createCollisionShape(p.GEOM_PLANE, planeNormal=[0, 0, 1], physicsClientId=client)
            plane = p.createMultiBody(0.0, shape, -1, [0, 0, ground.get("height_m", 0.0)], physicsClientId=client)
            if "friction" in ground:
                p.changeDynamics(plane, -1, lateralFriction=ground["friction"], physicsClientId=client)

        # 2. The robot.
        base_rpy = [math.radians(a) for a in robot.get("base_rpy_deg", [0, 0, 0])]
        flags = 0 if args.shape_inertia else p.URDF_USE_INERTIA_FROM_FILE
        body = p.loadURDF(load_path, robot["base_position_m"], quat_from_rpy(*base_rpy),
                          useFixedBase=True, flags=flags, physicsClientId=client)
        if temporary:
            os.remove(temporary)
        joint_index = {}
        link_index = {}
        effort = {}
        for i in range(p.getNumJoints(body, physicsClientId=client)):
            info = p.getJointInfo(body, i, physicsClientId=client)
            joint_index[info[1].decode()] = i
            link_index[info[12].decode()] = i
            effort[info[1].decode()] = info[10]
        controlled = [a["joint"] for a in scene["actuator"]]
        for name in controlled:
            if name not in joint_index:
                fail(f"the robot has no joint {name}")
        for name, deg in robot.get("held_joints_deg", {}).items():
            j = joint_index[name]
            angle = math.radians(deg)
            p.resetJointState(body, j, angle, 0.0, physicsClientId=client)
            force = effort[name] if effort[name] > 0 else 1e6
            p.setJointMotorControl2(body, j, p.POSITION_CONTROL, targetPosition=angle, targetVelocity=0.0,
                                    positionGain=1.0, velocityGain=1.0, force=force, physicsClientId=client)
        indices = [joint_index[n] for n in controlled]
        if args.max_force is not None:
            forces = [args.max_force] * len(controlled)
        else:
            forces = [a.get("force_limit", 1e12) for a in scene["actuator"]]
        gains = [args.velocity_gain] * len(controlled)

        def command(velocities):
            p.setJointMotorControlArray(body, indices, p.VELOCITY_CONTROL, targetVelocities=velocities,
                                        forces=forces, velocityGains=gains, physicsClientId=client)

        command([0.0] * len(controlled))

        # 3. The objects.
        objects = {}
        for obj in scene.get("object", []):
            if obj["shape"] != "box":
                fail(f"object {obj['name']}: shape {obj['shape']} not supported")
            half = [s / 2 for s in obj["size_m"]]
            shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
            rpy = [math.radians(a) for a in obj.get("rpy_deg", [0, 0, 0])]
            uid = p.createMultiBody(obj["mass_kg"], shape, -1, obj["position_m"], quat_from_rpy(*rpy),
                                    physicsClientId=client)
            if "friction" in obj:
                p.changeDynamics(uid, -1, lateralFriction=obj["friction"], physicsClientId=client)
            objects[obj["name"]] = uid

        tracked = []
        for t in scene.get("track", []):
            if t["role"] == "wrist" and args.study_wrist:
                # What the study's PyBullet script recorded as the wrist:
                # getLinkState(arm, 6)[0:2], i.e. the centre of mass of
                # Bullet link 6 = m1n6s300_link_5 of the Kinova URDF.
                tracked.append((t["role"], "com", link_index["m1n6s300_link_5"]))
            elif "link" in t:
                if t["link"] not in link_index:
                    fail(f"track {t['role']}: the robot has no (non-root) link {t['link']}")
                tracked.append((t["role"], "link", link_index[t["link"]]))
            else:
                tracked.append((t["role"], "object", objects[t["object"]]))

        controller = scene["controller"]
        period = controller["period_s"]
        steps = round(period / args.timestep)
        if steps < 1 or abs(period / args.timestep - steps) > 1e-6 * steps:
            fail(f"period {period} s is not a whole number of {args.timestep} s timesteps")
        samples = round(scene["duration_s"] / period)
        gain = controller["gain_per_s"]
        max_speed = controller["max_speed_deg_s"]

        rows = []
        for tick in range(samples):
            t_s = tick * period
            angles = [p.getJointState(body, j, physicsClientId=client)[0] for j in indices]
            row = [t_s]
            for role, kind, uid in tracked:
                if kind == "link":
                    state = p.getLinkState(body, uid, computeForwardKinematics=1, physicsClientId=client)
                    pos, orn = link_frame(state)
                elif kind == "com":
                    state = p.getLinkState(body, uid, computeForwardKinematics=1, physicsClientId=client)
                    pos, orn = state[0], state[1]
                else:
                    pos, orn = p.getBasePositionAndOrientation(uid, physicsClientId=client)
                row += list(pos) + [orn[3], orn[0], orn[1], orn[2]]
            row += angles
            rows.append(row)
            targets = schedule_targets(scene, controlled, t_s)
            velocities = []
            for target, angle in zip(targets, angles):
                v = max(-max_speed, min(max_speed, gain * (target - math.degrees(angle))))
                velocities.append(math.radians(v))
            command(velocities)
            for _ in range(steps):
                p.stepSimulation(physicsClientId=client)
    finally:
        p.disconnect(physicsClientId=client)

    header = ["t_s"]
    for role, _, _ in tracked:
        header += [f"{role}_{c}" for c in ("x_m", "y_m", "z_m", "qw", "qx", "qy", "qz")]
    header += [f"{j}_rad" for j in controlled]
    version = metadata.version("pybullet")
    settings = (f"timestep_s={args.timestep} solver_iterations={args.solver_iterations} "
                f"max_force_n_m={'scene' if args.max_force is None else args.max_force} "
                f"velocity_gain={args.velocity_gain} inertia_from_file={not args.shape_inertia}"
                + (" wrist=centre of mass of m1n6s300_link_5 (the study's)" if args.study_wrist else ""))
    with open(args.out, "w", encoding="utf-8") as f:
        f.write(f"# generated by tools/pybullet_reference.py with pybullet {version} "
                f"(API {p.getAPIVersion()}), python {sys.version.split()[0]}\n")
        f.write(f"# scene {os.path.relpath(os.path.abspath(args.scene))}; robot {os.path.basename(urdf)}\n")
        f.write(f"# settings: {settings}\n")
        f.write(",".join(header) + "\n")
        for row in rows:
            f.write(",".join(f"{v:.10g}" for v in row) + "\n")
    print(f"wrote {len(rows)} rows to {args.out} (pybullet {version}; {settings})", file=sys.stderr)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", help="scene TOML file (assets/scenes/*.toml)")
    parser.add_argument("--urdf", help="robot URDF (default: the scene's)")
    parser.add_argument("--package", action="append", default=[], metavar="NAME=DIR",
                        help="directory of a ROS package named in package:// mesh URIs")
    parser.add_argument("--out", required=True, help="CSV file to write")
    parser.add_argument("--timestep", type=float, default=0.01, help="s (default 0.01)")
    parser.add_argument("--solver-iterations", type=int, default=50, help="default 50 (Bullet's)")
    parser.add_argument("--max-force", type=float, help="N m for every controlled joint (default: the scene's force limits)")
    parser.add_argument("--velocity-gain", type=float, default=1.0, help="Bullet motor velocityGain (default 1)")
    parser.add_argument("--study-wrist", action="store_true",
                        help="record as the wrist what the study's PyBullet script did: the centre of mass "
                             "of m1n6s300_link_5 (getLinkState(arm, 6)[0:2]), not the frame of m1n6s300_link_6")
    parser.add_argument("--shape-inertia", action="store_true",
                        help="let Bullet compute inertias from collision shapes (no URDF_USE_INERTIA_FROM_FILE)")
    run(parser.parse_args())


if __name__ == "__main__":
    main()
