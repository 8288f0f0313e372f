//! `realitygap replay` of tossed objects end to end: the three real tosses
//! committed with `realitygap-contactnets` (BSD 3-Clause, written by the
//! data's authors) imported, then replayed in every engine and the
//! physics-free model, with the published friction as parameters.

use realitygap_data::RunStore;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn realitygap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(args)
        .output()
        .expect("the binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn tosses() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../contactnets/tests/data/tosses")
}

fn imported(tmp: &Path) -> PathBuf {
    let real = tmp.join("real");
    let o = realitygap(&[
        "import",
        "contactnets",
        tosses().to_str().unwrap(),
        "--out",
        real.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    real
}

#[test]
fn every_toss_is_replayed_in_every_engine_and_the_physics_free_model() {
    let tmp = tempfile::tempdir().unwrap();
    let real = imported(tmp.path());
    let params = tmp.path().join("mu.toml");
    std::fs::write(&params, "[objects.cube]\nfriction = 0.18\n").unwrap();
    let out = tmp.path().join("replay");
    let o = realitygap(&[
        "replay",
        real.to_str().unwrap(),
        "--params",
        params.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let stdout = text(&o.stdout);
    assert!(o.status.success(), "{stdout}\n{}", text(&o.stderr));
    assert!(stdout.contains("replayed 3 tosses in "), "{stdout}");
    let real_store = RunStore::open(&real).unwrap();
    let table = std::fs::read_to_string(out.join("tosses.md")).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("tosses.json")).unwrap()).unwrap();
    let rows = json.as_array().unwrap();
    let error = |source: &str| {
        rows.iter()
            .find(|r| r["source"] == source)
            .and_then(|r| r["position_error_edges"].as_f64())
            .unwrap_or_else(|| panic!("no row for {source}: {json}"))
    };
    let mut engines: Vec<String> = rows
        .iter()
        .map(|r| r["source"].as_str().unwrap().to_string())
        .collect();
    engines.sort();
    assert!(engines.len() >= 2, "{engines:?}");
    for engine in &engines {
        let store = RunStore::open(&out.join(engine)).unwrap();
        assert_eq!(store.runs().len(), 3, "{engine}");
        for id in ["185", "229", "563"] {
            let csv =
                std::fs::read_to_string(out.join(engine).join("runs").join(format!("{id}.csv")))
                    .unwrap();
            let mut lines = csv.lines();
            assert_eq!(
                lines.next().unwrap(),
                "t_s,cube_x_m,cube_y_m,cube_z_m,cube_qw,cube_qx,cube_qy,cube_qz",
                "{engine} {id}"
            );
            let want = real_store.read_run(id).unwrap();
            let got = store.read_run(id).unwrap();
            assert_eq!(
                got.len(),
                want.len(),
                "{engine} {id}: one row per recorded sample"
            );
            assert_eq!(got.time_s, want.time_s, "{engine} {id}: the recorded times");
            // Every source starts at the recorded first pose.
            let (a, b) = (
                got.bodies[0].poses[0].unwrap().position_m,
                want.bodies[0].poses[0].unwrap().position_m,
            );
            assert!(
                a.distance(b) < 1e-6,
                "{engine} {id}: starts {} m off",
                a.distance(b)
            );
        }
        assert!(
            table.contains(engine.as_str()) || engine == "ideal",
            "{table}"
        );
        let e = error(engine);
        assert!(e.is_finite() && e > 0.0, "{engine}: {e}");
    }
    // Ballistic flight frozen at first contact is far off (1.5 edges on
    // the visible tosses); MuJoCo with the published friction comes within
    // a third of an edge, as it does from Python.
    let ideal = error("ideal");
    assert!(ideal > 0.5, "physics-free: {ideal} edges");
    // By phase: the ballistic row follows the flight (it starts from the
    // recorded state) and is far off once the cube slides; every phase of
    // these tosses has samples, so each cell has a value.
    let phase = |source: &str, i: usize| {
        let r = rows.iter().find(|r| r["source"] == source).unwrap();
        assert_eq!(
            r["phases"][i]["phase"],
            ["flight", "impact", "slide and tumble", "rest"][i]
        );
        r["phases"][i]["position_error_edges"].as_f64().unwrap()
    };
    assert!(phase("ideal", 0) < 0.1 && phase("ideal", 2) > 0.5, "{json}");
    assert!(
        table.contains("\n| source | flight | impact | slide and tumble | rest |\n|---|"),
        "{table}"
    );
    if engines.iter().any(|e| e == "mujoco") {
        let mujoco = error("mujoco");
        assert!(
            mujoco < 0.5 * ideal,
            "mujoco {mujoco} against physics-free {ideal}"
        );
    }

    // `compare` of the replay's folder measures the stored runs again
    // against the real tosses its manifests name: the same rows as the
    // replay's own table (the speeds aside, which a comparison cannot
    // know), in Markdown, JSON and CSV.
    let compare = |format: &str| {
        let o = realitygap(&["compare", out.to_str().unwrap(), "--format", format]);
        assert!(o.status.success(), "{format}: {}", text(&o.stderr));
        text(&o.stdout)
    };
    let md = compare("md");
    let headline = |t: &str| -> Vec<String> {
        t.lines()
            .filter(|l| l.starts_with("| ") && !l.starts_with("| source"))
            .map(|l| l.rsplit_once(" | ").unwrap().0.to_string())
            .collect()
    };
    assert_eq!(headline(&md), headline(&table), "{md}\n{table}");
    let again: serde_json::Value = serde_json::from_str(&compare("json")).unwrap();
    for row in rows {
        let other = again
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["source"] == row["source"])
            .unwrap();
        assert_eq!(other["position_error_edges"], row["position_error_edges"]);
        assert_eq!(other["phases"], row["phases"]);
    }
    let csv = compare("csv");
    assert!(csv.starts_with("source,tosses,failed,position_error_edges,position_error_edges_low,"));
    assert_eq!(csv.lines().count(), 1 + rows.len(), "{csv}");
    assert!(csv.contains("\nphysics-free,3,0,"), "{csv}");
    // A folder with no replayed tosses is not taken for one.
    let o = realitygap(&["compare", real.to_str().unwrap(), "--format", "md"]);
    assert!(!o.status.success());

    // `report` of the replay's folder: a page of the tosses alone (the
    // verdict, the table, the figure, the 3D replay of the quartiles'
    // tosses), the table's files beside it; the parameters the engines ran
    // with (the published friction) are named, not called defaults.
    let site = tmp.path().join("site");
    let o = realitygap(&[
        "report",
        out.to_str().unwrap(),
        "--out",
        site.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let page = std::fs::read_to_string(site.join("index.html")).unwrap();
    assert_eq!(
        text(&o.stdout).trim(),
        site.join("index.html").to_str().unwrap()
    );
    assert!(
        page.contains("<section id=\"tosses\">")
            && page.contains("On 3 real cube tosses, the engine closest to the real cube with the given parameters is ")
            && page.contains("id=\"replay-data\"")
            && page.contains("\"name\":\"toss ")
            && page.contains("href=\"provenance.json\""),
        "{page}"
    );
    assert!(!page.contains("at its defaults"), "{page}");
    assert!(
        !page.contains("id=\"summary\"") && !page.contains("href=\"table.md\""),
        "no scene table in a page of tosses"
    );
    assert!(site.join("figures/tosses_centre_error.svg").is_file());
    // A cross-validated tune of the arm has no place on a page of tosses:
    // refused with both names, nothing written.
    let site2 = tmp.path().join("site2");
    let o = realitygap(&[
        "report",
        out.to_str().unwrap(),
        "--out",
        site2.to_str().unwrap(),
        "--crossval",
        "cv-folder",
    ]);
    assert!(!o.status.success());
    let err = text(&o.stderr);
    assert!(
        err.contains("--crossval cv-folder") && err.contains("holds replayed tosses"),
        "{err}"
    );
    assert!(!site2.exists());
    assert!(site.join("figures/tosses_centre_error.png").is_file());
    assert!(!site.join("table.md").exists());
    assert_eq!(
        headline(&std::fs::read_to_string(site.join("tosses.md")).unwrap()),
        headline(&table)
    );
    let again: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(site.join("tosses.json")).unwrap()).unwrap();
    assert_eq!(again.as_array().unwrap().len(), rows.len());
    assert_eq!(
        std::fs::read_to_string(site.join("tosses.csv")).unwrap(),
        csv
    );
    // Each engine's manifest records what it ran with.
    let engine = engines.iter().find(|e| *e != "ideal").unwrap();
    let manifest: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join(engine).join("manifest.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(
        manifest["settings"]["params"]["objects"]["cube"]["friction"], 0.18,
        "{manifest}"
    );
}

#[test]
fn a_toss_without_its_velocities_is_a_located_error() {
    let tmp = tempfile::tempdir().unwrap();
    let real = imported(tmp.path());
    std::fs::remove_file(real.join("runs/229.velocities.csv")).unwrap();
    let out = tmp.path().join("replay");
    let o = realitygap(&[
        "replay",
        real.to_str().unwrap(),
        "--engine",
        "ideal",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = text(&o.stderr);
    assert!(!o.status.success());
    assert!(stderr.contains("run 229"), "{stderr}");
    assert!(!out.exists(), "nothing written: {}", out.display());
}

#[test]
fn parameters_no_engine_can_use_are_refused_before_anything_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let real = imported(tmp.path());
    let out = tmp.path().join("replay");
    for (toml, want) in [
        ("[objects.box]\nfriction = 0.18\n", "box"),
        ("[engine.mujoco]\ntimestep_s = 0.002\n", "0.002"),
    ] {
        let params = tmp.path().join("p.toml");
        std::fs::write(&params, toml).unwrap();
        let o = realitygap(&[
            "replay",
            real.to_str().unwrap(),
            "--engine",
            "mujoco",
            "--params",
            params.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let stderr = text(&o.stderr);
        assert!(!o.status.success(), "{toml}: {stderr}");
        assert!(stderr.contains(want), "{toml}: {stderr}");
        assert!(!out.exists(), "{toml}: nothing written");
    }
}
