//! The guide cannot rot: every internal link in the README, `docs/` and the
//! crates' READMEs points at a file (and a heading) that exists, and every
//! `realitygap` command in a code block names a command and options that the
//! binary's `--help` lists. The checker itself is tested on a broken page.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

/// One problem found in a page: the file, its line (1-based) and what is wrong.
#[derive(Debug, Clone, PartialEq)]
struct Problem {
    file: PathBuf,
    line: usize,
    what: String,
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}: {}", self.file.display(), self.line, self.what)
    }
}

/// A Markdown page split into its prose lines (links checked) and its code
/// blocks (commands checked), each line with its number.
struct Page {
    prose: Vec<(usize, String)>,
    code: Vec<(usize, String)>,
    headings: BTreeSet<String>,
}

fn read_page(path: &Path) -> Page {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let mut prose = Vec::new();
    let mut code = Vec::new();
    let mut headings = BTreeSet::new();
    let mut in_code = false;
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    for (i, line) in text.lines().enumerate() {
        let n = i + 1;
        if line.trim_start().starts_with("```") {
            in_code = !in_code;
            continue;
        }
        if in_code {
            code.push((n, line.to_string()));
            continue;
        }
        if let Some(h) = line.strip_prefix('#') {
            let title = h.trim_start_matches('#').trim();
            let slug = slug(title);
            // GitHub numbers repeated headings: name, name-1, name-2.
            let count = seen.entry(slug.clone()).or_insert(0);
            if *count == 0 {
                headings.insert(slug.clone());
            } else {
                headings.insert(format!("{slug}-{count}"));
            }
            *count += 1;
        }
        prose.push((n, line.to_string()));
    }
    Page {
        prose,
        code,
        headings,
    }
}

/// GitHub's anchor for a heading: lower case, punctuation dropped except
/// hyphens and underscores, spaces to hyphens.
fn slug(title: &str) -> String {
    let title = strip_inline_code_marks(title);
    title
        .to_lowercase()
        .chars()
        .filter_map(|c| {
            if c.is_alphanumeric() || c == '-' || c == '_' {
                Some(c)
            } else if c == ' ' {
                Some('-')
            } else {
                None
            }
        })
        .collect()
}

fn strip_inline_code_marks(s: &str) -> String {
    s.replace('`', "")
}

/// Removes inline code spans, so `[a](b)` written as code is not a link.
fn without_inline_code(line: &str) -> String {
    let mut out = String::new();
    let mut in_code = false;
    for c in line.chars() {
        if c == '`' {
            in_code = !in_code;
            continue;
        }
        if !in_code {
            out.push(c);
        }
    }
    out
}

/// The targets of the Markdown links and images on one line.
fn link_targets(line: &str) -> Vec<String> {
    let line = without_inline_code(line);
    let mut targets = Vec::new();
    let mut rest = line.as_str();
    while let Some(at) = rest.find("](") {
        let after = &rest[at + 2..];
        let end = after.find(')').unwrap_or(after.len());
        let target = after[..end].split_whitespace().next().unwrap_or("");
        targets.push(target.to_string());
        rest = &after[end.min(after.len())..];
    }
    targets
}

fn is_external(target: &str) -> bool {
    ["http://", "https://", "mailto:"]
        .iter()
        .any(|p| target.starts_with(p))
}

/// Checks every internal link of the pages; `pages` are read once each.
fn check_links(files: &[PathBuf]) -> Vec<Problem> {
    let mut cache: BTreeMap<PathBuf, Page> = BTreeMap::new();
    let mut problems = Vec::new();
    for file in files {
        let page = read_page(file);
        let dir = file.parent().unwrap_or(Path::new("."));
        for (n, line) in &page.prose {
            for target in link_targets(line) {
                if target.is_empty() || is_external(&target) {
                    continue;
                }
                let (path_part, anchor) = match target.split_once('#') {
                    Some((p, a)) => (p.to_string(), Some(a.to_string())),
                    None => (target.clone(), None),
                };
                let target_path = if path_part.is_empty() {
                    file.clone()
                } else {
                    dir.join(&path_part)
                };
                if !target_path.exists() {
                    problems.push(Problem {
                        file: file.clone(),
                        line: *n,
                        what: format!("link to {target}: no such file {}", target_path.display()),
                    });
                    continue;
                }
                let Some(anchor) = anchor else { continue };
                if target_path.extension().is_none_or(|e| e != "md") {
                    continue;
                }
                let headings = if &target_path == file {
                    &page.headings
                } else {
                    let key = target_path.canonicalize().unwrap_or(target_path.clone());
                    &cache
                        .entry(key)
                        .or_insert_with(|| read_page(&target_path))
                        .headings
                };
                if !headings.contains(&anchor) {
                    problems.push(Problem {
                        file: file.clone(),
                        line: *n,
                        what: format!(
                            "link to {target}: {} has no heading #{anchor}",
                            target_path.display()
                        ),
                    });
                }
            }
        }
    }
    problems
}

/// The realitygap invocations in a page's code blocks: continuation lines
/// joined, comments and output left out. Each is the line number and the
/// arguments after the program (`cargo run --release --` or `realitygap`).
fn commands(page: &Page) -> Vec<(usize, Vec<String>)> {
    let mut out = Vec::new();
    let mut joined = String::new();
    let mut first = 0;
    for (n, line) in &page.code {
        let line = line.trim();
        if joined.is_empty() {
            first = *n;
        }
        if let Some(head) = line.strip_suffix('\\') {
            joined.push_str(head);
            joined.push(' ');
            continue;
        }
        joined.push_str(line);
        let full = std::mem::take(&mut joined);
        let full = full.trim().trim_start_matches("$ ");
        if full.starts_with('#') {
            continue;
        }
        // A command line may chain commands with && or pipe into another.
        for part in full.split("&&").flat_map(|p| p.split('|').take(1)) {
            let words: Vec<&str> = part.split_whitespace().collect();
            let args = match words.as_slice() {
                ["cargo", "run", rest @ ..] => match rest.iter().position(|w| *w == "--") {
                    Some(i) => rest[i + 1..].to_vec(),
                    None => continue,
                },
                ["realitygap", rest @ ..] => rest.to_vec(),
                _ => continue,
            };
            let args: Vec<String> = args
                .iter()
                .take_while(|w| !w.starts_with('#') && !w.starts_with('>'))
                .map(|w| w.to_string())
                .collect();
            if !args.is_empty() {
                out.push((first, args));
            }
        }
    }
    out
}

/// What `--help` says of a command: its subcommands and its options.
struct Help {
    subcommands: BTreeSet<String>,
    options: BTreeSet<String>,
}

fn parse_help(text: &str) -> Help {
    let mut subcommands = BTreeSet::new();
    let mut options = BTreeSet::new();
    let mut in_commands = false;
    for line in text.lines() {
        if line.starts_with("Commands:") {
            in_commands = true;
            continue;
        }
        if !line.starts_with(' ') {
            in_commands = false;
        }
        let t = line.trim_start();
        if in_commands && line.starts_with("  ") && !line.starts_with("     ") {
            if let Some(w) = t.split_whitespace().next() {
                subcommands.insert(w.to_string());
            }
        }
        for word in t.split(|c: char| c.is_whitespace() || c == ',' || c == '[' || c == ']') {
            if let Some(name) = word.strip_prefix("--") {
                let name = name.split(['=', '<']).next().unwrap_or("");
                if !name.is_empty() {
                    options.insert(format!("--{name}"));
                }
            }
            if word.len() == 2 && word.starts_with('-') && word != "--" {
                options.insert(word.to_string());
            }
        }
    }
    Help {
        subcommands,
        options,
    }
}

/// Checks each command against the help that `help_of(path)` returns for
/// the command path (e.g. `["import", "rosbag"]`).
fn check_commands(
    files: &[PathBuf],
    help_of: &mut dyn FnMut(&[String]) -> Option<String>,
) -> Vec<Problem> {
    let mut problems = Vec::new();
    let mut cache: BTreeMap<Vec<String>, Option<Help>> = BTreeMap::new();
    for file in files {
        let page = read_page(file);
        for (line, args) in commands(&page) {
            let mut path: Vec<String> = Vec::new();
            let mut help = cache
                .entry(path.clone())
                .or_insert_with(|| help_of(&path).map(|t| parse_help(&t)));
            let mut words = args.iter().peekable();
            let mut unknown = false;
            // The command path: words that are subcommands of what precedes.
            while let Some(w) = words.peek() {
                let Some(h) = help.as_ref() else { break };
                if h.subcommands.is_empty() || w.starts_with('-') {
                    break;
                }
                if !h.subcommands.contains(w.as_str()) {
                    problems.push(Problem {
                        file: file.clone(),
                        line,
                        what: format!(
                            "`realitygap {} {w}`: no such command (the help lists: {})",
                            path.join(" "),
                            h.subcommands.iter().cloned().collect::<Vec<_>>().join(", ")
                        )
                        .replace("realitygap  ", "realitygap "),
                    });
                    unknown = true;
                    break;
                }
                path.push(w.to_string());
                words.next();
                help = cache
                    .entry(path.clone())
                    .or_insert_with(|| help_of(&path).map(|t| parse_help(&t)));
            }
            let Some(h) = help.as_ref() else { continue };
            if unknown {
                continue;
            }
            for w in words {
                let numeric = w
                    .chars()
                    .nth(1)
                    .is_some_and(|c| c.is_ascii_digit() || c == '.');
                if !w.starts_with('-') || w == "-" || w == "--" || numeric {
                    continue;
                }
                let name = w.split('=').next().unwrap_or(w);
                if !h.options.contains(name) {
                    problems.push(Problem {
                        file: file.clone(),
                        line,
                        what: format!(
                            "`realitygap {}`: no option {name} in its --help",
                            path.join(" ")
                        ),
                    });
                }
            }
        }
    }
    problems
}

fn workspace() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    root.canonicalize().unwrap_or(root)
}

/// The pages the guide consists of: the README, docs/, and every README the
/// repository keeps beside its code and data.
fn pages() -> Vec<PathBuf> {
    let root = workspace();
    let mut files = vec![root.join("README.md")];
    for dir in ["docs", "crates", "assets", "tools", "scripts"] {
        collect_md(&root.join(dir), &mut files);
    }
    files.sort();
    files
}

fn collect_md(dir: &Path, files: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let p = entry.path();
        let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if p.is_dir() {
            // Snapshots and the Python package's build output are not pages.
            if !["target", "snapshots", "node_modules", ".venv"].contains(&name) {
                collect_md(&p, files);
            }
        } else if name.ends_with(".md") && (dir.ends_with("docs") || name == "README.md") {
            files.push(p);
        }
    }
}

fn binary_help(path: &[String]) -> Option<String> {
    let out = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(path)
        .arg("--help")
        .output()
        .expect("the realitygap binary runs");
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
}

#[test]
fn every_internal_link_in_the_guide_resolves() {
    let files = pages();
    assert!(files.len() > 10, "found only {files:?}");
    let problems = check_links(&files);
    let list: Vec<String> = problems.iter().map(|p| p.to_string()).collect();
    assert!(list.is_empty(), "broken links:\n{}", list.join("\n"));
}

#[test]
fn every_command_in_the_guide_exists_with_its_options() {
    let files = pages();
    let mut count = 0;
    let mut help = |path: &[String]| {
        count += 1;
        binary_help(path)
    };
    let problems = check_commands(&files, &mut help);
    let list: Vec<String> = problems.iter().map(|p| p.to_string()).collect();
    assert!(
        list.is_empty(),
        "commands that do not exist:\n{}",
        list.join("\n")
    );
    // The README alone shows more than a handful of commands: the checker
    // really read them (it asked for the help of several).
    assert!(count >= 8, "only {count} help texts asked for");
}

/// The checker's own test: a page with a broken file link, a broken anchor,
/// an unknown command and an unknown option gets one problem for each, with
/// its line; the good links and commands beside them get none.
#[test]
fn the_checker_finds_broken_links_and_commands() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.md");
    let b = dir.path().join("b.md");
    std::fs::write(
        &b,
        "# Page B\n\n## Joint commands (position, velocity) in each engine\n",
    )
    .unwrap();
    std::fs::write(
        &a,
        "# Page A\n\
         See [B](b.md) and [its section](b.md#joint-commands-position-velocity-in-each-engine).\n\
         A [missing page](missing.md), a [missing heading](b.md#nowhere), [here](#page-a).\n\
         `[code](not-a-link.md)` is not a link.\n\
         \n\
         ```sh\n\
         # realitygap frobnicate is a comment\n\
         cargo run --release -- compare assets/x.toml --output t.md\n\
         cargo run --release -- frobnicate --now\n\
         realitygap import rosbag bag/ --robot r.urdf \\\n  --no-such-flag\n\
         ```\n",
    )
    .unwrap();
    let links = check_links(&[a.clone(), b.clone()]);
    let lines: Vec<(usize, bool)> = links
        .iter()
        .map(|p| {
            (
                p.line,
                p.what.contains("missing.md") || p.what.contains("#nowhere"),
            )
        })
        .collect();
    assert_eq!(lines, vec![(3, true), (3, true)], "{links:?}");

    let mut help = |path: &[String]| -> Option<String> {
        match path.join(" ").as_str() {
            "" => Some(
                "Commands:\n  compare  Compare\n  import   Import\n\nOptions:\n  -h, --help\n"
                    .into(),
            ),
            "compare" => Some("Options:\n      --output <FILE>  where\n  -h, --help\n".into()),
            "import" => Some("Commands:\n  rosbag  A bag\n\nOptions:\n  -h, --help\n".into()),
            "import rosbag" => Some("Options:\n      --robot <URDF>\n  -h, --help\n".into()),
            _ => None,
        }
    };
    let problems = check_commands(&[a], &mut help);
    let found: Vec<(usize, String)> = problems.iter().map(|p| (p.line, p.what.clone())).collect();
    assert_eq!(found.len(), 2, "{found:?}");
    assert_eq!(found[0].0, 9);
    assert!(found[0].1.contains("frobnicate"), "{found:?}");
    assert_eq!(found[1].0, 10);
    assert!(found[1].1.contains("--no-such-flag"), "{found:?}");
}

#[test]
fn the_readme_fits_on_a_few_screens() {
    let text = std::fs::read_to_string(workspace().join("README.md")).unwrap();
    let lines = text.lines().count();
    assert!(
        lines <= 250,
        "README.md has {lines} lines; the guide in docs/ is the place for detail"
    );
}
