"""The floor under any Python adapter's replay: what a Python loop costs
when the commands change every step, without the protocol.

A 7-joint serial arm (capsules, position servos) in MuJoCo at 1 ms,
10 000 steps, best of 5 wall times:

- ``rollout``: MuJoCo's own loop in C (its rollout: the commands of every
  step given at once, the states and the tip's pose, as sensors,
  recorded at every step), with the iiwa pattern's commands below: what
  a linked engine's loop costs, near enough, and how the SDK's MuJoCo
  adapter takes a replay (``run_open_loop``); the base of the ratios;
- ``nstep_at_rest``: ``mj_step(m, d, nstep=N)`` with the servos at 0 and
  the arm at rest: a step of an arm at rest costs less (MuJoCo's own
  loop either way);
- ``commands``: a Python loop that writes the step's commands and steps;
- ``commands_and_state``: the same, and reads the joint state back each
  step (what a replay does where the recording samples every step);
- ``iiwa_pattern``: the schedule of the protocol bench's iiwa replay
  (``cargo bench -p realitygap --bench protocol``): the recording samples
  every 5 steps and commands every 10, so the loop steps 5 at a time
  (``nstep=5``), reads the joint state and one body's pose (its
  kinematics brought to the step's end) before each, and writes the
  commands before every other.

Prints each time, microseconds per step and the ratio to ``rollout``: an
adapter that steps from Python cannot replay such a recording faster
than its ratio over the linked engine; one that hands the schedule to
its engine's own loop can come near 1.

Each case runs twice: with the timer that MuJoCo's Python bindings
install at import (``mjcb_time``: the clock read at every stage of every
step, for ``mjData.timer``), then without it, as the SDK's MuJoCo adapter
and a program linking MuJoCo run (``timers_off`` in
python/realitygap_engine/adapters/mujoco.py).

    ~/.cache/realitygap/fixtures-venv/bin/python crates/cli/benches/protocol_floor.py
"""
import os
import sys
import time

import mujoco
import numpy as np
from mujoco import _rollout

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..", "python"))
from realitygap_engine.adapters.mujoco import timers_off  # noqa: E402

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
    sensors = '<framepos objtype="xbody" objname="tip"/><framequat objtype="xbody" objname="tip"/>'
    bodies = bodies.replace('<body pos="0 0 0.15">', '<body name="tip" pos="0 0 0.15">', 7)
    bodies = bodies.replace('<body name="tip" pos="0 0 0.15">', '<body pos="0 0 0.15">', 6)
    return mujoco.MjModel.from_xml_string(
        f'<mujoco><option timestep="0.001"/><worldbody>{bodies}{closes}</worldbody>'
        f"<actuator>{servos}</actuator><sensor>{sensors}</sensor></mujoco>")


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

    full = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
    roller = _rollout.Rollout(nthread=0)
    states = np.empty((1, STEPS, mujoco.mj_stateSize(m, full)))
    sensors = np.empty((1, STEPS, m.nsensordata))

    def rollout() -> None:
        control = np.ascontiguousarray(np.repeat(commands[::10], 10, axis=0)[None, :STEPS])
        start = np.empty(states.shape[2])
        mujoco.mj_getState(m, d, start, full)
        roller.rollout([m], [d], STEPS, int(mujoco.mjtState.mjSTATE_CTRL), start[None], d.qacc_warmstart[None].copy(),
                       control, states, sensors, None)
        # The iiwa pattern's readings: the state before every fifth step
        # (after the step before it), the pose the sensors' of that step.
        reads[0, :2 * m.nv] = start[1:1 + 2 * m.nv]
        reads[1:, :2 * m.nv] = states[0, 4:-1:5, 1:1 + 2 * m.nv]
        reads[:, 2 * m.nv:] = sensors[0, ::5]

    def best(f) -> float:
        times = []
        for _ in range(REPEATS):
            mujoco.mj_resetData(m, d)
            t = time.perf_counter()
            f()
            times.append(time.perf_counter() - t)
        return min(times)

    cases = (("rollout", rollout), ("nstep_at_rest", nstep), ("commands", with_commands),
             ("commands_and_state", with_commands_and_state), ("iiwa_pattern", iiwa_pattern))
    print(f"MuJoCo {mujoco.__version__}, 7-joint arm at 1 ms, {STEPS} steps, best of {REPEATS}")
    for timer in ("on", "off"):
        if timer == "off" and not timers_off():
            break
        print(f"the bindings' timer {timer}:")
        base = best(rollout)
        for name, f in cases:
            b = base if f is rollout else best(f)
            print(f"{name:>20}: {b * 1e3:7.1f} ms  {b / STEPS * 1e6:5.2f} us/step  {b / base:4.2f}x")


if __name__ == "__main__":
    main()
