"""The floor under any Python adapter's replay: what a Python loop costs
when the commands change every step, without the protocol.

A 7-joint serial arm (capsules, position servos) in MuJoCo at 1 ms,
10 000 steps, three ways, best of 5 wall times:

- ``nstep``: ``mj_step(m, d, nstep=N)``, MuJoCo's own loop in C (what a
  linked engine's loop costs, near enough);
- ``commands``: a Python loop that writes the step's commands and steps;
- ``commands_and_state``: the same, and reads the joint state back each
  step (what a replay does where the recording samples every step);
- ``iiwa_pattern``: the schedule of the protocol bench's iiwa replay
  (``cargo bench -p realitygap --bench protocol``): the recording samples
  every 5 steps and commands every 10, so the loop steps 5 at a time
  (``nstep=5``), reads the joint state and one body's pose (its
  kinematics brought to the step's end) before each, and writes the
  commands before every other.

Prints each time, microseconds per step and the ratio to ``nstep``: no
out-of-process adapter written in Python can replay such a recording
faster than its ratio over the linked engine.

    ~/.cache/realitygap/fixtures-venv/bin/python crates/cli/benches/protocol_floor.py
"""
import time

import mujoco
import numpy as np

STEPS = 10_000
REPEATS = 5


def arm() -> mujoco.MjModel:
    bodies, closes = "", ""
    for i in range(7):
        axis = "0 0 1" if i % 2 == 0 else "0 1 0"
        bodies += (f'<body pos="0 0 0.15"><joint name="j{i}" axis="{axis}" damping="0.5" armature="0.01"/>'
                   '<geom type="capsule" fromto="0 0 0 0 0 0.15" size="0.04" mass="2"/>')
        closes += "</body>"
    servos = "".join(f'<position joint="j{i}" kp="300" kv="20"/>' for i in range(7))
    return mujoco.MjModel.from_xml_string(
        f'<mujoco><option timestep="0.001"/><worldbody>{bodies}{closes}</worldbody>'
        f"<actuator>{servos}</actuator></mujoco>")


def main() -> None:
    m = arm()
    d = mujoco.MjData(m)
    commands = 0.3 * np.sin(np.linspace(0.0, 10.0, STEPS))[:, None] * np.ones(m.nu)
    state = np.empty((STEPS, 2 * m.nv))

    def nstep() -> None:
        mujoco.mj_step(m, d, nstep=STEPS)

    def with_commands() -> None:
        for k in range(STEPS):
            d.ctrl[:] = commands[k]
            mujoco.mj_step(m, d)

    def with_commands_and_state() -> None:
        for k in range(STEPS):
            d.ctrl[:] = commands[k]
            mujoco.mj_step(m, d)
            state[k, :m.nv] = d.qpos
            state[k, m.nv:] = d.qvel

    tip = m.nbody - 1
    reads = np.empty((STEPS // 5, 2 * m.nv + 7))

    def iiwa_pattern() -> None:
        for k in range(STEPS // 5):
            mujoco.mj_kinematics(m, d)
            reads[k, :m.nv] = d.qpos
            reads[k, m.nv:2 * m.nv] = d.qvel
            reads[k, 2 * m.nv:2 * m.nv + 3] = d.xpos[tip]
            reads[k, 2 * m.nv + 3:] = d.xquat[tip]
            if k % 2 == 0:
                d.ctrl[:] = commands[5 * k]
            mujoco.mj_step(m, d, nstep=5)

    def best(f) -> float:
        times = []
        for _ in range(REPEATS):
            mujoco.mj_resetData(m, d)
            t = time.perf_counter()
            f()
            times.append(time.perf_counter() - t)
        return min(times)

    base = best(nstep)
    print(f"MuJoCo {mujoco.__version__}, 7-joint arm at 1 ms, {STEPS} steps, best of {REPEATS}")
    for name, f in (("nstep", nstep), ("commands", with_commands),
                    ("commands_and_state", with_commands_and_state), ("iiwa_pattern", iiwa_pattern)):
        b = base if f is nstep else best(f)
        print(f"{name:>20}: {b * 1e3:7.1f} ms  {b / STEPS * 1e6:5.2f} us/step  {b / base:4.2f}x")


if __name__ == "__main__":
    main()
