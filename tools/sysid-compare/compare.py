#!/usr/bin/env python3
"""Side by side: mujoco.sysid (MuJoCo 3.17) and `realitygap tune --recordings`
on one known-truth problem (issue 26, item 5).

The problem: the independent writer's simulated KUKA iiwa recordings
(tools/fixtures/make_joint_recordings.py, truth.json). Both tools fit the
same two training episodes (1-2 of the 4) with the servo gains (kp, kd)
given as known and 21 unknowns: damping, armature and frictionloss of the 7
joints, from the same start and within the same bounds (the space
`realitygap tune` writes to space.toml). realitygap fits the command delay
too (22 unknowns); mujoco.sysid cannot (see README.md), so it is handed the
true delay.

Run with a Python that has `mujoco[sysid]==3.17.0`; see README.md.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import shutil
import statistics
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
FIELDS = ("damping", "armature", "frictionloss")

# mujoco.sysid set-ups: what it observes (MuJoCo state qpos/qvel, or
# jointpos/jointvel sensors) and how the commands reach its rollout.
VARIANTS = {
    "state": dict(
        signal="state", observe="qpos", control="zoh",
        what="joint angles read from the rolled-out state (qpos), commands shifted by the true delay and held at every 1 ms step",
    ),
    "sensor": dict(
        signal="sensor", observe="qpos", control="zoh",
        what="joint angles from jointpos sensors (mujoco.rollout returns the sensors computed before each step's integration, labelled with the time after it: one step, 1 ms, late), commands as 'state'",
    ),
    "state-vel": dict(
        signal="state", observe="qpos+qvel", control="zoh",
        what="joint angles and velocities from the state, commands as 'state'",
    ),
    "state-linear": dict(
        signal="state", observe="qpos", control="linear",
        what="joint angles from the state, the 100 Hz commands shifted by the true delay and interpolated linearly by mujoco.sysid (no zero-order hold)",
    ),
}


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, required=True, help="output folder (created)")
    p.add_argument(
        "--realitygap",
        default=os.environ.get("REALITYGAP_BIN", str(Path.home() / ".cache/realitygap/target/release/realitygap")),
        help="the realitygap binary (release build)",
    )
    p.add_argument("--fixtures", type=Path, default=ROOT / "third_party/fixtures/joint-recordings")
    p.add_argument("--urdf", type=Path, default=ROOT / "third_party/pybullet_data/kuka_iiwa/model.urdf")
    p.add_argument("--jobs", type=int, default=2, help="threads for both tools (default 2)")
    p.add_argument(
        "--sysid-run",
        action="append",
        choices=sorted(VARIANTS),
        help="a mujoco.sysid set-up to run (repeatable; default: state and sensor): "
        + "; ".join(f"'{k}': {v['what']}" for k, v in sorted(VARIANTS.items())),
    )
    p.add_argument("--skip-realitygap", action="store_true", help="reuse OUT/realitygap from an earlier run")
    p.add_argument(
        "--repeat",
        type=int,
        default=1,
        help="run every tool this many times, in turn (the fits are deterministic): the table gives the median wall time and the range",
    )
    return p.parse_args()


# ---------------------------------------------------------------------------
# Truth
# ---------------------------------------------------------------------------


def load_truth(fixtures: Path) -> dict:
    return json.loads((fixtures / "truth.json").read_text())


def true_value(truth: dict, joint: str, field: str) -> float:
    """The truth as both fits represent it: MuJoCo's implicitfast integrates a
    kv servo implicitly (M + dt kv), the writer's PD is explicit, so both
    fitted armatures are compared after adding dt kv (as
    crates/cli/tests/tune_recordings.rs does)."""
    return float(truth["joints"][joint][field])


def armature_shift(truth: dict, joint: str) -> float:
    return float(truth["timestep_s"]) * float(truth["joints"][joint]["kd"])


# ---------------------------------------------------------------------------
# realitygap
# ---------------------------------------------------------------------------


def run_realitygap(args: argparse.Namespace, truth: dict, out: Path, fit_delay: bool) -> dict:
    """`realitygap tune --recordings` on the 4 imported bags, episodes 1-2
    fitted and 3-4 held out, the gains known (and the delay, unless
    `fit_delay`)."""
    out.mkdir(parents=True, exist_ok=True)
    real = out / "real"
    tune = out / "tune"
    if real.exists():
        shutil.rmtree(real)
    if tune.exists():
        shutil.rmtree(tune)
    bags = [str(args.fixtures / f"mcap/episode_{e:03d}") for e in range(4)]
    subprocess.run(
        [args.realitygap, "import", "rosbag", *bags, "--robot", str(args.urdf), "--out", str(real)],
        check=True,
        capture_output=True,
    )
    known = out / "known.toml"
    text = "".join(f"[joints.{n}]\nkp = {j['kp']}\nkv = {j['kd']}\n" for n, j in truth["joints"].items())
    if not fit_delay:
        text += f"[controller]\ndelay_s = {truth['delay_s']}\n"
    known.write_text(text)
    cmd = [
        args.realitygap, "tune", "--recordings", str(real), "--engine", "mujoco",
        "--params", str(known), "--runs", "1-2", "--holdout", "3-4", "--out", str(tune),
        "-j", str(args.jobs),
    ]
    print("+", " ".join(cmd), flush=True)
    t0 = time.monotonic()
    run = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.monotonic() - t0
    (out / "tune.stdout").write_text(run.stdout)
    (out / "tune.stderr").write_text(run.stderr)
    if run.returncode != 0:
        raise SystemExit(f"realitygap tune failed ({run.returncode}):\n{run.stderr[-2000:]}")
    summary = json.loads((tune / "summary.json").read_text())
    params = {}
    for p in summary["params"]:
        params[p["key"]] = {
            "value": p["value"],
            "interval": p.get("interval"),
        }
    # summary.json counts every replay of the training episodes (the delay
    # scan, each Jacobian column, the secant and rejected steps, the
    # delay's profile); its search_time_s ends at the intervals, while the
    # process also scores the episodes and runs the timestep check.
    return {
        "params": params,
        "wall_s": float(summary.get("search_time_s", summary["wall_time_s"])),
        "process_wall_s": wall,
        "evaluations": int(summary["evaluations"]),
        "iterations": summary.get("iterations"),
        "reason": summary.get("reason"),
        "summary": summary,
        "command": cmd,
    }


# ---------------------------------------------------------------------------
# mujoco.sysid
# ---------------------------------------------------------------------------


def urdf_text(urdf: Path) -> str:
    text = urdf.read_text()
    block = (
        f'<mujoco><compiler meshdir="{urdf.parent.resolve()}" strippath="false" discardvisual="true" '
        'balanceinertia="false" fusestatic="false" angle="radian"/></mujoco>'
    )
    text, n = re.subn(r"(<robot\b[^>]*>)", lambda m: m.group(1) + block, text, count=1)
    if n != 1:
        raise SystemExit(f"no <robot> element in {urdf}")
    return text


def sysid_spec(args: argparse.Namespace, truth: dict, start: dict):
    """The writer's model as a mujoco.sysid user builds it: the URDF, the
    writer's options, the start values of the unknowns, and a position
    actuator per joint with the known kp and kv (MuJoCo's own servo,
    integrated implicitly by implicitfast), jointpos and jointvel sensors."""
    import mujoco

    spec = mujoco.MjSpec.from_string(urdf_text(args.urdf))
    joints = list(truth["joint_order"])
    if [j.name for j in spec.joints] != joints:
        raise SystemExit(f"unexpected joints {[j.name for j in spec.joints]}")
    for joint in spec.joints:
        d = np.zeros_like(np.asarray(joint.damping, dtype=float))
        d.flat[0] = start[(joint.name, "damping")]
        joint.damping = d if d.ndim else float(d)
        joint.armature = start[(joint.name, "armature")]
        joint.frictionloss = start[(joint.name, "frictionloss")]
    for geom in spec.geoms:
        geom.contype = 0
        geom.conaffinity = 0
    spec.option.timestep = float(truth["timestep_s"])
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.gravity = [0.0, 0.0, -9.81]
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    for name in joints:
        j = truth["joints"][name]
        act = spec.add_actuator(name=f"{name}_servo", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=float(j["kp"]), kv=float(j["kd"]))
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-float(j["effort_limit"]), float(j["effort_limit"])]
    for name in joints:
        spec.add_sensor(name=f"{name}_pos", type=mujoco.mjtSensor.mjSENS_JOINTPOS, objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=name)
    for name in joints:
        spec.add_sensor(name=f"{name}_vel", type=mujoco.mjtSensor.mjSENS_JOINTVEL, objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=name)
    return spec, joints


def read_episode(fixtures: Path, e: int, joints: list[str]):
    with open(fixtures / f"csv/episode_{e:03d}.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    t = np.array([float(r["time_s"]) for r in rows])
    q = np.array([[float(r[f"/joint_states/{n}/position"]) for n in joints] for r in rows])
    v = np.array([[float(r[f"/joint_states/{n}/velocity"]) for n in joints] for r in rows])
    # The CSV's command column is the command in force at the row (200 Hz);
    # the 100 Hz commands are the even rows.
    cmd = np.array([[float(r[f"{n}/position_command"]) for n in joints] for r in rows[::2]])
    return t, q, v, cmd


def run_sysid(args: argparse.Namespace, variant: str, truth: dict, bounds: dict, start: dict) -> dict:
    import mujoco
    from mujoco import sysid

    var = VARIANTS[variant]
    spec, joints = sysid_spec(args, truth, start)
    model = spec.compile()
    dt = float(truth["timestep_s"])
    delay = float(truth["delay_s"])
    cmd_dt = 1.0 / float(truth["command_rate_hz"])
    initial, controls, sensors, names = [], [], [], []
    for e in (0, 1):  # episodes 1-2, as `--runs 1-2`
        t, q, v, cmd = read_episode(args.fixtures, e, joints)
        duration = t[-1]
        if var["control"] == "zoh":
            # The writer's servo: at step k (t = k dt) the latest command whose
            # time is <= t - delay, held. Integer step arithmetic.
            steps = int(round(duration / dt)) + 1
            per_cmd = int(round(cmd_dt / dt))
            lag = int(round(delay / dt))
            idx = np.clip((np.arange(steps) - lag) // per_cmd, 0, len(cmd) - 1)
            ctrl_t = np.arange(steps) * dt
            ctrl = cmd[idx]
        else:
            # The recorded commands shifted by the delay; mujoco.sysid then
            # interpolates them linearly at every step.
            ctrl_t = np.concatenate([[0.0], np.arange(len(cmd)) * cmd_dt + delay])
            ctrl = np.vstack([cmd[:1], cmd])
            keep = ctrl_t <= duration + 1e-12
            ctrl_t, ctrl = ctrl_t[keep], ctrl[keep]
        controls.append(sysid.TimeSeries(ctrl_t, ctrl))
        if var["signal"] == "sensor":
            sensors.append(sysid.TimeSeries.from_names(t, np.hstack([q, v]), model))
        else:
            sensors.append(
                sysid.TimeSeries.from_names(
                    t, np.hstack([q, v]), model, names=[f"{n}_qpos" for n in joints] + [f"{n}_qvel" for n in joints]
                )
            )
        initial.append(sysid.create_initial_state(model, q[0], v[0]))
        names.append(f"episode_{e + 1}")
    ms = sysid.ModelSequences("iiwa", spec, names, initial, controls, sensors)

    params = sysid.ParameterDict()
    keys = []
    for name in joints:
        for field in FIELDS:
            key = f"joints.{name}.{field}"
            lo, hi = bounds[(name, field)]

            def modifier(s, p, n=name, fld=field):
                joint = s.joint(n)
                if fld == "damping":
                    d = np.zeros_like(np.asarray(joint.damping, dtype=float))
                    d.flat[0] = p.value[0]
                    joint.damping = d if d.ndim else float(d)
                else:
                    setattr(joint, fld, float(p.value[0]))

            params.add(sysid.Parameter(key, nominal=start[(name, field)], min_value=lo, max_value=hi, modifier=modifier))
            keys.append(key)

    if var["signal"] == "sensor":
        observe = [(f"{n}_pos", sysid.SignalType.MjSensor) for n in joints]
        if var["observe"] == "qpos+qvel":
            observe += [(f"{n}_vel", sysid.SignalType.MjSensor) for n in joints]
    else:
        observe = [(f"{n}_qpos", sysid.SignalType.MjStateQPos) for n in joints]
        if var["observe"] == "qpos+qvel":
            observe += [(f"{n}_qvel", sysid.SignalType.MjStateQVel) for n in joints]
    inner = sysid.build_residual_fn(models_sequences=[ms], n_threads=args.jobs, enabled_observations=observe)
    counter = {"vectors": 0, "calls": 0}

    def residual_fn(x, p, **kw):
        counter["calls"] += 1
        counter["vectors"] += 1 if np.ndim(x) == 1 else np.shape(x)[1]
        return inner(x, p, **kw)

    t0 = time.monotonic()
    opt_params, result = sysid.optimize(initial_params=params, residual_fn=residual_fn, optimizer="mujoco", verbose=False)
    wall = time.monotonic() - t0
    vectors = counter["vectors"]
    # Intervals as mujoco.sysid computes them (save_results does the same):
    # the residuals at the optimum and the Jacobian of the last iteration.
    residuals, _, _ = inner(opt_params.as_vector(), opt_params.copy())
    _, half = sysid.calculate_intervals(residuals, np.asarray(result.jac))
    x = opt_params.as_vector()
    iterations = len(result.extras.get("objective", [])) if hasattr(result, "extras") else None
    fitted = {
        k: {"value": float(x[i]), "interval": [float(x[i] - half[i]), float(x[i] + half[i])]}
        for i, k in enumerate(keys)
    }
    return {
        "params": fitted,
        "wall_s": wall,
        "evaluations": vectors,
        "iterations": iterations,
        "variant": variant,
        "setup": var["what"],
    }


# ---------------------------------------------------------------------------
# Scoring and the table
# ---------------------------------------------------------------------------


def score(fit: dict, truth: dict) -> dict:
    rows = []
    for name in truth["joint_order"]:
        for field in FIELDS:
            key = f"joints.{name}.{field}"
            p = fit["params"][key]
            shift = armature_shift(truth, name) if field == "armature" else 0.0
            want = true_value(truth, name, field)
            got = p["value"] + shift
            lo, hi = (p["interval"][0] + shift, p["interval"][1] + shift) if p.get("interval") else (math.nan, math.nan)
            rows.append(
                {
                    "key": key,
                    "truth": want,
                    "fitted": got,
                    "rel_error": abs(got - want) / want,
                    "interval": [lo, hi],
                    "covers": bool(lo <= want <= hi),
                }
            )
    delay = fit["params"].get("controller.delay_s")
    if delay is not None:
        want = float(truth["delay_s"])
        lo, hi = delay["interval"] if delay.get("interval") else (math.nan, math.nan)
        rows.append(
            {
                "key": "controller.delay_s",
                "truth": want,
                "fitted": delay["value"],
                "rel_error": abs(delay["value"] - want) / want,
                "interval": [lo, hi],
                "covers": bool(lo <= want <= hi),
            }
        )
    return rows


def wall_text(s: dict) -> str:
    """The median wall time, with the range when a tool ran more than once."""
    times = s.get("wall_all_s") or [s["wall_s"]]
    if len(times) < 2:
        return f"{s['wall_s']:.1f}"
    return f"{s['wall_s']:.1f} ({min(times):.1f}-{max(times):.1f}, {len(times)} runs)"


def summarize(name: str, fit: dict, rows: list[dict]) -> dict:
    joint_rows = [r for r in rows if r["key"].startswith("joints.")]
    errs = [r["rel_error"] for r in joint_rows]
    worst = max(joint_rows, key=lambda r: r["rel_error"])
    by_field = {
        f: max(r["rel_error"] for r in joint_rows if r["key"].endswith("." + f)) for f in FIELDS
    }
    delay = next((r for r in rows if r["key"] == "controller.delay_s"), None)
    return {
        "tool": name,
        "unknowns": len(rows),
        "max_rel_error": max(errs),
        "median_rel_error": statistics.median(errs),
        "worst": worst["key"],
        "max_rel_error_by_field": by_field,
        "covered": sum(r["covers"] for r in rows),
        "median_rel_halfwidth": statistics.median(
            (r["interval"][1] - r["interval"][0]) / 2 / r["truth"] for r in joint_rows
        ),
        "delay": delay,
        "evaluations": fit["evaluations"],
        "wall_s": fit["wall_s"],
        "wall_all_s": fit.get("wall_all_s", [fit["wall_s"]]),
    }


def markdown(summaries: list[dict], notes: dict) -> str:
    lines = [
        "| tool | unknowns | max rel. error (21 joint params) | median rel. error | worst | max by field (damping / armature / frictionloss) | 95 % intervals covering the truth | median interval half-width (rel. to truth) | delay | evaluations (parameter vectors) | wall time, s |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for s in summaries:
        by = s["max_rel_error_by_field"]
        if s["delay"] is None:
            delay = "known: true 20 ms" if s["tool"].startswith("realitygap") else "not modelled (given: true 20 ms)"
        else:
            d = s["delay"]
            delay = f"fitted {d['fitted'] * 1e3:.2f} ms [{d['interval'][0] * 1e3:.2f}, {d['interval'][1] * 1e3:.2f}]"
        lines.append(
            f"| {s['tool']} | {s['unknowns']} | {100 * s['max_rel_error']:.2f} % | {100 * s['median_rel_error']:.2f} % "
            f"| {s['worst'].removeprefix('joints.')} | {100 * by['damping']:.2f} / {100 * by['armature']:.2f} / {100 * by['frictionloss']:.2f} % "
            f"| {s['covered']} of {s['unknowns']} | {100 * s['median_rel_halfwidth']:.2f} % | {delay} | {s['evaluations']} | {wall_text(s)} |"
        )
    lines.append("")
    for k, v in notes.items():
        lines.append(f"- {k}: {v}")
    return "\n".join(lines) + "\n"


def main() -> None:
    args = parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    truth = load_truth(args.fixtures)
    rg_out = args.out / "realitygap"
    rgs: dict[str, dict] = {}
    walls: dict[str, list[float]] = {}
    repeats = max(1, args.repeat)

    def realitygap_runs(rep: int) -> None:
        for name, fit_delay in (("realitygap", True), ("realitygap-delay-known", False)):
            if args.skip_realitygap:
                rg = json.loads((args.out / f"{name}.json").read_text())
            else:
                rg = run_realitygap(args, truth, args.out / name, fit_delay)
                rg.pop("summary")
                (args.out / f"{name}.json").write_text(json.dumps(rg, indent=1))
            print(f"{name} (run {rep + 1}): {rg['evaluations']} evaluations, {rg['wall_s']:.1f} s", flush=True)
            walls.setdefault(name, []).extend(rg.get("wall_all_s", [rg["wall_s"]]))
            rgs[name] = rg

    realitygap_runs(0)
    # The same space for mujoco.sysid: realitygap's bounds and start values.
    space = tomllib.loads((rg_out / "tune/space.toml").read_text())["params"]
    bounds, start = {}, {}
    for name in truth["joint_order"]:
        for field in FIELDS:
            s = space[f"joints.{name}.{field}"]
            bounds[(name, field)] = (float(s["low"]), float(s["high"]))
            start[(name, field)] = float(s["start"])

    # The tools in turn, run after run, so that a drift of the machine's
    # speed reaches both alike.
    variants = args.sysid_run or ["state", "sensor"]
    sysid: dict[str, dict] = {}
    sysid_walls: dict[str, list[float]] = {v: [] for v in variants}
    for rep in range(repeats):
        if rep > 0 and not args.skip_realitygap:
            realitygap_runs(rep)
        for variant in variants:
            sy = run_sysid(args, variant, truth, bounds, start)
            print(f"mujoco.sysid ({variant}, run {rep + 1}): {sy['evaluations']} parameter vectors, {sy['wall_s']:.1f} s", flush=True)
            sysid_walls[variant].append(sy["wall_s"])
            sysid[variant] = sy
    for name, rg in rgs.items():
        rg["wall_all_s"] = walls[name]
        rg["wall_s"] = statistics.median(walls[name])

    rg_rows = {name: score(rg, truth) for name, rg in rgs.items()}
    summaries = [
        summarize("realitygap tune --recordings (mujoco), delay fitted", rgs["realitygap"], rg_rows["realitygap"]),
        summarize(
            "realitygap tune --recordings (mujoco), delay known",
            rgs["realitygap-delay-known"],
            rg_rows["realitygap-delay-known"],
        ),
    ]
    peers = {}
    for variant in variants:
        sy = sysid[variant]
        sy["wall_all_s"] = sysid_walls[variant]
        sy["wall_s"] = statistics.median(sysid_walls[variant])
        rows = score(sy, truth)
        summaries.append(summarize(f"mujoco.sysid 3.17 ({variant})", sy, rows))
        peers[variant] = {k: v for k, v in sy.items() if k != "params"} | {"params": rows}
    notes = {
        "problem": "the writer's simulated iiwa (truth.json), episodes 1-2 fitted (2 x 10 s, 200 Hz joint states, 100 Hz commands), kp and kd known",
        "armature": "compared as fitted + dt kd (both use MuJoCo's implicitfast, which integrates the kv servo implicitly; the writer's PD is explicit)",
        "evaluations": "realitygap: summary.json's count (every replay of both training episodes: delay scan, Jacobian columns, secant and rejected steps, the delay's profile); mujoco.sysid: parameter vectors passed to its residual (each rolls out both episodes)",
        "wall time": "realitygap: the search as summary.json reports it (search_time_s: the scores and the timestep check excluded); mujoco.sysid: sysid.optimize only",
        "machine": f"{os.cpu_count()} cores, shared with other work; {args.jobs} threads/jobs for each tool, both at the script's priority (nice {os.nice(0)})",
    }
    for variant in peers:
        notes[f"mujoco.sysid ({variant})"] = VARIANTS[variant]["what"]
    table = markdown(summaries, notes)
    print()
    print(table)
    (args.out / "table.md").write_text(table)
    (args.out / "results.json").write_text(
        json.dumps(
            {
                "summaries": summaries,
                "realitygap": {
                    name: {k: v for k, v in rg.items() if k != "params"} | {"params": rg_rows[name]}
                    for name, rg in rgs.items()
                },
                "mujoco_sysid": peers,
                "notes": notes,
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
