//! End-to-end: `realitygap report` on the study's recordings.

use std::path::{Path, PathBuf};
use std::process::Command;

fn study() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../assets/studies/collins2019.toml")
}

fn out_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("rg-report-e2e-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// The `<tbody>` of the table with this id.
fn tbody<'a>(html: &'a str, id: &str) -> &'a str {
    let start = html
        .find(&format!("<table id=\"{id}\""))
        .unwrap_or_else(|| panic!("no table #{id}"));
    let rest = &html[start..];
    let body = &rest[rest.find("<tbody>").unwrap()..];
    &body[..body.find("</tbody>").unwrap()]
}

fn run_report(data: &Path, out: &Path, mode: &str) -> String {
    let output = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .arg("report")
        .arg(study())
        .arg("--data")
        .arg(data)
        .args(["--mode", mode, "--out"])
        .arg(out)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "report failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout).unwrap()
}

#[test]
fn report_on_the_paper_data() {
    let Some(data) = realitygap::paper_data_for_tests() else {
        return;
    };
    let out = out_dir("default");
    let stdout = run_report(&data, &out, "default");
    let index = out.join("index.html");
    assert_eq!(
        stdout.trim(),
        index.display().to_string(),
        "stdout names index.html"
    );
    let html = std::fs::read_to_string(&index).unwrap();

    assert_eq!(html.matches("<section id=\"scene-").count(), 3);
    for scene in [
        "scene1_single_joint",
        "scene2_two_joints",
        "scene3_cube_push",
    ] {
        assert!(
            html.contains(&format!("<h2>{scene}</h2>")),
            "no section for {scene}"
        );
    }
    let table = tbody(&html, "accumulated-error");
    // The study's 7 sources and, by default, the physics-free model (its
    // runs under OUT/physics-free/).
    assert_eq!(table.matches("<tr>").count(), 8, "one row per source");
    assert!(table.contains("physics-free (this tool)"), "{table}");
    assert!(out
        .join("physics-free/perfect/scene1_single_joint/ideal/manifest.json")
        .is_file());
    assert_eq!(
        table.matches("class=\"num best\"").count(),
        4,
        "best per scene and total highlighted"
    );
    assert!(table.contains("V-Rep ODE") && table.contains("n/a (20 of 20 runs left out)"));

    let svgs = html.matches("<svg ").count();
    assert!(svgs >= 6, "{svgs} inline figures");
    assert_eq!(html.matches("</svg>").count(), svgs);
    assert!(!html.contains("http://") && !html.contains("https://"));
    // ODE is named as not plotted, never drawn.
    assert!(html.contains("Not plotted: V-Rep ODE (no usable runs: 20 of 20 left out (diverged"));
    assert!(html.contains("Closest per phase"));
    assert!(html.contains("Alignment of the reference"));
    // Intervals, the verdict per scene, the registration and the runs used.
    let pybullet = table.lines().find(|l| l.contains("PyBullet")).unwrap();
    assert_eq!(pybullet.matches(" [").count(), 4, "{pybullet}");
    assert!(html.contains("bootstrap interval over the real runs"));
    assert!(
        html.contains("scene1_single_joint: closest source: ")
            || html.contains("cannot be told apart")
    );
    assert!(html.contains(
        "<p id=\"registration\"><strong>Registration:</strong> capture frame registered"
    ));
    assert!(html.contains("<p id=\"runs\"><strong>Real runs:</strong> all 20 runs"));
    let reg: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("registration.json")).unwrap())
            .unwrap();
    assert_eq!(reg["rotation_wxyz"].as_array().unwrap().len(), 4);
    assert_eq!(reg["translation_m"].as_array().unwrap().len(), 3);

    let pngs: Vec<PathBuf> = std::fs::read_dir(out.join("figures"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    assert_eq!(pngs.len(), svgs, "a PNG per figure");
    for p in &pngs {
        let bytes = std::fs::read(p).unwrap();
        assert!(
            bytes.starts_with(b"\x89PNG\r\n\x1a\n"),
            "{} is not a PNG",
            p.display()
        );
        assert!(
            bytes.len() > 10_000,
            "{}: only {} bytes",
            p.display(),
            bytes.len()
        );
        assert!(out
            .join("figures")
            .join(p.file_name().unwrap())
            .with_extension("svg")
            .is_file());
    }
    for t in [
        "table.md",
        "table.csv",
        "table.json",
        "table.tex",
        "series.json",
        "provenance.json",
    ] {
        assert!(std::fs::metadata(out.join(t)).unwrap().len() > 100, "{t}");
    }
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn study_mode_keeps_the_diverged_runs_but_not_in_the_axes() {
    let Some(data) = realitygap::paper_data_for_tests() else {
        return;
    };
    let out = out_dir("study");
    run_report(&data, &out, "study");
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(html.contains("analysis mode <code>study</code>"));
    // The study averaged the diverged ODE runs in: ~1e17 m, clipped in figures.
    let table = tbody(&html, "accumulated-error");
    let ode = table.lines().find(|l| l.contains("V-Rep ODE")).unwrap();
    assert!(ode.contains("e17"), "{ode}");
    assert!(html.contains("Clipped at the edge of the plot: V-Rep ODE (up to "));
    // The study's procedure: the raw capture frame and no intervals.
    assert!(!out.join("registration.json").exists());
    assert!(!table.contains(" ["), "{table}");
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn bad_input_is_an_error_naming_it() {
    let out = out_dir("bad");
    let output = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(["report", "no-such-study.toml", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let err = String::from_utf8_lossy(&output.stderr);
    assert!(err.contains("no-such-study.toml"), "{err}");
    assert!(!out.exists(), "nothing written on error");
}

/// `report --physics-free` draws and tabulates the physics-free model
/// (perfect tracking, run from the study's scene files into
/// OUT/physics-free/) beside the study's sources, with the same error as
/// `compare --physics-free` gives.
#[test]
fn report_with_the_physics_free_row() {
    let Some(data) = realitygap::paper_data_for_tests() else {
        return;
    };
    let out = out_dir("physics-free");
    // `--out` relative to the working folder, as the README writes it (the
    // physics-free runs were once read back relative to the study's folder).
    let output = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .current_dir(out.parent().unwrap())
        .arg("report")
        .arg(study())
        .arg("--data")
        .arg(&data)
        .args(["--physics-free", "--out"])
        .arg(out.file_name().unwrap())
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    let table = tbody(&html, "accumulated-error");
    assert_eq!(table.matches("<tr>").count(), 8, "the study's 7 and one");
    let row = table
        .lines()
        .find(|l| l.contains("physics-free (this tool)"))
        .expect("the physics-free row");
    assert!(out
        .join("physics-free/perfect/scene3_cube_push/ideal/manifest.json")
        .is_file());
    // The same error as compare's.
    let compare = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .arg("compare")
        .arg(study())
        .arg("--data")
        .arg(&data)
        .args(["--physics-free", "--format", "json"])
        .output()
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&compare.stdout).unwrap();
    let total = v["totals"]["physics-free (this tool)"].as_f64().unwrap();
    assert!(row.contains(&format!("{total:.3}")), "{row} vs {total}");
    let _ = std::fs::remove_dir_all(&out);
}
