//! Extreme values of every typed parameter, in every compiled engine,
//! through the `realitygap` binary (a child process survives an engine's
//! panic or abort, so the test can say which engine and key did it).
//!
//! Each of 0, 1e-300, 1e300 and f32::MAX for each key of
//! [`ParamKey::ALL`] (on joint 2, link 3, the cube) in a parameters file,
//! scene 1 cut to 1 s: the run either fails before running with a located
//! error (the key named, with the file or the engine) or runs, every run
//! ok with finite numbers or flagged (diverged, or unstable: the engine
//! saw a non-finite state). Never a panic, a signal or a silent
//! non-finite number.

mod common;

use common::{path, realitygap, scratch, text};
use realitygap_core::params::ParamKey;
use std::path::{Path, PathBuf};

/// The values each key is tried with.
/// and the bounds of core's reading (`PHYSICAL_MIN`, `PHYSICAL_MAX`).
const VALUES: [(&str, f64); 6] = [
    ("0", 0.0),
    ("1e-300", 1e-300),
    ("1e300", 1e300),
    ("f32max", f32::MAX as f64),
    ("min", realitygap_core::params::PHYSICAL_MIN),
    ("max", realitygap_core::params::PHYSICAL_MAX),
];

/// Scene 1 cut to its first second (20 samples), written into `dir`.
fn short_scene(dir: &Path) -> PathBuf {
    let scene =
        realitygap_core::testing::workspace().join("assets/scenes/scene1_single_joint.toml");
    let text = std::fs::read_to_string(&scene).unwrap();
    let robot = realitygap_core::testing::workspace().join("assets/robots/mico2/mico2.urdf");
    let text = text
        .replace(
            "urdf = \"../robots/mico2/mico2.urdf\"",
            &format!("urdf = {:?}", path(&robot)),
        )
        .replace("duration_s = 6.0", "duration_s = 1.0");
    assert!(
        text.contains("duration_s = 1.0"),
        "scene 1's duration moved"
    );
    let file = dir.join("scene1_short.toml");
    std::fs::write(&file, text).unwrap();
    file
}

/// The parameters file setting `key` to `value` (TOML text) and the key's
/// full name.
fn params_text(key: ParamKey, value: f64) -> (String, String) {
    let full = key
        .pattern()
        .replace("<joint>", "m1n6s300_joint_2")
        .replace("<link>", "m1n6s300_link_3")
        .replace("<object>", "cube");
    let (table, field) = full.rsplit_once('.').unwrap();
    (format!("[{table}]\n{field} = {value:e}\n"), full)
}

/// What one run of an engine did with one extreme value.
fn outcome(
    engine: &str,
    key: ParamKey,
    label: &str,
    value: f64,
    scene: &Path,
    dir: &Path,
) -> Result<String, String> {
    let (toml, full) = params_text(key, value);
    let file = dir.join(format!("{engine}-{}-{label}.toml", full.replace('.', "_")));
    std::fs::write(&file, &toml).unwrap();
    let out_dir = dir.join(format!("out-{engine}-{}-{label}", full.replace('.', "_")));
    let out = realitygap(&[
        "run",
        &path(scene),
        "--engine",
        engine,
        "--params",
        &path(&file),
        "--out",
        &path(&out_dir),
    ]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    let what = format!("{engine} {full} = {value:e}");
    let Some(code) = out.status.code() else {
        return Err(format!(
            "{what}: killed by a signal ({:?}): {stderr}",
            out.status
        ));
    };
    if stderr.contains("panicked") || code == 101 {
        return Err(format!("{what}: panicked (exit {code}): {stderr}"));
    }
    if code != 0 {
        // A located error: the key, and the file or the engine.
        let all = format!("{stdout}{stderr}");
        // The key by its full name, or the joint, link or object it sets
        // (an engine's own check, e.g. MuJoCo's stability check of kv).
        let (table, _) = full.rsplit_once('.').unwrap();
        let item = table.rsplit('.').next().unwrap();
        let located = (all.contains(&full) || all.contains(item))
            && (all.contains(&path(&file)) || all.contains(&format!("engine {engine}")));
        return if located {
            let line = all.lines().find(|l| l.contains(item)).unwrap_or("");
            Ok(format!("{what}: refused: {line}"))
        } else {
            Err(format!(
                "{what}: failed without naming the key and the file or engine: {all}"
            ))
        };
    }
    let scene_dir = std::fs::read_dir(&out_dir)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let source = std::fs::read_dir(&scene_dir)
        .unwrap()
        .find_map(|e| {
            let p = e.unwrap().path();
            p.join("manifest.json").is_file().then_some(p)
        })
        .unwrap_or_else(|| panic!("{what}: no manifest in {}", scene_dir.display()));
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(source.join("manifest.json")).unwrap()).unwrap();
    let status = manifest["runs"][0]["status"]
        .as_str()
        .unwrap_or("")
        .to_string();
    match status.as_str() {
        // Flagged: diverged (the controller's check) or unstable (the
        // engine saw a non-finite state).
        "diverged" | "unstable" => Ok(format!("{what}: {status}")),
        "ok" => {
            let csv = std::fs::read_to_string(source.join("runs/run000.csv")).unwrap();
            for row in csv.lines().skip(1) {
                for cell in row.split(',') {
                    let v: f64 = cell.parse().unwrap_or(f64::NAN);
                    if !v.is_finite() {
                        return Err(format!("{what}: ok with a non-finite number: {row}"));
                    }
                }
            }
            Ok(format!("{what}: ok"))
        }
        other => Err(format!("{what}: run status {other:?}: {stdout} {stderr}")),
    }
}

#[test]
fn extreme_values_are_refused_or_run_never_crash() {
    let dir = scratch("extreme_values", "all");
    let scene = short_scene(&dir);
    let engines: Vec<&'static str> = realitygap::compiled_engines()
        .iter()
        .map(|e| e.name())
        .collect();
    let cases: Vec<(&str, ParamKey, &str, f64)> = engines
        .iter()
        .flat_map(|&e| {
            ParamKey::ALL
                .into_iter()
                .flat_map(move |k| VALUES.into_iter().map(move |(l, v)| (e, k, l, v)))
        })
        .collect();
    use rayon::prelude::*;
    let results: Vec<Result<String, String>> = cases
        .par_iter()
        .map(|&(e, k, l, v)| outcome(e, k, l, v, &scene, &dir))
        .collect();
    let mut failures = Vec::new();
    for r in results {
        match r {
            Ok(line) => eprintln!("EXTREME {line}"),
            Err(line) => {
                eprintln!("EXTREME FAIL {line}");
                failures.push(line);
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} failures:\n{}",
        failures.len(),
        failures.join("\n")
    );
}
