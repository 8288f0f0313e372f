//! Byte-level helpers shared by the readers: line splitting and number
//! parsing straight from `&[u8]`, with no allocation per line or cell.

/// One line of a file.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Line<'a> {
    /// 1-based line number.
    pub number: usize,
    /// The line's bytes without its line end (`\n` or `\r\n`).
    pub bytes: &'a [u8],
    /// False for a last line that has no line end (possibly cut short).
    pub terminated: bool,
}

/// Splits a buffer into lines (LF or CRLF line ends).
pub(crate) struct Lines<'a> {
    rest: &'a [u8],
    number: usize,
}

impl<'a> Lines<'a> {
    /// Lines of `bytes`, after dropping a UTF-8 byte-order mark.
    pub fn new(bytes: &'a [u8]) -> Self {
        let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
        Lines {
            rest: bytes,
            number: 0,
        }
    }
}

impl<'a> Lines<'a> {
    /// The input not yet split into lines.
    pub fn rest(&self) -> &'a [u8] {
        self.rest
    }
}

impl<'a> Iterator for Lines<'a> {
    type Item = Line<'a>;

    #[inline]
    fn next(&mut self) -> Option<Line<'a>> {
        if self.rest.is_empty() {
            return None;
        }
        self.number += 1;
        let (mut line, terminated) = match find_byte(self.rest, b'\n') {
            Some(i) => {
                let line = &self.rest[..i];
                self.rest = &self.rest[i + 1..];
                (line, true)
            }
            None => (std::mem::take(&mut self.rest), false),
        };
        if let [head @ .., b'\r'] = line {
            line = head;
        }
        Some(Line {
            number: self.number,
            bytes: line,
            terminated,
        })
    }
}

const ONES: u64 = 0x0101_0101_0101_0101;
const LOW7: u64 = 0x7f7f_7f7f_7f7f_7f7f;
const HIGH: u64 = 0x8080_8080_8080_8080;

/// The high bit of every byte of `word` that equals `c` (exact: no false
/// positives, unlike the shorter zero-byte trick).
#[inline]
fn byte_mask(word: u64, c: u8) -> u64 {
    let x = word ^ (ONES * u64::from(c));
    !(((x & LOW7) + LOW7) | x) & HIGH
}

/// The 8 bytes at `i` as a little-endian word.
#[inline]
fn word_at(bytes: &[u8], i: usize) -> u64 {
    let mut w = [0u8; 8];
    w.copy_from_slice(&bytes[i..i + 8]);
    u64::from_le_bytes(w)
}

/// Index of the first `c` in `bytes`, 8 bytes at a time.
#[inline]
pub(crate) fn find_byte(bytes: &[u8], c: u8) -> Option<usize> {
    let mut i = 0;
    while i + 8 <= bytes.len() {
        let m = byte_mask(word_at(bytes, i), c);
        if m != 0 {
            return Some(i + (m.trailing_zeros() / 8) as usize);
        }
        i += 8;
    }
    bytes[i..].iter().position(|&b| b == c).map(|p| i + p)
}

/// Splits the first line of `bytes` into tab-separated fields (appended to
/// `fields`; a `\r` before the line end is dropped), scanning once, 8 bytes
/// at a time. Returns the bytes consumed (including the `\n`) and whether
/// the line had a line end.
#[inline]
pub(crate) fn split_tab_line<'a>(bytes: &'a [u8], fields: &mut Vec<&'a [u8]>) -> (usize, bool) {
    let finish = |fields: &mut Vec<&'a [u8]>, start: usize, end: usize| {
        let mut last = &bytes[start..end];
        if let [head @ .., b'\r'] = last {
            last = head;
        }
        fields.push(last);
    };
    let mut start = 0;
    let mut i = 0;
    while i + 8 <= bytes.len() {
        let w = word_at(bytes, i);
        let mut m = byte_mask(w, b'\t') | byte_mask(w, b'\n');
        while m != 0 {
            let j = i + (m.trailing_zeros() / 8) as usize;
            if bytes[j] == b'\n' {
                finish(fields, start, j);
                return (j + 1, true);
            }
            fields.push(&bytes[start..j]);
            start = j + 1;
            m &= m - 1;
        }
        i += 8;
    }
    while i < bytes.len() {
        match bytes[i] {
            b'\n' => {
                finish(fields, start, i);
                return (i + 1, true);
            }
            b'\t' => {
                fields.push(&bytes[start..i]);
                start = i + 1;
            }
            _ => {}
        }
        i += 1;
    }
    finish(fields, start, bytes.len());
    (bytes.len(), false)
}

/// Powers of ten that are exact in an `f64`.
const EXACT_POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// Parses a decimal number (`-12.345`, `1e17`, `2.07E-19`, `nan`, `inf`,
/// `-inf`, ...) from bytes. `None` when the cell is not a number.
#[inline]
pub(crate) fn parse_f64(cell: &[u8]) -> Option<f64> {
    match exact_fast_path(cell) {
        Some(v) => Some(v),
        None => std::str::from_utf8(cell).ok()?.parse().ok(),
    }
}

/// [`parse_f64`] for text already known to be UTF-8 (saves validating
/// every cell when the whole line was validated once).
#[inline]
pub(crate) fn parse_f64_str(cell: &str) -> Option<f64> {
    match exact_fast_path(cell.as_bytes()) {
        Some(v) => Some(v),
        None => cell.parse().ok(),
    }
}

/// Plain decimals (`-872.12345`) with at most 15 significant digits: the
/// integer mantissa and the power of ten are both exact in an `f64`, so one
/// division gives the correctly rounded result (every Qualisys cell takes
/// this path). `None` for anything else, which the standard library's
/// parser then handles.
#[inline]
fn exact_fast_path(cell: &[u8]) -> Option<f64> {
    let (negative, digits) = match cell.first() {
        Some(b'-') => (true, &cell[1..]),
        Some(b'+') => (false, &cell[1..]),
        _ => (false, cell),
    };
    if digits.is_empty() || digits.len() > 16 {
        return None;
    }
    let mut mantissa: u64 = 0;
    let mut count = 0usize;
    let mut frac_digits = 0usize;
    let mut seen_point = false;
    for &b in digits {
        match b {
            b'0'..=b'9' => {
                mantissa = mantissa * 10 + u64::from(b - b'0');
                count += 1;
                frac_digits += usize::from(seen_point);
            }
            b'.' if !seen_point => seen_point = true,
            _ => return None,
        }
    }
    if count == 0 || count > 15 {
        return None;
    }
    let value = mantissa as f64 / EXACT_POW10[frac_digits];
    Some(if negative { -value } else { value })
}

/// True when the line holds only spaces (a blank line).
#[inline]
pub(crate) fn is_blank(line: &[u8]) -> bool {
    line.iter().all(|&b| b == b' ')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_handle_crlf_lf_and_missing_final_newline() {
        let v: Vec<_> = Lines::new(b"\xEF\xBB\xBFa\r\nb\n\nc")
            .map(|l| (l.number, l.bytes, l.terminated))
            .collect();
        assert_eq!(
            v,
            vec![
                (1, &b"a"[..], true),
                (2, &b"b"[..], true),
                (3, &b""[..], true),
                (4, &b"c"[..], false)
            ]
        );
        assert_eq!(Lines::new(b"").count(), 0);
        assert_eq!(Lines::new(b"x\n").count(), 1);
    }

    #[test]
    fn find_byte_and_split_tab_line_agree_with_naive() {
        let samples: [&[u8]; 7] = [
            b"",
            b"a\tb\tc",
            b"1\t0.00000\t-0.10689\t1.90247\t\t\r\nnext\tline\n",
            b"\n",
            b"\t\t\t\t\t\t\t\t\t\t\n",
            b"0123456789abcdef\x08\t\x0b\n\x08\x0b\t",
            b"\xff\xfe\t\x89\x8a\x0a\x09\x8a\x89",
        ];
        for s in samples {
            for c in [b'\n', b'\t', b'a', 0x89] {
                assert_eq!(find_byte(s, c), s.iter().position(|&b| b == c), "{s:?} {c}");
            }
            let mut fields = Vec::new();
            let (used, terminated) = split_tab_line(s, &mut fields);
            let line = Lines::new(s).next();
            match line {
                None => assert_eq!((used, fields, terminated), (0, vec![&b""[..]], false)),
                Some(l) => {
                    let naive: Vec<&[u8]> = l.bytes.split(|&b| b == b'\t').collect();
                    assert_eq!(fields, naive, "{s:?}");
                    assert_eq!(terminated, l.terminated);
                    assert_eq!(used, find_byte(s, b'\n').map_or(s.len(), |i| i + 1));
                }
            }
        }
    }

    #[test]
    fn fast_path_agrees_with_std() {
        for s in [
            "0",
            "-0",
            "-0.0",
            "1",
            "12.5",
            "-872.12345",
            "0.00001",
            "999999999999999",
            "0.999999999999999",
            "123456789012345",
            "1234567890123456",
            "0.1234567890123456789",
            "1e17",
            "2.07310114618026E-19",
            "+3.25",
            ".5",
            "5.",
            "-.5",
            "NaN",
            "nan",
            "inf",
            "-inf",
            "Infinity",
            "0.06706189529703803",
        ] {
            let ours = parse_f64(s.as_bytes());
            let std: Option<f64> = s.parse().ok();
            match (ours, std) {
                (Some(a), Some(b)) if a.is_nan() => assert!(b.is_nan(), "{s}"),
                (Some(a), Some(b)) => assert_eq!(a.to_bits(), b.to_bits(), "{s}"),
                (a, b) => assert_eq!(a, b, "{s}"),
            }
        }
    }

    #[test]
    fn str_variant_agrees() {
        for s in ["1.5", "-0.06706189529703803", "nan", "1e17", "x", ""] {
            assert_eq!(
                parse_f64_str(s).map(f64::to_bits),
                parse_f64(s.as_bytes()).map(f64::to_bits),
                "{s}"
            );
        }
    }

    #[test]
    fn rejects_non_numbers() {
        for s in [
            "", "-", "+", ".", "abc", "1.2.3", "1,5", " 1", "1 ", "--1", "0x10", "1e", "\u{ff}",
        ] {
            assert_eq!(parse_f64(s.as_bytes()), None, "{s:?}");
        }
        assert_eq!(parse_f64(&[0xff, b'1']), None);
    }
}
