"""The Python package against the ``realitygap`` command: each API call,
the table equal to the command's, errors as exceptions with the command's
messages, an interrupted run keeping its finished runs, and MuJoCo loaded
from the ``mujoco`` wheel."""

import io
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import realitygap as rg


def finished(d: Path):
    m = d / "manifest.json"
    if not m.is_file():
        return []
    try:
        runs = json.loads(m.read_text())["runs"]
    except (ValueError, KeyError):
        return []
    return [r["id"] for r in runs if r["status"] == "ok"]


# ------------------------------------------------------------ the wheel


def test_imported_from_the_installed_wheel_not_the_source_tree(root):
    package = Path(rg.__file__).resolve().parent
    assert root.resolve() not in package.parents, package
    assert "site-packages" in package.parts
    # The scenes and the study ship inside the package.
    assert Path(rg.builtin_study()).is_file()
    assert Path(rg.builtin_study()).resolve().is_relative_to(package)
    assert rg.__version__


def test_mujoco_is_loaded_from_the_mujoco_wheel():
    import importlib.util

    mujoco_dir = Path(importlib.util.find_spec("mujoco").submodule_search_locations[0]).resolve()
    ours = Path(rg.__file__).resolve().parent
    # The wheel ships no copy.
    assert not [p for p in ours.rglob("libmujoco*")], "a libmujoco inside the realitygap package"
    # The one mapped in this process is the mujoco wheel's.
    maps = Path("/proc/self/maps").read_text().splitlines()
    loaded = {Path(line.split()[-1]).resolve() for line in maps if "libmujoco" in line}
    assert loaded == {mujoco_dir / "libmujoco.so.3.17.0"}, loaded
    assert Path(rg.MUJOCO_LIBRARY).resolve() == mujoco_dir / "libmujoco.so.3.17.0"
    # And a simulation in MuJoCo works with it.
    names = [e.name for e in rg.engines()]
    assert "mujoco" in names


# ------------------------------------------------------------ engines


def test_engines_lists_every_engine_of_the_command(cli):
    engines = rg.engines()
    names = [e.name for e in engines]
    for e in ["mujoco", "ode", "rapier", "bullet", "physx", "dart", "ideal"]:
        assert e in names, names
    mujoco = engines[names.index("mujoco")]
    assert "3.17.0" in mujoco.version, mujoco.version
    assert mujoco.default_timestep_s > 0
    assert mujoco.params and mujoco.commands
    listing = cli("engines").stdout
    for e in engines:
        assert e.name in listing


# ------------------------------------------------------------ compare


def test_compare_table_equals_the_commands_table_csv(cli, tmp_path):
    cmp = rg.compare(rg.builtin_study(), progress=False)
    expected = cli("compare", rg.builtin_study(), "--format", "csv").stdout
    assert cmp.csv == expected
    table = cmp.table
    pd.testing.assert_frame_equal(table, pd.read_csv(io.StringIO(expected)))
    # Interval columns, every scene and source of the study.
    assert any("low" in c or "interval" in c for c in table.columns), list(table.columns)
    assert len(table) >= 7
    assert "MuJoCo" in table.to_string()


def test_compare_with_the_physics_free_rows_equals_the_command(cli, tmp_path):
    fitted = tmp_path / "fitted.toml"
    fitted.write_text("[controller]\ndelay_s = 0.05\n\n[actuator]\nfrequency_rad_s = 20.0\ndamping_ratio = 0.5\n")
    cmp = rg.compare(rg.builtin_study(), physics_free=fitted, progress=False)
    expected = cli(
        "compare", rg.builtin_study(), "--physics-free", str(fitted), "--format", "csv"
    ).stdout
    assert cmp.csv == expected
    sources = set(cmp.table["source"])
    assert {"physics-free (this tool)", "physics-free (tuned)"} <= sources, sources
    plain = rg.compare(rg.builtin_study(), physics_free=True, progress=False)
    assert "physics-free (this tool)" in plain.csv and "physics-free (tuned)" not in plain.csv
    # Perfect tracking is a row by default; False leaves both out, as the
    # command's --no-physics-free does.
    assert rg.compare(rg.builtin_study(), progress=False).csv == plain.csv
    none = rg.compare(rg.builtin_study(), physics_free=False, progress=False)
    assert "physics-free" not in none.csv
    assert none.csv == cli("compare", rg.builtin_study(), "--no-physics-free", "--format", "csv").stdout


def test_compare_measures_and_series():
    cmp = rg.compare(series=True, progress=False)
    m = cmp.measures
    assert {"scene", "source", "role"} <= set(m.columns)
    assert set(m["scene"]) >= {"scene1_single_joint", "scene2_two_joints", "scene3_cube_push"}
    assert (m["role"] == "reference").sum() == 3
    assert "accumulated_error_interval_m.low_m" in m.columns
    assert "accumulated_error_interval_m" not in m.columns
    s = cmp.series("scene2_two_joints")
    assert s.index.name == "t_s" and len(s) > 10
    assert "MuJoCo" in s.columns
    assert np.isfinite(s["MuJoCo"].to_numpy()).any()
    assert cmp.markdown in repr(cmp)


# ------------------------------------------------------------ run, load_run


def test_run_scene1_equals_the_command_and_loads_as_numpy(cli, tmp_path):
    batch = rg.run("scene1", "mujoco", out=tmp_path / "py", progress=False)
    assert len(batch.dirs) == 1
    g = batch.groups
    assert list(g["ok"]) == [1] and list(g["engine"]) == ["mujoco"]
    run = batch.load()
    assert run.status == "ok"
    assert len(run) > 100
    assert run.position().shape == (len(run), 3)
    assert run.pose().shape == (len(run), 7)
    assert np.all(np.diff(run.time_s) > 0)
    assert list(run.frame.columns)[0] == "t_s"
    # The command's run of the same scene: the same trajectory, to the byte.
    cli("run", rg.scene_file("scene1"), "--engine", "mujoco", "--out", tmp_path / "cli")
    ours = Path(batch.dirs[0]) / "runs" / ("%s.csv" % run.id)
    theirs = tmp_path / "cli" / "scene1_single_joint" / "mujoco" / "runs" / ("%s.csv" % run.id)
    assert ours.read_bytes() == theirs.read_bytes()
    # load_run on a run's CSV file too.
    again = rg.load_run(theirs)
    np.testing.assert_array_equal(again.position(), run.position())


def test_run_with_params_as_a_dict(tmp_path):
    joint = "m1n6s300_joint_2"
    batch = rg.run(
        "scene1", "mujoco", out=tmp_path, params={"joints": {joint: {"damping": 0.5}}}, progress=False
    )
    assert list(batch.groups["ok"]) == [1]
    assert list(tmp_path.glob("params-*.toml"))


def test_interrupted_run_keeps_its_finished_runs(tmp_path):
    # Ctrl-C arrives while the first finished run is being reported: the
    # reporter raises SIGINT in its own process, Python's handler turns it
    # into KeyboardInterrupt there, and the batch starts no further run
    # (a worker takes its next job only once its run is stored and
    # reported), so exactly one run is kept, whatever the machine's load.
    out = tmp_path / "runs"
    script = textwrap.dedent(
        """
        import signal, sys, realitygap as rg
        from realitygap._progress import Reporter

        # A process started in the background by a shell without job
        # control (nohup, a CI runner's `cmd &`) inherits SIGINT ignored,
        # and Python then installs no KeyboardInterrupt handler: the
        # Ctrl-C below would do nothing. Install Python's own.
        signal.signal(signal.SIGINT, signal.default_int_handler)

        class CtrlCAfterFirstRun(Reporter):
            def inc(self, id, n):
                signal.raise_signal(signal.SIGINT)

        try:
            rg.run("scene2", "mujoco", out=sys.argv[1], repeats=12, jobs=1, perturb={"sensor_noise_deg": 0.1}, progress=CtrlCAfterFirstRun(False))
        except KeyboardInterrupt as e:
            print("interrupted:", e, flush=True)
            sys.exit(3)
        print("finished", flush=True)
        """
    )
    p = subprocess.run([sys.executable, "-c", script, str(out)], capture_output=True, text=True, timeout=600)
    d = out / "scene2_two_joints" / "mujoco"
    stdout, stderr = p.stdout, p.stderr
    assert p.returncode == 3, (stdout, stderr)
    assert "interrupted" in stdout
    assert "runs finished before are kept" in stdout, stdout
    kept = finished(d)
    assert len(kept) == 1, kept
    # The finished runs are whole and load; no child is left.
    for id in kept:
        assert len(rg.load_run(d, id)) > 100
    # A rerun completes the rest (two at a time: nothing interrupts it)
    # and leaves the kept ones untouched.
    before = {id: (d / "runs" / ("%s.csv" % id)).read_bytes() for id in kept}
    batch = rg.run("scene2", "mujoco", out=out, repeats=12, jobs=2, perturb={"sensor_noise_deg": 0.1}, progress=False)
    g = batch.groups.iloc[0]
    assert (g["ok"], g["kept"]) == (12 - len(kept), len(kept)), batch.groups
    assert len(finished(d)) == 12
    for id, data in before.items():
        assert (d / "runs" / ("%s.csv" % id)).read_bytes() == data


# ------------------------------------------------------------ errors


def test_errors_are_exceptions_with_the_commands_messages(cli, tmp_path):
    missing = tmp_path / "no-such-study.toml"
    with pytest.raises(rg.RealityGapError) as e:
        rg.compare(missing, progress=False)
    p = cli("compare", missing, check=False)
    assert p.returncode != 0
    message = p.stderr.strip().splitlines()[-1]
    assert message.startswith("error: ")
    assert str(e.value) == message[len("error: "):]
    assert str(missing) in str(e.value)

    bad = tmp_path / "bad.toml"
    bad.write_text("[joints.m1n6s300_joint_2]\ndamping = -1\n")
    with pytest.raises(rg.RealityGapError) as e:
        rg.run("scene1", "mujoco", out=tmp_path / "o", params=bad, progress=False)
    p = cli("run", rg.scene_file("scene1"), "--engine", "mujoco", "--out", tmp_path / "o2", "--params", bad, check=False)
    assert p.returncode != 0
    assert str(e.value) in p.stderr
    assert "bad.toml" in str(e.value)

    # A system error that its error type prints and also hands on as its
    # cause: once, as the command prints it.
    scene = Path(rg.scene_file("scene1"))
    text = scene.read_text()
    assert 'urdf = "../robots/mico2/mico2.urdf"' in text
    no_urdf = tmp_path / "no-urdf.toml"
    no_urdf.write_text(text.replace('urdf = "../robots/mico2/mico2.urdf"', 'urdf = "nope.urdf"'))
    with pytest.raises(rg.RealityGapError) as e:
        rg.run(no_urdf, "mujoco", out=tmp_path / "o4", progress=False)
    p = cli("run", no_urdf, "--engine", "mujoco", "--out", tmp_path / "o5", check=False)
    assert p.returncode != 0
    assert str(e.value).endswith(p.stderr.strip().splitlines()[-1].split("nope.urdf", 1)[1])
    assert str(e.value).count("No such file or directory") == 1, str(e.value)

    with pytest.raises(rg.RealityGapError, match="no-such-engine"):
        rg.run("scene1", "no-such-engine", out=tmp_path / "o3", progress=False)
    with pytest.raises(rg.RealityGapError, match="no shipped scene"):
        rg.scene_file("no-such-scene")
    with pytest.raises(rg.RealityGapError):
        rg.load_run(tmp_path / "nothing-here")


# ------------------------------------------------------------ tune


def test_tune_briefly_gives_params_summary_history_intervals(tmp_path):
    t = rg.tune("ideal", out=tmp_path / "tune", budget=8, jobs=2, progress=False)
    assert isinstance(t.params, dict) and t.params
    assert Path(t.params_file).is_file()
    h = t.history
    assert len(h) >= 8
    s = t.summary
    assert {"set", "scene", "untuned_m", "tuned_m"} <= set(s.columns)
    assert "Total" in set(s["scene"])
    assert t.intervals is not None and len(t.intervals) > 0
    assert len(t.parameters) > 0
    assert t.markdown


def test_tune_refuses_a_pull_it_cannot_honour(tmp_path):
    # prior_weight reaches the command's checks: negative, or with no
    # physics-free row to pull toward (the physics-free model itself).
    with pytest.raises(rg.RealityGapError, match=r"--prior-weight -1: expected a finite number >= 0"):
        rg.tune("mujoco", out=tmp_path / "a", prior_weight=-1.0, budget=4, progress=False)
    with pytest.raises(rg.RealityGapError, match="--prior-weight pulls toward the physics-free model"):
        rg.tune("ideal", out=tmp_path / "b", prior_weight=1.0, budget=4, iterations=0, progress=False)


def test_tune_with_folds_is_cross_validated(tmp_path):
    cv = rg.tune("ideal", out=tmp_path / "cv", folds=2, budget=6, iterations=0, jobs=2, progress=False)
    assert isinstance(cv, rg.CrossValidated)
    assert [f.out.rsplit("/", 1)[-1] for f in cv.folds] == ["fold-1", "fold-2"]
    assert [f.summary_json["holdout"]["runs"] for f in cv.folds] == ["1-10", "11-20"]
    t = cv.table
    # The physics-free model tuned: its own rows, no physics-free row to beat.
    assert list(t["source"].unique()) == ["untuned", "tuned"]
    total = t[(t["source"] == "tuned") & (t["scene"] == "total")].iloc[0]
    assert total["low_m"] <= total["mean_m"] <= total["high_m"]
    assert cv.differences.empty
    assert cv.verdict.startswith("Cross-validated over 2 folds of runs 1-20")
    assert "Cross-validated" in cv.markdown
    # By phase: every scene's phases, each fold's sum over them its scene's.
    ph = cv.phases
    tuned = ph[ph["source"] == "tuned"]
    assert set(tuned["scene"]) == set(t["scene"]) - {"total"}
    for scene, g in tuned.groupby("scene"):
        whole = t[(t["source"] == "tuned") & (t["scene"] == scene)].iloc[0]["mean_m"]
        assert abs(g["mean_m"].sum() - whole) < 1e-9 * whole
        assert list(g["phase"]) == list(range(1, len(g) + 1))
    # The report of a study with it holds its section.
    rep = rg.reproduce(tmp_path / "study", engines="ideal", repeats=1, tosses=False,
                       crossval=cv, progress=False)
    with open(rep.report, encoding="utf-8") as f:
        html = f.read()
    assert '<section id="crossval">' in html


def test_tune_of_tosses_gives_the_held_out_table_and_the_contact(root, tmp_path):
    study = tmp_path / "three.toml"
    study.write_text(
        'kind = "tosses"\nname = "three"\ntitle = "three tosses"\ntosses = "tosses"\n'
        'experiment = "experiment.json"\nheld_out_every = 2\nbudget = 8\n'
    )
    data = root / "crates" / "contactnets" / "tests" / "data"
    t = rg.tune("ode", study=study, data=data, out=tmp_path / "tune", jobs=2, progress=False)
    assert list(t.summary["source"]) == ["ode at its defaults", "ode tuned", "ideal"]
    assert (t.summary["tosses"] == 1).all()
    assert set(t.parameters["key"]) == {
        "objects.cube.friction", "objects.cube.restitution",
        "contact.time_constant_s", "contact.damping_ratio",
    }
    assert "friction" in t.params["objects"]["cube"]
    assert len(t.history) == 8


# ------------------------------------------------------------ replay


def test_replay_of_recordings(recordings, root, tmp_path):
    r = rg.replay(recordings, engines=["mujoco"], out=tmp_path / "replay", progress=False)
    t = r.table
    assert "ideal" in set(t["source"]) and "mujoco" in set(t["source"])
    assert Path(r.report).is_file()
    again = r.compare()
    assert again.kind == "replay"


def test_replay_of_tosses_and_their_comparison_equal_the_command(cli, root, tmp_path):
    # The three real tosses committed beside the reader (the data's authors'
    # files), imported by the command, replayed from Python.
    real = tmp_path / "real"
    cli("import", "contactnets", root / "crates/contactnets/tests/data/tosses", "--out", real)
    r = rg.replay(real, engines=["mujoco", "ideal"], out=tmp_path / "replay",
                  params={"objects": {"cube": {"friction": 0.18}}}, progress=False)
    assert r.kind == "tosses"
    assert list(r.table["source"]) == ["mujoco", "physics-free"], r.table
    assert (r.table["tosses"] == 3).all()
    assert Path(r.report).name == "index.html" and Path(r.report).is_file()
    assert "with the given parameters" in Path(r.report).read_text()
    again = r.compare()
    assert again.kind == "tosses"
    m = again.measures
    assert set(m["source"]) == {"mujoco", "ideal"}
    # The same numbers as the command's comparison of the folder.
    command = json.loads(cli("compare", tmp_path / "replay", "--format", "json").stdout)
    by_source = {row["source"]: row["position_error_edges"] for row in command}
    for _, row in m.iterrows():
        assert row["position_error_edges"] == by_source[row["source"]]
    mujoco = m.set_index("source").loc["mujoco", "position_error_edges"]
    ideal = m.set_index("source").loc["ideal", "position_error_edges"]
    assert 0 < mujoco < ideal, m


# ------------------------------------------------------------ reproduce


def test_reproduce_small(tmp_path, cli):
    out = tmp_path / "study"
    r = rg.reproduce(out, repeats=1, engines=["ideal"], scenes=["scene1"], progress=False)
    assert Path(r.report).is_file()
    assert len(r.table) > 0
    assert r.timings
    t = r.table
    assert "physics-free (this tool)" in set(t["source"])
    assert set(t["scene"]) == {"scene1_single_joint", "total"}
    assert r.problems == []
    assert (out / "runs" / "scene1_single_joint").is_dir()
