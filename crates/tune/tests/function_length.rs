//! No function of the tune crate runs over [`LIMIT`] lines (from its `fn`
//! line to its closing brace): a cross-validation runs the whole fit many
//! times, and its stages are meant to stay small enough to read and change
//! one at a time (`src/stages/`).

use std::path::{Path, PathBuf};

/// Lines a function may span at most.
const LIMIT: usize = 150;

/// `src` with its comments, strings and character literals blanked (their
/// newlines kept), so that braces are only the code's.
fn code_only(src: &str) -> Vec<u8> {
    let b = src.as_bytes();
    let mut out = b.to_vec();
    let blank = |out: &mut Vec<u8>, from: usize, to: usize| {
        for c in out.iter_mut().take(to.min(b.len())).skip(from) {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    };
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let mut i = 0;
    while i < b.len() {
        let rest = &b[i..];
        if rest.starts_with(b"//") {
            let end = rest
                .iter()
                .position(|&c| c == b'\n')
                .map_or(b.len(), |p| i + p);
            blank(&mut out, i, end);
            i = end;
        } else if rest.starts_with(b"/*") {
            let end = find(b, i + 2, b"*/").map_or(b.len(), |p| p + 2);
            blank(&mut out, i, end);
            i = end;
        } else if rest[0] == b'r' && (i == 0 || !ident(b[i - 1])) && raw_quote(rest).is_some() {
            let (open, hashes) = raw_quote(rest).unwrap_or((0, 0));
            let mut close = vec![b'"'];
            close.extend(std::iter::repeat_n(b'#', hashes));
            let end = find(b, i + open, &close).map_or(b.len(), |p| p + close.len());
            blank(&mut out, i, end);
            i = end;
        } else if rest[0] == b'"' {
            let mut j = i + 1;
            while j < b.len() && b[j] != b'"' {
                j += if b[j] == b'\\' { 2 } else { 1 };
            }
            blank(&mut out, i, j + 1);
            i = j + 1;
        } else if rest[0] == b'\'' && char_literal(rest).is_some() {
            let len = char_literal(rest).unwrap_or(1);
            blank(&mut out, i, i + len);
            i += len;
        } else {
            i += 1;
        }
    }
    out
}

fn find(b: &[u8], from: usize, what: &[u8]) -> Option<usize> {
    (from..b.len().saturating_sub(what.len() - 1)).find(|&p| b[p..].starts_with(what))
}

/// `r"`, `r#"`, ...: the opening's length and the hashes.
fn raw_quote(s: &[u8]) -> Option<(usize, usize)> {
    let hashes = s[1..].iter().take_while(|&&c| c == b'#').count();
    (s.get(1 + hashes) == Some(&b'"')).then_some((hashes + 2, hashes))
}

/// A character literal's length (`'a'`, `'\n'`, `'\''`), or `None` for a
/// lifetime.
fn char_literal(s: &[u8]) -> Option<usize> {
    match s {
        [b'\'', b'\\', b'u', b'{', ..] => s.iter().position(|&c| c == b'}').map(|p| p + 2),
        [b'\'', b'\\', _, b'\'', ..] => Some(4),
        [b'\'', c, b'\'', ..] if *c != b'\\' => Some(3),
        _ => {
            // A multi-byte character.
            let text = std::str::from_utf8(&s[1..s.len().min(6)])
                .ok()
                .or_else(|| {
                    (2..6)
                        .rev()
                        .find_map(|n| std::str::from_utf8(&s[1..s.len().min(n)]).ok())
                })?;
            let c = text.chars().next()?;
            (c.len_utf8() > 1 && s.get(1 + c.len_utf8()) == Some(&b'\''))
                .then_some(2 + c.len_utf8())
        }
    }
}

/// Every function with a body in `src`: (name, first line, lines).
fn functions(src: &str) -> Vec<(String, usize, usize)> {
    let code = code_only(src);
    let line_of = |p: usize| code[..p].iter().filter(|&&c| c == b'\n').count() + 1;
    let mut found = Vec::new();
    let mut i = 0;
    while let Some(p) = find(&code, i, b"fn ") {
        i = p + 3;
        if p > 0 && (code[p - 1].is_ascii_alphanumeric() || code[p - 1] == b'_') {
            continue;
        }
        let name: String = code[p + 3..]
            .iter()
            .skip_while(|c| c.is_ascii_whitespace())
            .take_while(|&&c| c.is_ascii_alphanumeric() || c == b'_')
            .map(|&c| c as char)
            .collect();
        if name.is_empty() {
            continue;
        }
        // The body: the first `{` before a `;` outside brackets (a
        // declaration has none; `[f64; 2]` in the signature is no end).
        let Some(open) = body_start(&code, p) else {
            continue;
        };
        let mut depth = 0usize;
        let mut close = None;
        for (q, &c) in code.iter().enumerate().skip(open) {
            match c {
                b'{' => depth += 1,
                b'}' => {
                    depth -= 1;
                    if depth == 0 {
                        close = Some(q);
                        break;
                    }
                }
                _ => {}
            }
        }
        let Some(close) = close else { continue };
        let first = line_of(p);
        found.push((name, first, line_of(close) - first + 1));
    }
    found
}

/// Where the body of the function whose `fn` is at `from` opens: the
/// first `{` outside parentheses and square brackets, unless a `;` comes
/// first there.
fn body_start(code: &[u8], from: usize) -> Option<usize> {
    let mut depth = 0i64;
    for (q, &c) in code.iter().enumerate().skip(from) {
        match c {
            b'(' | b'[' => depth += 1,
            b')' | b']' => depth -= 1,
            b'{' if depth == 0 => return Some(q),
            b';' if depth == 0 => return None,
            _ => {}
        }
    }
    None
}

fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("a directory entry").path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            sources(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

#[test]
fn no_function_of_the_tune_crate_is_over_the_limit() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    sources(&root.join("src"), &mut files);
    sources(&root.join("tests"), &mut files);
    assert!(files.len() > 5, "the crate's sources: {files:?}");
    let mut long = Vec::new();
    for file in &files {
        let src = std::fs::read_to_string(file).expect("a source file");
        for (name, line, lines) in functions(&src) {
            if lines > LIMIT {
                long.push(format!(
                    "{}:{line}: fn {name}, {lines} lines",
                    file.strip_prefix(root).unwrap_or(file).display()
                ));
            }
        }
    }
    assert!(
        long.is_empty(),
        "functions over {LIMIT} lines (split them into stages):\n{}",
        long.join("\n")
    );
}

#[test]
fn the_counter_sees_long_functions_through_strings_and_comments() {
    let mut src = String::from(
        "/// fn doc() {\nfn short(x: &str) -> char {\n    let _ = \"}\";\n    '}'\n}\n",
    );
    src.push_str("pub(crate) fn long<'a>(v: &'a [u8]) -> &'a [u8] {\n");
    for k in 0..LIMIT {
        src.push_str(&format!("    // {k} }}\n    let _s = r#\"{{\"#;\n"));
    }
    src.push_str("    v\n}\ntrait T { fn declared(&self); }\n");
    src.push_str("fn pairs() -> Vec<[f64; 2]> {\n    vec![[0.0; 2]; 3]\n}\n");
    let found = functions(&src);
    let names: Vec<&str> = found.iter().map(|f| f.0.as_str()).collect();
    assert_eq!(names, ["short", "long", "pairs"], "{found:?}");
    assert_eq!(found[2].2, 3);
    assert_eq!((found[0].1, found[0].2), (2, 4));
    assert_eq!(found[1].2, 2 * LIMIT + 3);
}
