//! The study's recordings built in (`--data builtin`, the default): the
//! same tables as the recordings read in place, a cache that is verified
//! and rebuilt when damaged, and clear errors for an unwritable cache or a
//! `--data` folder that does not exist.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn study() -> PathBuf {
    root().join("assets/studies/collins2019.toml")
}

/// The command with its cache in `cache` and no package path.
fn realitygap(cache: &Path, args: &[&std::ffi::OsStr]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .env("REALITYGAP_CACHE_DIR", cache)
        .env_remove("ROS_PACKAGE_PATH")
        .env_remove("REALITYGAP_ASSETS")
        .args(args)
        .output()
        .unwrap()
}

fn ok(out: &Output) -> (String, String) {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "failed: {stderr}");
    (String::from_utf8(out.stdout.clone()).unwrap(), stderr)
}

fn os(s: &(impl AsRef<std::ffi::OsStr> + ?Sized)) -> &std::ffi::OsStr {
    s.as_ref()
}

/// The unpacked folder in a cache root (there is one).
fn unpacked_dir(cache: &Path) -> PathBuf {
    std::fs::read_dir(cache.join("study-data"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.is_dir() && !p.file_name().unwrap().to_string_lossy().starts_with('.'))
        .expect("an unpacked folder in the cache")
}

#[test]
fn compare_with_the_builtin_data_gives_the_tables_of_paper_data() {
    let Some(paper) = realitygap::paper_data_for_tests() else {
        return;
    };
    let cache = tempfile::tempdir().unwrap();
    for (i, mode) in ["study", "default"].into_iter().enumerate() {
        let (builtin, stderr) = ok(&realitygap(
            cache.path(),
            &[os("compare"), os(&study()), os("--mode"), os(mode)],
        ));
        // Unpacked on first use only.
        assert_eq!(stderr.contains("unpacked"), i == 0, "{stderr}");
        let (in_place, _) = ok(&realitygap(
            cache.path(),
            &[
                os("compare"),
                os(&study()),
                os("--mode"),
                os(mode),
                os("--data"),
                os(&paper),
            ],
        ));
        assert_eq!(builtin, in_place, "{mode} mode");
        for source in ["| MuJoCo |", "| V-Rep Newton |", "| V-Rep ODE |"] {
            assert!(builtin.contains(source), "{mode}: {source} in {builtin}");
        }
    }
    let (explicit, _) = ok(&realitygap(
        cache.path(),
        &[os("compare"), os(&study()), os("--data"), os("builtin")],
    ));
    let (default, _) = ok(&realitygap(cache.path(), &[os("compare"), os(&study())]));
    assert_eq!(explicit, default);
}

#[test]
fn a_damaged_cache_is_detected_and_rebuilt() {
    let cache = tempfile::tempdir().unwrap();
    let study = study();
    let args = [os("compare"), os(&study), os("--mode"), os("study")];
    let (first, _) = ok(&realitygap(cache.path(), &args));
    let victim = unpacked_dir(cache.path()).join("MotionCapture/Experiment2/Double0007_6D.tsv");
    let size = std::fs::metadata(&victim).unwrap().len();
    std::fs::OpenOptions::new()
        .write(true)
        .open(&victim)
        .unwrap()
        .set_len(size / 2)
        .unwrap();
    let (second, stderr) = ok(&realitygap(cache.path(), &args));
    assert!(
        stderr.contains("damaged") && stderr.contains("Double0007_6D.tsv"),
        "{stderr}"
    );
    assert_eq!(std::fs::metadata(&victim).unwrap().len(), size);
    assert_eq!(first, second);
    let (_, stderr) = ok(&realitygap(cache.path(), &args));
    assert!(!stderr.contains("unpacked"), "{stderr}");
}

#[test]
fn an_unwritable_cache_folder_is_a_clear_error() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("plain-file");
    std::fs::write(&file, "a file, not a folder").unwrap();
    let cache = file.join("cache");
    let out = realitygap(&cache, &[os("compare"), os(&study())]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains(&*cache.display().to_string()), "{err}");
    assert!(err.contains("REALITYGAP_CACHE_DIR"), "{err}");
}

#[test]
fn data_pointing_nowhere_names_the_path() {
    let tmp = tempfile::tempdir().unwrap();
    let out_dir = tmp.path().join("out");
    for args in [
        vec![os("compare"), os(&study())],
        vec![os("report"), os(&study()), os("--out"), os(&out_dir)],
        vec![os("reproduce"), os("--out"), os(&out_dir)],
    ] {
        let mut args = args;
        args.extend([os("--data"), os("/does/not/exist")]);
        let out = realitygap(tmp.path(), &args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}");
        assert!(
            err.contains("/does/not/exist") && err.contains("no such folder"),
            "{args:?}: {err}"
        );
    }
    // Nothing was simulated or unpacked on the way.
    assert!(!out_dir.join("runs").exists());
    assert!(!tmp.path().join("study-data").exists());
}

#[test]
fn data_none_is_refused_for_a_study_that_reads_recordings() {
    let tmp = tempfile::tempdir().unwrap();
    let out = realitygap(
        tmp.path(),
        &[os("compare"), os(&study()), os("--data"), os("none")],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("--data none") && err.contains("collins2019.toml"),
        "{err}"
    );
}

#[cfg(all(feature = "rapier", feature = "ode"))]
/// `reproduce` with the built-in data gives the table of `--data
/// paper-data` (same simulations: the second call resumes the first's), and
/// `--data none` compares the engines with each other.
#[test]
fn reproduce_with_the_builtin_data_gives_the_table_of_paper_data() {
    let Some(paper) = realitygap::paper_data_for_tests() else {
        return;
    };
    let cache = tempfile::tempdir().unwrap();
    let out_dir = cache.path().join("study");
    let base = [
        os("reproduce"),
        os("--repeats"),
        os("1"),
        os("--engine"),
        os("rapier"),
        os("--engine"),
        os("ode"),
        os("--out"),
        os(&out_dir),
    ];
    let with = |extra: &[&std::ffi::OsStr]| {
        let mut args = base.to_vec();
        args.extend_from_slice(extra);
        ok(&realitygap(cache.path(), &args)).0
    };
    // The full tables and measures, as written into the report folder
    // (standard output has the summary).
    let tables = |_stdout: String| {
        let text = std::fs::read_to_string(out_dir.join("report/table.md")).unwrap();
        assert!(text.contains("## Accumulated error"), "{text}");
        text
    };
    let in_place = tables(with(&[os("--data"), os(&paper)]));
    let stdout = with(&[]);
    // Two engines without the physics-free model: the summary says the
    // table lacks that baseline.
    assert!(
        stdout.contains("The physics-free model was not run") && stdout.contains("--engine ideal"),
        "{stdout}"
    );
    let builtin = tables(stdout);
    assert!(
        builtin == in_place,
        "built in:\n{builtin}\nin place:\n{in_place}"
    );
    let summary = builtin.split("\n### ").next().unwrap();
    let rows: Vec<&str> = summary.lines().filter(|l| l.starts_with("| ")).collect();
    // Header, 7 recorded simulators, 2 engines of this tool.
    assert_eq!(rows.len(), 1 + 7 + 2, "{summary}");
    assert!(builtin.contains("| V-Rep Vortex |") && builtin.contains("(this tool)"));
    // The second study: the built-in tosses in both engines and the
    // physics-free row.
    let tosses = std::fs::read_to_string(out_dir.join("tosses/tosses.md")).unwrap();
    for row in ["| rapier |", "| ode |", "| physics-free"] {
        assert!(tosses.contains(row), "{tosses}");
    }
    assert!(tosses.contains("456 real tosses"), "{tosses}");
    let html = std::fs::read_to_string(out_dir.join("report/index.html")).unwrap();
    assert!(
        html.contains("paper-data.tar.zst"),
        "provenance names the built-in data"
    );
    // The report's tosses: the verdict, the figure (inlined and as files,
    // a line per source) and the table by phase.
    let at = html
        .find("<section id=\"tosses\">")
        .expect("a tosses section");
    let section = &html[at..];
    let section = &section[..section.find("</section>").unwrap()];
    assert!(
        section.contains(
            "On 456 real cube tosses, the engine closest to the real cube at its defaults is"
        ) && section.contains("the physics-free row&#39;s"),
        "{section}"
    );
    assert!(section.contains("<th>Slide and tumble</th>"), "{section}");
    for source in ["rapier", "ode", "physics-free"] {
        assert!(
            section.contains(&format!("<tr><td>{source}</td>")),
            "{source}: {section}"
        );
    }
    let svg =
        std::fs::read_to_string(out_dir.join("report/figures/tosses_centre_error.svg")).unwrap();
    for source in ["rapier", "ode", "physics-free"] {
        assert!(svg.contains(source), "{source} in the figure's legend");
    }
    assert!(section.contains("href=\"figures/tosses_centre_error.png\""));
    assert!(out_dir
        .join("report/figures/tosses_centre_error.png")
        .is_file());
    // The 3D replay's menu gains three tosses (the median and quartiles of
    // the closest engine's error), the real cube and each source's.
    assert_eq!(
        html.matches("{\"name\":\"toss ").count(),
        3,
        "three tosses in the 3D replay"
    );
    assert!(html.contains("(median of "), "the median toss named");

    let cross = tables(with(&[os("--data"), os("none")]));
    assert!(!cross.contains("V-Rep"), "{cross}");
    assert!(cross.contains("(this tool)"), "{cross}");
}

#[cfg(feature = "ode")]
/// `--robot official` without `--package` takes `kinova_description` from
/// the built-in data.
#[test]
fn the_official_robot_comes_from_the_builtin_data() {
    let cache = tempfile::tempdir().unwrap();
    let out_dir = cache.path().join("runs");
    let (_, stderr) = ok(&realitygap(
        cache.path(),
        &[
            os("run"),
            os(&root().join("assets/scenes/scene1_single_joint.toml")),
            os("--robot"),
            os("official"),
            os("--engine"),
            os("ode"),
            os("--out"),
            os(&out_dir),
        ],
    ));
    let manifest: serde_json::Value = serde_json::from_slice(
        &std::fs::read(out_dir.join("scene1_single_joint/ode-official/manifest.json")).unwrap(),
    )
    .unwrap();
    let urdf = manifest["settings"]["config"]["robot"]["urdf"]
        .as_str()
        .unwrap();
    let expected = unpacked_dir(cache.path()).join("kinova_description/urdf/m1n6s300.urdf");
    assert_eq!(Path::new(urdf), expected, "{stderr}");
    assert_eq!(manifest["runs"][0]["status"], "ok", "{manifest}");
}

/// Two processes starting on an empty cache at once: one unpacks, the
/// other waits for it and reuses its copy; both give the same table.
#[test]
fn two_processes_share_one_unpacking() {
    let cache = tempfile::tempdir().unwrap();
    let spawn = || {
        Command::new(env!("CARGO_BIN_EXE_realitygap"))
            .env("REALITYGAP_CACHE_DIR", cache.path())
            .env_remove("REALITYGAP_ASSETS")
            .args([os("compare"), os(&study()), os("--mode"), os("study")])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (spawn(), spawn());
    let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
    let ((out_a, err_a), (out_b, err_b)) = (ok(&a), ok(&b));
    assert_eq!(out_a, out_b);
    let unpacked = [&err_a, &err_b]
        .iter()
        .filter(|e| e.contains("unpacked"))
        .count();
    assert_eq!(unpacked, 1, "{err_a}\n{err_b}");
    let leftovers: Vec<_> = std::fs::read_dir(cache.path().join("study-data"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".tmp") || n.starts_with(".trash"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

/// A study of results directories only reads no recordings: without
/// `--data` (or with `--data none`) nothing is unpacked.
#[cfg(feature = "rapier")]
#[test]
fn a_study_of_results_directories_needs_no_recordings() {
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path().join("runs");
    ok(&realitygap(
        tmp.path(),
        &[
            os("run"),
            os(&root().join("assets/scenes/scene1_single_joint.toml")),
            os("--engine"),
            os("rapier"),
            os("--out"),
            os(&runs),
        ],
    ));
    let study = tmp.path().join("stores.toml");
    std::fs::write(
        &study,
        "name = \"stores\"\n[[scenes]]\nname = \"scene1_single_joint\"\nsteps = 120\n\
         [scenes.reference]\nname = \"rapier\"\nformat = \"store\"\ndir = \"scene1_single_joint/rapier\"\n\
         [[scenes.sources]]\nname = \"rapier again\"\nformat = \"store\"\ndir = \"scene1_single_joint/rapier\"\n",
    )
    .unwrap();
    let cache = tmp.path().join("cache");
    let mut tables = Vec::new();
    for data in [None, Some("none")] {
        let mut args = vec![os("compare"), os(&study), os("--results"), os(&runs)];
        if let Some(d) = data {
            args.extend([os("--data"), os(d)]);
        }
        let (out, _) = ok(&realitygap(&cache, &args));
        assert!(
            out.contains("| rapier again | 0.000 [0.000, 0.000] |"),
            "{out}"
        );
        tables.push(out);
    }
    assert_eq!(tables[0], tables[1]);
    assert!(!cache.exists(), "nothing unpacked");
}
