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
        Lines { rest: bytes, number: 0 }
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
        let (mut line, terminated) = match self.rest.iter().position(|&b| b == b'\n') {
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
        Some(Line { number: self.number, bytes: line, terminated })
    }
}

/// Powers of ten that are exact in an `f64`.
const EXACT_POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19,
    1e20, 1e21, 1e22,
];

/// Parses a decimal number (`-12.345`, `1e17`, `2.07E-19`, `nan`, `inf`,
/// `-inf`, ...) from bytes. `None` when the cell is not a number.
///
/// Plain decimals with at most 15 significant digits (every Qualisys cell)
/// take an exact fast path: the integer mantissa and the power of ten are
/// both exact in an `f64`, so one division gives the correctly rounded
/// result. Everything else goes through the standard library's parser.
#[inline]
pub(crate) fn parse_f64(cell: &[u8]) -> Option<f64> {
    let (negative, digits) = match cell.first() {
        Some(b'-') => (true, &cell[1..]),
        Some(b'+') => (false, &cell[1..]),
        _ => (false, cell),
    };
    let mut mantissa: u64 = 0;
    let mut count = 0usize;
    let mut frac_digits = 0usize;
    let mut seen_point = false;
    let mut fast = !digits.is_empty() && digits.len() <= 16;
    if fast {
        for &b in digits {
            match b {
                b'0'..=b'9' => {
                    mantissa = mantissa * 10 + u64::from(b - b'0');
                    count += 1;
                    if seen_point {
                        frac_digits += 1;
                    }
                }
                b'.' if !seen_point => seen_point = true,
                _ => {
                    fast = false;
                    break;
                }
            }
        }
    }
    if fast && count > 0 && count <= 15 {
        let value = mantissa as f64 / EXACT_POW10[frac_digits];
        return Some(if negative { -value } else { value });
    }
    std::str::from_utf8(cell).ok()?.parse().ok()
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
        let v: Vec<_> = Lines::new(b"\xEF\xBB\xBFa\r\nb\n\nc").map(|l| (l.number, l.bytes, l.terminated)).collect();
        assert_eq!(v, vec![(1, &b"a"[..], true), (2, &b"b"[..], true), (3, &b""[..], true), (4, &b"c"[..], false)]);
        assert_eq!(Lines::new(b"").count(), 0);
        assert_eq!(Lines::new(b"x\n").count(), 1);
    }

    #[test]
    fn fast_path_agrees_with_std() {
        for s in [
            "0", "-0", "-0.0", "1", "12.5", "-872.12345", "0.00001", "999999999999999", "0.999999999999999",
            "123456789012345", "1234567890123456", "0.1234567890123456789", "1e17", "2.07310114618026E-19",
            "+3.25", ".5", "5.", "-.5", "NaN", "nan", "inf", "-inf", "Infinity", "0.06706189529703803",
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
    fn rejects_non_numbers() {
        for s in ["", "-", "+", ".", "abc", "1.2.3", "1,5", " 1", "1 ", "--1", "0x10", "1e", "\u{ff}"] {
            assert_eq!(parse_f64(s.as_bytes()), None, "{s:?}");
        }
        assert_eq!(parse_f64(&[0xff, b'1']), None);
    }
}
