//! End-to-end: `realitygap reproduce --data ../shared/paper-data` with one
//! repeat per scene and engine, then the report opened in headless Chromium:
//! every figure and table row must be in the rendered DOM, and a screenshot
//! must not be blank. A rerun resumes (simulates nothing again).

use std::path::{Path, PathBuf};
use std::process::Command;

fn chromium() -> Option<PathBuf> {
    for p in [
        "/usr/bin/chromium",
        "/usr/bin/chromium-browser",
        "/usr/bin/google-chrome",
    ] {
        if Path::new(p).is_file() {
            return Some(PathBuf::from(p));
        }
    }
    if std::env::var_os("CI").is_some()
        || std::env::var_os("REALITYGAP_REQUIRE_PAPER_DATA").is_some()
    {
        panic!("Chromium not found (scripts/setup --tests installs the Debian package `chromium`)");
    }
    eprintln!("SKIPPED: Chromium not found; run scripts/setup --tests");
    None
}

/// Runs headless Chromium with the flags this closed network needs.
fn headless(browser: &Path, profile: &Path, extra: &[&str], url: &str) -> std::process::Output {
    Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(extra)
        .arg(url)
        .output()
        .expect("chromium starts")
}

/// The RGB pixels of a PNG file.
fn pixels(path: &Path) -> Vec<[u8; 3]> {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let step = info.color_type.samples();
    buf[..info.buffer_size()]
        .chunks(step)
        .map(|c| [c[0], c[1], c[2]])
        .collect()
}

#[test]
fn reproduce_renders_every_figure_and_table_in_chromium() {
    let Some(data) = realitygap::paper_data_for_tests() else {
        return;
    };
    let Some(browser) = chromium() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let out_dir = tmp.path().join("study");
    let run = || {
        Command::new(env!("CARGO_BIN_EXE_realitygap"))
            // The arm's report only: the tosses' part of `reproduce` is
            // checked by builtin_data.rs.
            .args(["reproduce", "--repeats", "1", "--no-tosses", "--data"])
            .arg(&data)
            .arg("--out")
            .arg(&out_dir)
            .output()
            .unwrap()
    };
    let out = run();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "reproduce failed: {stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        stdout.contains("| V-Rep Newton |"),
        "table on stdout: {stdout}"
    );
    // A summary a person can read: the table, the verdicts, each kind of
    // flag once, where the files are; the full lists are in table.md.
    assert!(stdout.lines().count() < 45, "{stdout}");
    assert_eq!(stdout.matches("- short: ").count(), 1, "{stdout}");
    assert!(
        stdout.contains("report: ") && stdout.contains("table.md"),
        "{stdout}"
    );
    let full = std::fs::read_to_string(out_dir.join("report/table.md")).unwrap();
    assert!(
        full.matches("only ").count() >= 20,
        "every short run in table.md"
    );
    let timings: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("timings.json")).unwrap())
            .unwrap();
    for stage in ["simulate_s", "compare_s", "report_s", "total_s"] {
        assert!(
            timings[stage].as_f64().is_some(),
            "timings.json has {stage}"
        );
    }

    // The rendered DOM: Chromium loads the page and prints the DOM it built.
    let index = out_dir.join("report/index.html");
    // Self-contained, figures and the 3D replay's data included, and under
    // the 2 MB the guide states.
    let size = std::fs::metadata(&index).unwrap().len();
    assert!(size < 2_000_000, "index.html is {size} bytes");
    let url = format!("file://{}", index.display());
    let profile = tmp.path().join("profile");
    let dom = headless(&browser, &profile, &["--dump-dom"], &url);
    assert!(
        dom.status.success(),
        "chromium --dump-dom: {}",
        String::from_utf8_lossy(&dom.stderr)
    );
    let dom = String::from_utf8_lossy(&dom.stdout).into_owned();
    let svgs = dom.matches("<svg").count();
    // 8 figures (2 + 2 + 4) for the three scenes.
    assert!(svgs >= 8, "{svgs} <svg> elements in the DOM");
    // The accumulated-error table: the 7 recorded simulators and every
    // engine simulated here.
    let engines = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .arg("engines")
        .output()
        .unwrap();
    let engine_count = String::from_utf8_lossy(&engines.stdout)
        .lines()
        .filter(|l| !l.starts_with(' ') && !l.contains("not installed: "))
        .count();
    let first_table = &dom[dom.find("<table").unwrap()..];
    let first_table = &first_table[..first_table.find("</table>").unwrap()];
    let rows = first_table.matches("<tr").count();
    assert_eq!(
        rows,
        1 + 7 + engine_count,
        "table rows (header + sources): {first_table}"
    );
    for scene in [
        "scene1_single_joint",
        "scene2_two_joints",
        "scene3_cube_push",
    ] {
        assert!(dom.contains(scene), "{scene} in the page");
    }
    assert!(
        dom.contains("(this tool)"),
        "the simulated engines are in the page"
    );

    // A screenshot that is not blank: many distinct colours, not one.
    let shot = tmp.path().join("shot.png");
    let s = headless(
        &browser,
        &profile,
        &[
            &format!("--screenshot={}", shot.display()),
            "--window-size=1280,2000",
        ],
        &url,
    );
    assert!(
        shot.is_file(),
        "no screenshot: {}",
        String::from_utf8_lossy(&s.stderr)
    );
    let mut colours = pixels(&shot);
    let count = colours.len();
    let non_white = colours
        .iter()
        .filter(|c| c.iter().any(|&v| v < 240))
        .count();
    colours.sort_unstable();
    colours.dedup();
    assert!(
        colours.len() > 50,
        "screenshot has only {} colours",
        colours.len()
    );
    assert!(
        non_white * 100 > count,
        "screenshot is almost blank ({non_white} non-white pixels)"
    );

    // The verdict comes first, in sentences generated from the numbers.
    let verdict_at = dom.find("id=\"verdict\"").expect("a verdict section");
    assert!(verdict_at < dom.find("id=\"summary\"").unwrap());
    let verdict = &dom[verdict_at..];
    let verdict = &verdict[..verdict.find("</section>").unwrap()];
    assert!(
        verdict.contains("physics-free") && verdict.contains("closest source"),
        "{verdict}"
    );
    for scene in ["scene1_single_joint", "scene3_cube_push"] {
        assert!(verdict.contains(scene), "{scene} in the verdict");
    }
    assert!(
        verdict.contains("(contact, from"),
        "scene 3's push is a contact phase: {verdict}"
    );

    // The 3D replay: the slider set to two times (through the page's
    // `#replay=scene:time` location) draws two different pictures, and the
    // clock beside the slider follows.
    let replay = |t: &str, name: &str| -> Vec<[u8; 3]> {
        let shot = tmp.path().join(name);
        let at = format!("{url}#replay=2:{t}");
        let s = headless(
            &browser,
            &profile,
            &[
                &format!("--screenshot={}", shot.display()),
                "--window-size=1100,760",
                "--virtual-time-budget=3000",
            ],
            &at,
        );
        assert!(
            shot.is_file(),
            "no screenshot: {}",
            String::from_utf8_lossy(&s.stderr)
        );
        let dom = headless(
            &browser,
            &profile,
            &["--dump-dom", "--virtual-time-budget=3000"],
            &at,
        );
        let dom = String::from_utf8_lossy(&dom.stdout).into_owned();
        assert!(
            dom.contains(&format!("<output id=\"replay-clock\">{t}.00 s</output>")),
            "the clock shows {t} s"
        );
        pixels(&shot)
    };
    let early = replay("2", "replay_2.png");
    let late = replay("15", "replay_15.png");
    let drawn = early.iter().filter(|c| c.iter().any(|&v| v < 200)).count();
    assert!(
        drawn > 2000,
        "the replay draws almost nothing ({drawn} dark pixels)"
    );
    assert_eq!(early.len(), late.len());
    let changed = early.iter().zip(&late).filter(|(a, b)| a != b).count();
    assert!(
        changed > 200,
        "moving the slider changed only {changed} pixels"
    );

    // A rerun resumes: nothing is simulated again.
    let again = run();
    assert!(again.status.success());
    let said = String::from_utf8_lossy(&again.stdout);
    assert!(!said.contains(" 1 ok"), "rerun simulated again: {said}");
    assert!(said.contains("1 kept"), "{said}");
}
