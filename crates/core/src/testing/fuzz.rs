//! Damage campaigns for the importers' tests: real files as seeds, damaged
//! by deterministic, seeded mutations (bit flips, inserted and deleted
//! bytes, truncation, length fields set to huge values, numbers replaced
//! by `NaN`/`inf`/`1e308`/huge integers, lines and XML elements or
//! attributes deleted or duplicated), each fed to a reader that must
//! return `Ok` or an error naming the file: never panic, never abort,
//! never make one allocation larger than 64 x the input's size + 64 MiB.
//!
//! A test binary that runs a campaign installs a counting global allocator
//! ([`counting_global_allocator!`](crate::counting_global_allocator): it records the largest single request
//! of the current thread) and calls [`run_campaign_test`], which runs the campaign in a
//! child process (this test alone, again): an abort or a stack overflow
//! then fails the test with the input that caused it instead of killing
//! the test binary. Each input is named by its format and index; the
//! failure messages say how to run that one input again
//! (`REALITYGAP_FUZZ_ONLY=FORMAT:INDEX`), which also writes its bytes to a
//! file. `REALITYGAP_FUZZ_INPUTS` sets the damaged inputs per seed and
//! `REALITYGAP_FUZZ_SEED` changes the mutations, for longer local campaigns.

use std::cell::{Cell, RefCell};
use std::fmt::Write as _;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Environment variable set in the child process that runs a campaign.
const CHILD_ENV: &str = "REALITYGAP_FUZZ_CHILD";
/// `FORMAT:INDEX`: run that one input only (and write its bytes to a file).
pub const ONLY_ENV: &str = "REALITYGAP_FUZZ_ONLY";
/// Damaged inputs per seed, instead of each campaign's default (the same
/// variable as the joint-recording importers' campaign).
pub const INPUTS_ENV: &str = "REALITYGAP_FUZZ_INPUTS";
/// Seed of the mutations (default 0).
pub const SEED_ENV: &str = "REALITYGAP_FUZZ_SEED";

/// Requests above this are refused (the allocation fails and the process
/// aborts, which the parent test reports with the input): serving them
/// could exhaust the shared machine's memory.
const HARD_CAP: usize = 1 << 30;

thread_local! {
    static LARGEST: Cell<usize> = const { Cell::new(0) };
    static PANIC_MESSAGE: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// Records an allocation request of `size` bytes for the current thread's
/// largest ([`largest_allocation`]); false when the request must be
/// refused (above 1 GiB), after saying so on stderr. Called by the
/// allocator that [`counting_global_allocator!`](crate::counting_global_allocator) installs.
pub fn record_allocation(size: usize) -> bool {
    let _ = LARGEST.try_with(|l| l.set(l.get().max(size)));
    if size > HARD_CAP {
        // Format without allocating: the request is refused right after.
        let mut buf = [0u8; 96];
        let prefix = b"fuzz: refusing an allocation of ";
        let mut n = prefix.len();
        buf[..n].copy_from_slice(prefix);
        let mut digits = [0u8; 20];
        let (mut d, mut v) = (digits.len(), size);
        loop {
            d -= 1;
            digits[d] = b'0' + (v % 10) as u8;
            v /= 10;
            if v == 0 {
                break;
            }
        }
        let digits = &digits[d..];
        buf[n..n + digits.len()].copy_from_slice(digits);
        n += digits.len();
        let suffix = b" bytes\n";
        buf[n..n + suffix.len()].copy_from_slice(suffix);
        n += suffix.len();
        use std::io::Write;
        let _ = std::io::stderr().write_all(&buf[..n]);
        return false;
    }
    true
}

/// Installs, in a test binary, a global allocator that forwards to the
/// system's and records every request with [`record_allocation`]: the
/// campaign then knows the largest single allocation each input caused
/// ([`largest_allocation`]), and a request above 1 GiB is refused (the
/// child process aborts and its test fails, naming the input). In a macro
/// because a `GlobalAlloc` needs `unsafe`, which this crate forbids.
#[macro_export]
macro_rules! counting_global_allocator {
    () => {
        /// Forwards to the system allocator, recording each request's size.
        struct CountingAllocator;

        // SAFETY: every call forwards to `System` with the caller's
        // arguments after recording the size in a thread-local counter
        // (const-initialised, no destructor: it neither allocates nor
        // outlives its thread); a refused request returns null, which
        // `GlobalAlloc` allows.
        unsafe impl ::std::alloc::GlobalAlloc for CountingAllocator {
            unsafe fn alloc(&self, layout: ::std::alloc::Layout) -> *mut u8 {
                if !$crate::testing::fuzz::record_allocation(layout.size()) {
                    return ::std::ptr::null_mut();
                }
                // SAFETY: the caller's layout, as `alloc` requires.
                unsafe { ::std::alloc::GlobalAlloc::alloc(&::std::alloc::System, layout) }
            }
            unsafe fn alloc_zeroed(&self, layout: ::std::alloc::Layout) -> *mut u8 {
                if !$crate::testing::fuzz::record_allocation(layout.size()) {
                    return ::std::ptr::null_mut();
                }
                // SAFETY: the caller's layout, as `alloc_zeroed` requires.
                unsafe { ::std::alloc::GlobalAlloc::alloc_zeroed(&::std::alloc::System, layout) }
            }
            unsafe fn dealloc(&self, ptr: *mut u8, layout: ::std::alloc::Layout) {
                // SAFETY: `ptr` was allocated by `System` with this layout.
                unsafe { ::std::alloc::GlobalAlloc::dealloc(&::std::alloc::System, ptr, layout) }
            }
            unsafe fn realloc(
                &self,
                ptr: *mut u8,
                layout: ::std::alloc::Layout,
                new_size: usize,
            ) -> *mut u8 {
                if !$crate::testing::fuzz::record_allocation(new_size) {
                    return ::std::ptr::null_mut();
                }
                // SAFETY: `ptr` was allocated by `System` with `layout`, as
                // the caller guarantees.
                unsafe {
                    ::std::alloc::GlobalAlloc::realloc(&::std::alloc::System, ptr, layout, new_size)
                }
            }
        }

        #[global_allocator]
        static COUNTING_ALLOCATOR: CountingAllocator = CountingAllocator;
    };
}

/// True in the child process that [`run_campaign_test`] runs a campaign in.
pub fn in_campaign_child() -> bool {
    std::env::var_os(CHILD_ENV).is_some()
}

/// Starts a new measurement of the largest allocation on this thread.
pub fn reset_largest_allocation() {
    LARGEST.with(|l| l.set(0));
}

/// The largest single allocation request on this thread since
/// [`reset_largest_allocation`] (0 unless [`counting_global_allocator!`](crate::counting_global_allocator)
/// installed the global allocator).
pub fn largest_allocation() -> usize {
    LARGEST.with(Cell::get)
}

/// The largest allocation allowed for an input of `len` bytes: 64 x its
/// size + 64 MiB.
pub fn allocation_limit(len: usize) -> usize {
    len.saturating_mul(64).saturating_add(64 << 20)
}

/// A small deterministic generator (SplitMix64).
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Rng(seed)
    }
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// A number in `0..n` (0 when `n` is 0).
    pub fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next_u64() % n as u64) as usize
        }
    }
    /// True with probability `1/n`.
    pub fn one_in(&mut self, n: usize) -> bool {
        self.below(n) == 0
    }
    /// One element of a non-empty slice.
    pub fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }
}

/// One kind of damage.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Damage {
    /// One bit flipped.
    BitFlip,
    /// One byte set to a random value.
    Byte,
    /// Random bytes or a separator inserted.
    Insert,
    /// A span of up to 64 bytes deleted.
    Delete,
    /// The file cut short.
    Truncate,
    /// A span of up to 256 bytes copied elsewhere.
    DuplicateSpan,
    /// A number in the text replaced by `NaN`, `inf`, `1e308`, a huge
    /// integer, `-1`, nothing, ...
    Number,
    /// A line deleted.
    DeleteLine,
    /// A line repeated.
    DuplicateLine,
    /// Two lines swapped.
    SwapLines,
    /// An XML element deleted (start tag to matching end tag).
    DeleteElement,
    /// An XML element repeated.
    DuplicateElement,
    /// An XML attribute deleted.
    DeleteAttribute,
    /// An XML attribute repeated in its tag.
    DuplicateAttribute,
    /// A number in an XML attribute's value (a count, stride, offset,
    /// unit, limit) replaced like [`Damage::Number`].
    AttributeNumber,
    /// An XML element wrapped in thousands of nested elements.
    DeepNesting,
    /// A little-endian u32 at this offset (a length or count field) set to
    /// 0, 1, a neighbour of its value, 2^31 - 1, 2^32 - 1, ...
    LengthField(usize),
    /// A 4-byte-aligned little-endian f32 after this offset set to `NaN`,
    /// `inf`, `-inf`, `f32::MAX` or a subnormal.
    Float32(usize),
}

/// Text numbers that break readers: not finite, huge, negative, empty.
const NUMBERS: &[&str] = &[
    "NaN",
    "nan",
    "inf",
    "-inf",
    "Infinity",
    "1e308",
    "-1e308",
    "1e309",
    "1e-320",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "18446744073709551616",
    "99999999999999999999999999999999",
    "-1",
    "0",
    "-0",
    "0x10",
    "",
];

/// Bytes that separate or end things in the importers' formats.
const SEPARATORS: &[&[u8]] = &[
    b"\t", b"\n", b"\r\n", b"\r", b" ", b",", b"-", b".", b"e", b"<", b">", b"/", b"\"", b"=",
    b"\0", b"\xff", b"\xc3", b"</", b"/>", b"<!--", b"-->", b"&", b"&#0;", b"]]>",
];

/// A position: anywhere, or near the start (headers, length fields) or the
/// end.
fn position(rng: &mut Rng, len: usize) -> usize {
    match rng.below(10) {
        0..=4 => rng.below(len + 1),
        5..=7 => rng.below(len.min(4096) + 1),
        _ => len - rng.below(len.min(4096) + 1),
    }
}

fn is_number_start(bytes: &[u8], i: usize) -> bool {
    let b = bytes[i];
    let prev_ok = i == 0 || !(bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'.');
    prev_ok
        && (b.is_ascii_digit() || (b == b'-' && bytes.get(i + 1).is_some_and(u8::is_ascii_digit)))
}

/// The first number token at or after `from` (wrapping around once).
fn find_number(bytes: &[u8], from: usize) -> Option<(usize, usize)> {
    let start = (from..bytes.len())
        .chain(0..from.min(bytes.len()))
        .find(|&i| is_number_start(bytes, i))?;
    let mut end = start + 1;
    while end < bytes.len()
        && (bytes[end].is_ascii_digit()
            || matches!(bytes[end], b'.' | b'e' | b'E' | b'+')
            || (bytes[end] == b'-' && matches!(bytes[end - 1], b'e' | b'E')))
    {
        end += 1;
    }
    Some((start, end))
}

/// Line spans `[start, end)` including the line end.
fn lines(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = 0;
    for (i, &b) in bytes.iter().enumerate() {
        if b == b'\n' {
            out.push((start, i + 1));
            start = i + 1;
        }
    }
    if start < bytes.len() {
        out.push((start, bytes.len()));
    }
    out
}

/// The XML start tag at or after `from`: (start, end of start tag, name,
/// self-closing).
fn find_start_tag(bytes: &[u8], from: usize) -> Option<(usize, usize, Vec<u8>, bool)> {
    let mut i = from;
    loop {
        let rel = bytes.get(i..)?.iter().position(|&b| b == b'<')?;
        let start = i + rel;
        i = start + 1;
        if !bytes.get(start + 1).is_some_and(u8::is_ascii_alphabetic) {
            continue;
        }
        let name_end = (start + 1..bytes.len())
            .find(|&k| {
                !(bytes[k].is_ascii_alphanumeric() || matches!(bytes[k], b'_' | b':' | b'-' | b'.'))
            })
            .unwrap_or(bytes.len());
        let name = bytes[start + 1..name_end].to_vec();
        // The tag's end, skipping quoted values.
        let mut k = name_end;
        let mut quote = None;
        while k < bytes.len() {
            match (quote, bytes[k]) {
                (None, b'"' | b'\'') => quote = Some(bytes[k]),
                (Some(q), c) if c == q => quote = None,
                (None, b'>') => break,
                _ => {}
            }
            k += 1;
        }
        if k >= bytes.len() {
            return None;
        }
        let self_closing = bytes[k - 1] == b'/';
        return Some((start, k + 1, name, self_closing));
    }
}

/// The span of the element whose start tag is found at or after `from`.
fn find_element(bytes: &[u8], from: usize) -> Option<(usize, usize)> {
    let (start, tag_end, name, self_closing) =
        find_start_tag(bytes, from).or_else(|| find_start_tag(bytes, 0))?;
    if self_closing {
        return Some((start, tag_end));
    }
    let mut open = [b"<".as_slice(), &name].concat();
    let close = [b"</".as_slice(), &name, b">"].concat();
    open.push(b' ');
    let mut depth = 1;
    let mut k = tag_end;
    while k < bytes.len() {
        if bytes[k..].starts_with(&close) {
            depth -= 1;
            if depth == 0 {
                return Some((start, k + close.len()));
            }
            k += close.len();
        } else if bytes[k..].starts_with(&open[..open.len() - 1])
            && bytes
                .get(k + open.len() - 1)
                .is_some_and(|&c| c == b'>' || c.is_ascii_whitespace())
        {
            depth += 1;
            k += 1;
        } else {
            k += 1;
        }
    }
    Some((start, tag_end))
}

/// Attribute spans ` key="value"` inside a start tag.
fn attributes(bytes: &[u8], tag_start: usize, tag_end: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut k = tag_start + 1;
    while k < tag_end {
        if bytes[k].is_ascii_whitespace() {
            let ws = k;
            while k < tag_end && bytes[k].is_ascii_whitespace() {
                k += 1;
            }
            let key_start = k;
            while k < tag_end
                && bytes[k] != b'='
                && !bytes[k].is_ascii_whitespace()
                && bytes[k] != b'>'
            {
                k += 1;
            }
            if k + 1 < tag_end && bytes[k] == b'=' && key_start < k {
                let q = bytes[k + 1];
                if q == b'"' || q == b'\'' {
                    if let Some(rel) = bytes[k + 2..tag_end].iter().position(|&c| c == q) {
                        let end = k + 2 + rel + 1;
                        out.push((ws, end));
                        k = end;
                        continue;
                    }
                }
            }
        } else {
            k += 1;
        }
    }
    out
}

/// Applies one damage of `kind` to `bytes`; returns what was done, or
/// `None` when the kind does not apply (no number, no element, ...).
pub fn damage(bytes: &mut Vec<u8>, kind: Damage, rng: &mut Rng) -> Option<String> {
    let len = bytes.len();
    Some(match kind {
        Damage::BitFlip => {
            if len == 0 {
                return None;
            }
            let (i, bit) = (position(rng, len - 1), rng.below(8));
            bytes[i] ^= 1 << bit;
            format!("flip bit {bit} of byte {i}")
        }
        Damage::Byte => {
            if len == 0 {
                return None;
            }
            let (i, v) = (position(rng, len - 1), rng.below(256) as u8);
            bytes[i] = v;
            format!("set byte {i} to {v:#04x}")
        }
        Damage::Insert => {
            let i = position(rng, len);
            let what: Vec<u8> = if rng.one_in(2) {
                rng.pick(SEPARATORS).to_vec()
            } else {
                (0..1 + rng.below(16))
                    .map(|_| rng.below(256) as u8)
                    .collect()
            };
            let shown = String::from_utf8_lossy(&what).escape_debug().to_string();
            bytes.splice(i..i, what);
            format!("insert \"{shown}\" at byte {i}")
        }
        Damage::Delete => {
            if len == 0 {
                return None;
            }
            let i = position(rng, len - 1);
            let n = (1 + rng.below(64)).min(len - i);
            bytes.drain(i..i + n);
            format!("delete {n} bytes at {i}")
        }
        Damage::Truncate => {
            if len == 0 {
                return None;
            }
            let n = position(rng, len - 1);
            bytes.truncate(n);
            format!("truncate to {n} bytes")
        }
        Damage::DuplicateSpan => {
            if len == 0 {
                return None;
            }
            let i = rng.below(len);
            let n = (1 + rng.below(256)).min(len - i);
            let to = position(rng, len);
            let span = bytes[i..i + n].to_vec();
            bytes.splice(to..to, span);
            format!("copy {n} bytes from {i} to {to}")
        }
        Damage::Number => {
            let (start, end) = find_number(bytes, rng.below(len + 1))?;
            let old = String::from_utf8_lossy(&bytes[start..end]).into_owned();
            let new = *rng.pick(NUMBERS);
            bytes.splice(start..end, new.bytes());
            format!("replace the number \"{old}\" at byte {start} by \"{new}\"")
        }
        Damage::DeleteLine | Damage::DuplicateLine | Damage::SwapLines => {
            let spans = lines(bytes);
            if spans.is_empty() {
                return None;
            }
            let pick = |rng: &mut Rng| {
                if rng.one_in(2) {
                    rng.below(spans.len().min(20))
                } else {
                    rng.below(spans.len())
                }
            };
            let a = pick(rng);
            let (s, e) = spans[a];
            match kind {
                Damage::DeleteLine => {
                    bytes.drain(s..e);
                    format!("delete line {}", a + 1)
                }
                Damage::DuplicateLine => {
                    let line = bytes[s..e].to_vec();
                    bytes.splice(e..e, line);
                    format!("repeat line {}", a + 1)
                }
                _ => {
                    let b = pick(rng);
                    let (lo, hi) = (a.min(b), a.max(b));
                    if lo == hi {
                        return None;
                    }
                    let (x, y) = (spans[lo], spans[hi]);
                    let mut out = bytes[..x.0].to_vec();
                    out.extend_from_slice(&bytes[y.0..y.1]);
                    out.extend_from_slice(&bytes[x.1..y.0]);
                    out.extend_from_slice(&bytes[x.0..x.1]);
                    out.extend_from_slice(&bytes[y.1..]);
                    *bytes = out;
                    format!("swap lines {} and {}", lo + 1, hi + 1)
                }
            }
        }
        Damage::DeleteElement | Damage::DuplicateElement | Damage::DeepNesting => {
            let (s, e) = find_element(bytes, position(rng, len))?;
            let name = String::from_utf8_lossy(
                &bytes[s + 1
                    ..(s + 1..e)
                        .find(|&k| !bytes[k].is_ascii_alphanumeric() && bytes[k] != b'_')
                        .unwrap_or(e)],
            )
            .into_owned();
            match kind {
                Damage::DeleteElement => {
                    bytes.drain(s..e);
                    format!("delete the <{name}> element at byte {s}")
                }
                Damage::DuplicateElement => {
                    let copy = bytes[s..e].to_vec();
                    bytes.splice(e..e, copy);
                    format!("repeat the <{name}> element at byte {s}")
                }
                _ => {
                    let depth = 1000 + rng.below(20_000);
                    bytes.splice(e..e, b"</x>".repeat(depth));
                    bytes.splice(s..s, b"<x>".repeat(depth));
                    format!("nest the <{name}> element at byte {s} in {depth} elements")
                }
            }
        }
        Damage::DeleteAttribute | Damage::DuplicateAttribute => {
            let (s, tag_end, name, _) =
                find_start_tag(bytes, position(rng, len)).or_else(|| find_start_tag(bytes, 0))?;
            let attrs = attributes(bytes, s, tag_end);
            if attrs.is_empty() {
                return None;
            }
            let (a, b) = *rng.pick(&attrs);
            let shown = String::from_utf8_lossy(&bytes[a..b]).trim().to_string();
            let name = String::from_utf8_lossy(&name).into_owned();
            if kind == Damage::DeleteAttribute {
                bytes.drain(a..b);
                format!("delete the attribute {shown} of <{name}> at byte {s}")
            } else {
                let copy = bytes[a..b].to_vec();
                bytes.splice(b..b, copy);
                format!("repeat the attribute {shown} of <{name}> at byte {s}")
            }
        }
        Damage::AttributeNumber => {
            // Attributes that hold a number, from a random tag onwards.
            let mut from = position(rng, len);
            for _ in 0..64 {
                let (s, tag_end, _, _) =
                    find_start_tag(bytes, from).or_else(|| find_start_tag(bytes, 0))?;
                let numeric: Vec<(usize, usize)> = attributes(bytes, s, tag_end)
                    .into_iter()
                    .filter_map(|(a, b)| {
                        let eq = a + bytes[a..b].iter().position(|&c| c == b'=')?;
                        find_number(&bytes[..b - 1], eq + 2).filter(|&(n, _)| n > eq && n < b)
                    })
                    .collect();
                if numeric.is_empty() {
                    from = tag_end;
                    continue;
                }
                let (start, end) = *rng.pick(&numeric);
                let old = String::from_utf8_lossy(&bytes[start..end]).into_owned();
                let new = *rng.pick(NUMBERS);
                bytes.splice(start..end, new.bytes());
                return Some(format!(
                    "replace the number \"{old}\" in an attribute at byte {start} by \"{new}\""
                ));
            }
            return None;
        }
        Damage::LengthField(at) => {
            if len < at + 4 {
                return None;
            }
            let old = u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
            let new = *rng.pick(&[
                0,
                1,
                old.wrapping_add(1),
                old.wrapping_sub(1),
                old.wrapping_mul(2),
                0x7fff_ffff,
                0x8000_0000,
                0xffff_ffff,
                0x0100_0000,
                (len as u32).wrapping_mul(64),
            ]);
            bytes[at..at + 4].copy_from_slice(&new.to_le_bytes());
            format!("set the u32 at byte {at} from {old} to {new}")
        }
        Damage::Float32(from) => {
            if len < from + 4 {
                return None;
            }
            let slots = (len - from) / 4;
            let at = from + 4 * rng.below(slots);
            let (v, shown) = *rng.pick(&[
                (f32::NAN, "NaN"),
                (f32::INFINITY, "inf"),
                (f32::NEG_INFINITY, "-inf"),
                (f32::MAX, "f32::MAX"),
                (-f32::MAX, "-f32::MAX"),
                (1e-45, "1e-45"),
            ]);
            bytes[at..at + 4].copy_from_slice(&v.to_le_bytes());
            format!("set the f32 at byte {at} to {shown}")
        }
    })
}

/// A real file that damaged inputs start from.
#[derive(Debug, Clone)]
pub struct Seed {
    /// The file, as the reader is told it (errors must name it).
    pub path: PathBuf,
    /// A short name for reports (the file name, or what was cut from it).
    pub name: String,
    /// Its content.
    pub bytes: Vec<u8>,
    /// Whether the seed itself must read without error.
    pub valid: bool,
}

impl Seed {
    /// The file's content as a valid seed.
    pub fn file(path: &Path) -> Seed {
        let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        Seed {
            path: path.to_path_buf(),
            name: file_name(path),
            bytes,
            valid: true,
        }
    }
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

/// A campaign on one format: damaged copies of its seeds, each fed to a
/// reader.
#[derive(Debug, Clone)]
pub struct Campaign {
    /// The format's name in reports and in `REALITYGAP_FUZZ_ONLY`.
    pub format: String,
    /// Real files to damage.
    pub seeds: Vec<Seed>,
    /// Damaged inputs per seed (run after the seeds themselves), unless
    /// `REALITYGAP_FUZZ_INPUTS` says otherwise.
    pub per_seed: usize,
    /// The kinds of damage, with weights.
    pub damages: Vec<(Damage, u32)>,
}

/// The outcome of a campaign.
#[derive(Debug, Clone, Default)]
pub struct Report {
    /// The format.
    pub format: String,
    /// Inputs run (the seeds and their damaged copies).
    pub inputs: usize,
    /// Inputs read without error.
    pub ok: usize,
    /// Inputs refused with an error.
    pub errors: usize,
    /// Bytes read, all inputs together.
    pub bytes: usize,
    /// The largest single allocation and the input size it was made for.
    pub largest_allocation: (usize, usize),
    /// Panics, oversized allocations, errors that do not name the file, and
    /// seeds that do not read: one line each, with the input's name.
    pub failures: Vec<String>,
    /// Wall time, seconds.
    pub seconds: f64,
}

impl Report {
    /// One line: inputs, outcomes, the largest allocation, failures.
    pub fn summary(&self) -> String {
        format!(
            "fuzz {}: {} inputs ({:.1} MB), {} ok, {} errors; {} failures; largest allocation {:.2} MB for a {:.2} MB input; {:.1} s",
            self.format,
            self.inputs,
            self.bytes as f64 / 1e6,
            self.ok,
            self.errors,
            self.failures.len(),
            self.largest_allocation.0 as f64 / 1e6,
            self.largest_allocation.1 as f64 / 1e6,
            self.seconds
        )
    }
}

fn env_usize(name: &str) -> Option<usize> {
    let v = std::env::var(name).ok()?;
    Some(
        v.trim()
            .parse()
            .unwrap_or_else(|_| panic!("{name}={v}: expected a number")),
    )
}

/// The panic hook while a campaign runs: keeps the message and where it
/// happened, prints nothing.
fn quiet_hook(info: &std::panic::PanicHookInfo<'_>) {
    let payload = info.payload();
    let message = payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(no message)".into());
    let at = info
        .location()
        .map(|l| format!(" at {}:{}", l.file(), l.line()))
        .unwrap_or_default();
    PANIC_MESSAGE.with(|m| *m.borrow_mut() = Some(format!("{message}{at}")));
}

impl Campaign {
    /// The input `index` (0-based; the seeds come first, undamaged), with
    /// its seed and a description of its damage.
    pub fn input(&self, index: usize, seed: u64) -> (&Seed, Vec<u8>, String) {
        if index < self.seeds.len() {
            let s = &self.seeds[index];
            return (s, s.bytes.clone(), "undamaged".into());
        }
        let mut rng = Rng::new(
            seed.wrapping_mul(0x2545_F491_4F6C_DD1D)
                ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ self
                    .format
                    .bytes()
                    .fold(0u64, |h, b| h.wrapping_mul(31).wrapping_add(b.into())),
        );
        let s = rng.pick(&self.seeds);
        let mut bytes = s.bytes.clone();
        let total: u32 = self.damages.iter().map(|d| d.1).sum();
        let count = if rng.one_in(3) { 2 + rng.below(3) } else { 1 };
        let mut done = Vec::new();
        let mut attempts = 0;
        while done.len() < count && attempts < 20 {
            attempts += 1;
            let mut w = rng.below(total as usize) as u32;
            let kind = self
                .damages
                .iter()
                .find(|(_, weight)| {
                    if w < *weight {
                        true
                    } else {
                        w -= weight;
                        false
                    }
                })
                .map(|d| d.0)
                .unwrap_or(Damage::BitFlip);
            if let Some(what) = damage(&mut bytes, kind, &mut rng) {
                done.push(what);
            }
        }
        (s, bytes, done.join("; "))
    }

    /// Runs the seeds and the damaged inputs through `read`, which returns
    /// the reader's error as text; checks every outcome.
    pub fn run(&self, read: impl Fn(&[u8], &Path) -> Result<(), String>) -> Report {
        let seed = env_usize(SEED_ENV).unwrap_or(0) as u64;
        let damaged = env_usize(INPUTS_ENV).unwrap_or(self.per_seed) * self.seeds.len();
        let total = self.seeds.len() + damaged;
        let only: Option<usize> = std::env::var(ONLY_ENV).ok().and_then(|v| {
            let (format, index) = v.split_once(':')?;
            (format == self.format)
                .then(|| index.parse().expect("REALITYGAP_FUZZ_ONLY=FORMAT:INDEX"))
        });
        let child = std::env::var_os(CHILD_ENV).is_some();
        let mut report = Report {
            format: self.format.clone(),
            ..Report::default()
        };
        let started = Instant::now();
        let previous_hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(quiet_hook));
        for index in 0..total {
            if only.is_some_and(|o| o != index) {
                continue;
            }
            let (seed_file, bytes, what) = self.input(index, seed);
            let label = format!("{}:{index} (seed {}; {what})", self.format, seed_file.name);
            if only.is_some() {
                let out = std::env::temp_dir()
                    .join(format!("realitygap-fuzz-{}-{index}.bin", self.format));
                std::fs::write(&out, &bytes).unwrap();
                println!(
                    "input {label}: {} bytes, written to {}",
                    bytes.len(),
                    out.display()
                );
            }
            if child {
                // The last line before an abort names its input.
                eprintln!("input {label}");
            }
            PANIC_MESSAGE.with(|m| *m.borrow_mut() = None);
            reset_largest_allocation();
            let outcome = catch_unwind(AssertUnwindSafe(|| read(&bytes, &seed_file.path)));
            if only.is_some() {
                println!("outcome: {outcome:?}");
            }
            let largest = largest_allocation();
            report.inputs += 1;
            report.bytes += bytes.len();
            if largest > report.largest_allocation.0 {
                report.largest_allocation = (largest, bytes.len());
            }
            if largest > allocation_limit(bytes.len()) {
                report.failures.push(format!(
                    "{label}: an allocation of {largest} bytes for an input of {} bytes",
                    bytes.len()
                ));
            }
            // A panic caught inside the reader is a failure too.
            if let Some(message) = PANIC_MESSAGE.with(|m| m.borrow_mut().take()) {
                report
                    .failures
                    .push(format!("{label}: panicked: {message}"));
                if outcome.is_err() {
                    continue;
                }
            }
            match outcome {
                Ok(Ok(())) => report.ok += 1,
                Ok(Err(e)) => {
                    report.errors += 1;
                    let name = file_name(&seed_file.path);
                    if !e.contains(&name) {
                        report
                            .failures
                            .push(format!("{label}: the error does not name {name}: {e}"));
                    }
                    if seed_file.valid && index < self.seeds.len() {
                        report
                            .failures
                            .push(format!("{label}: the undamaged seed does not read: {e}"));
                    }
                }
                Err(_) => report.failures.push(format!("{label}: panicked")),
            }
        }
        std::panic::set_hook(previous_hook);
        report.seconds = started.elapsed().as_secs_f64();
        report
    }
}

/// Runs a campaign test: in a child process (this test binary, `test`
/// alone) unless this is that child, where `campaign` builds the campaign
/// and `read` reads one input. Prints the report's summary; fails on any
/// failure, with how to run the failing input alone, and on a child that
/// aborts, with the input it was reading.
pub fn run_campaign_test(
    test: &str,
    campaign: impl FnOnce() -> Campaign,
    read: impl Fn(&[u8], &Path) -> Result<(), String>,
) -> Report {
    if let Some(out) = super::rerun_in_child(test, CHILD_ENV) {
        let stdout = String::from_utf8_lossy(&out.stdout);
        print!("{stdout}");
        if !out.status.success() {
            let stderr = String::from_utf8_lossy(&out.stderr);
            let tail: Vec<&str> = stderr
                .lines()
                .rev()
                .filter(|l| {
                    !(l.starts_with(' ')
                        || l.starts_with("stack backtrace")
                        || l.starts_with("note:"))
                })
                .take(12)
                .collect();
            let tail: Vec<&str> = tail.into_iter().rev().collect();
            let failures: Vec<&str> = stdout.lines().filter(|l| l.starts_with("  ")).collect();
            panic!(
                "the campaign's child process failed ({}); its failures:\n{}\nthe end of its stderr (the last input line \
                 names the input; run it alone with {ONLY_ENV}=FORMAT:INDEX):\n{}",
                out.status,
                failures.join("\n"),
                tail.join("\n")
            );
        }
        return Report::default();
    }
    let campaign = campaign();
    let report = campaign.run(read);
    println!("{}", report.summary());
    if !report.failures.is_empty() {
        let mut message = String::new();
        for f in report.failures.iter().take(20) {
            let _ = writeln!(message, "  {f}");
        }
        print!("{message}");
        panic!(
            "{} failures in the {} campaign (run one alone with {ONLY_ENV}=FORMAT:INDEX):\n{message}",
            report.failures.len(),
            report.format
        );
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn damages_are_deterministic_and_do_what_they_say() {
        let xml = b"<robot name=\"r\">\n  <link name=\"a\"><inertial><mass value=\"1.5\"/></inertial></link>\n  <joint name=\"j\" type=\"fixed\"/>\n</robot>\n".to_vec();
        let mut rng = Rng::new(1);
        let mut a = xml.clone();
        let what = damage(&mut a, Damage::Number, &mut rng).unwrap();
        assert!(what.contains("\"1.5\""), "{what}");
        assert!(!a.windows(3).any(|w| w == b"1.5"));
        // The element found from the start is <robot>, the whole document.
        assert_eq!(find_element(&xml, 0), Some((0, xml.len() - 1)));
        let link = find_element(&xml, 5).unwrap();
        assert!(
            xml[link.0..link.1].starts_with(b"<link") && xml[link.0..link.1].ends_with(b"</link>")
        );
        let tag = find_start_tag(&xml, 0).unwrap();
        assert_eq!(attributes(&xml, tag.0, tag.1), vec![(6, 15)]);
        assert_eq!(lines(&xml).len(), 4);
        let campaign = Campaign {
            format: "t".into(),
            seeds: vec![Seed {
                path: "x".into(),
                name: "x".into(),
                bytes: xml.clone(),
                valid: true,
            }],
            per_seed: 10,
            damages: vec![
                (Damage::DeleteElement, 1),
                (Damage::LengthField(4), 1),
                (Damage::SwapLines, 1),
            ],
        };
        for i in 0..11 {
            assert_eq!(campaign.input(i, 3).1, campaign.input(i, 3).1);
        }
        assert_ne!(campaign.input(5, 3).1, xml);
        assert_eq!(allocation_limit(1), 64 + (64 << 20));
    }
}
