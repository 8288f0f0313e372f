//! A parquet file's stated sizes, checked before the `parquet` crate reads
//! it: the crate allocates a page's compressed and uncompressed sizes as its
//! header states them (up to 2 GiB each), so a damaged header would ask for
//! far more memory than the file could ever decode to. Here every column
//! chunk is checked to lie inside the file, and every page header inside it
//! is walked (Thrift compact protocol, read by hand: only the two sizes are
//! kept) and its sizes checked against the chunk and a limit from the
//! file's size. The file is then read from memory, so no read is larger
//! than the file.

use bytes::Bytes;
use parquet::file::reader::{FileReader, SerializedFileReader};
use realitygap_data::ImportError;
use std::cell::Cell;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::sync::Once;

/// The largest decompressed column chunk a parquet file of `file_len`
/// bytes is allowed to state: 16 times the file and 16 MiB more.
pub fn parquet_limit(file_len: usize) -> u64 {
    (file_len as u64)
        .saturating_mul(16)
        .saturating_add(16 << 20)
}

thread_local! {
    /// Whether a panic on this thread is one [`guarded`] turns into an
    /// error (the panic hook then prints nothing).
    static QUIET: Cell<bool> = const { Cell::new(false) };
}

/// Installs, once, a panic hook that stays silent for [`guarded`] code and
/// hands every other panic to the hook that was there before.
static QUIET_HOOK: Once = Once::new();

/// Runs `read` (the `parquet` crate reading `file`) and turns a panic into
/// an error naming the file: the crate panics on some damaged files where
/// it should return an error (an out-of-bounds index in its
/// BYTE_STREAM_SPLIT decoder when a page holds fewer bytes than its values
/// need, found by the fuzz campaign).
pub fn guarded<T>(
    file: &Path,
    read: impl FnOnce() -> Result<T, ImportError>,
) -> Result<T, ImportError> {
    QUIET_HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.with(Cell::get) {
                previous(info);
            }
        }));
    });
    let was = QUIET.with(|q| q.replace(true));
    let outcome = catch_unwind(AssertUnwindSafe(read));
    QUIET.with(|q| q.set(was));
    outcome.unwrap_or_else(|payload| {
        let message = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        Err(ImportError::new(
            file,
            format!("the parquet file is damaged: its reader failed ({message})"),
        ))
    })
}

/// Reads a parquet file into memory and opens it, once its column chunks
/// and page headers are checked.
pub fn open(file: &Path) -> Result<SerializedFileReader<Bytes>, ImportError> {
    let bytes =
        std::fs::read(file).map_err(|e| ImportError::new(file, format!("cannot read: {e}")))?;
    open_bytes(file, Bytes::from(bytes))
}

/// [`open`] on bytes already read; `file` names them in messages.
pub fn open_bytes(file: &Path, bytes: Bytes) -> Result<SerializedFileReader<Bytes>, ImportError> {
    let err = |e: parquet::errors::ParquetError| {
        ImportError::new(file, format!("cannot read the parquet file: {e}"))
    };
    let reader = SerializedFileReader::new(bytes.clone()).map_err(err)?;
    check_pages(file, &bytes, &reader)?;
    Ok(reader)
}

/// Checks every column chunk's place and every page header's sizes.
fn check_pages(
    file: &Path,
    bytes: &[u8],
    reader: &SerializedFileReader<Bytes>,
) -> Result<(), ImportError> {
    let limit = parquet_limit(bytes.len());
    let meta = reader.metadata();
    for g in 0..meta.num_row_groups() {
        for chunk in meta.row_group(g).columns() {
            let place = || format!("row group {g}, column {}", chunk.column_path());
            let damaged = |what: String| {
                ImportError::new(file, format!("{what}: the file is damaged")).with_field(place())
            };
            let start = chunk
                .dictionary_page_offset()
                .filter(|&d| d > 0)
                .unwrap_or_else(|| chunk.data_page_offset());
            let len = chunk.compressed_size();
            let end = u64::try_from(start)
                .ok()
                .zip(u64::try_from(len).ok())
                .and_then(|(s, l)| s.checked_add(l).map(|e| (s, e)));
            let Some((start, end)) = end.filter(|&(_, e)| e <= bytes.len() as u64) else {
                return Err(damaged(format!(
                    "the column chunk claims bytes {start} to {start}+{len}, beyond the file's {} bytes",
                    bytes.len()
                )));
            };
            let total = chunk.uncompressed_size();
            if u64::try_from(total).map_or(true, |t| t > limit) {
                return Err(damaged(format!(
                    "the column chunk claims {total} bytes once decompressed, more than this {}-byte file can hold (at most {limit})",
                    bytes.len()
                )));
            }
            let total = total as u64;
            let mut pos = start as usize;
            let end = end as usize;
            let mut page = 0usize;
            while pos < end {
                let (header_len, uncompressed, compressed) = page_sizes(&bytes[pos..end])
                    .map_err(|m| damaged(format!("page {page} at byte {pos}: {m}")))?;
                pos += header_len;
                let left = end - pos;
                if compressed < 0 || compressed as u64 > left as u64 {
                    return Err(damaged(format!(
                        "page {page} at byte {pos} claims {compressed} bytes, {left} are left in its column chunk"
                    )));
                }
                if uncompressed < 0 || uncompressed as u64 > total {
                    return Err(damaged(format!(
                        "page {page} at byte {pos} claims {uncompressed} bytes once decompressed, more than its whole column chunk ({total})"
                    )));
                }
                pos += compressed as usize;
                page += 1;
            }
        }
    }
    Ok(())
}

/// What reads or skips a struct field's value: called with the cursor, the
/// field's id, its type and the nesting depth.
type FieldReader<'f, T> = dyn FnMut(&mut T, i16, u8, u32) -> Result<(), String> + 'f;

/// A cursor over Thrift compact protocol bytes.
struct Thrift<'a> {
    buf: &'a [u8],
    pos: usize,
}

/// Nesting deeper than this is damage (a page header nests 3 levels).
const MAX_DEPTH: u32 = 32;

impl Thrift<'_> {
    fn byte(&mut self) -> Result<u8, String> {
        let b = *self
            .buf
            .get(self.pos)
            .ok_or("the page header runs past its column chunk")?;
        self.pos += 1;
        Ok(b)
    }

    fn varint(&mut self) -> Result<u64, String> {
        let mut value = 0u64;
        for shift in (0..70).step_by(7) {
            let b = self.byte()?;
            value |= u64::from(b & 0x7f).checked_shl(shift).unwrap_or(0);
            if b & 0x80 == 0 {
                return Ok(value);
            }
        }
        Err("a varint longer than 10 bytes".into())
    }

    fn zigzag(&mut self) -> Result<i64, String> {
        let v = self.varint()?;
        Ok((v >> 1) as i64 ^ -((v & 1) as i64))
    }

    fn skip_bytes(&mut self, n: u64) -> Result<(), String> {
        let left = (self.buf.len() - self.pos) as u64;
        if n > left {
            return Err(format!("a field of {n} bytes, {left} are left"));
        }
        self.pos += n as usize;
        Ok(())
    }

    /// Skips a value of compact type `ty`; `in_list` for list elements,
    /// whose booleans take a byte (a field's boolean is in its type).
    fn skip(&mut self, ty: u8, in_list: bool, depth: u32) -> Result<(), String> {
        if depth > MAX_DEPTH {
            return Err("structures nested too deep".into());
        }
        match ty {
            1 | 2 if !in_list => Ok(()),
            1..=3 => self.skip_bytes(1),
            4..=6 => self.varint().map(|_| ()),
            7 => self.skip_bytes(8),
            8 => {
                let n = self.varint()?;
                self.skip_bytes(n)
            }
            9 | 10 => {
                let head = self.byte()?;
                let size = match head >> 4 {
                    15 => self.varint()?,
                    n => u64::from(n),
                };
                // Every element takes at least a byte.
                if size > (self.buf.len() - self.pos) as u64 {
                    return Err(format!("a list of {size} elements in fewer bytes"));
                }
                for _ in 0..size {
                    self.skip(head & 0x0f, true, depth + 1)?;
                }
                Ok(())
            }
            11 => {
                let size = self.varint()?;
                if size == 0 {
                    return Ok(());
                }
                if size > (self.buf.len() - self.pos) as u64 {
                    return Err(format!("a map of {size} entries in fewer bytes"));
                }
                let types = self.byte()?;
                for _ in 0..size {
                    self.skip(types >> 4, true, depth + 1)?;
                    self.skip(types & 0x0f, true, depth + 1)?;
                }
                Ok(())
            }
            12 => self.fields(depth + 1, &mut |t: &mut Self, _, ty, depth| {
                t.skip(ty, false, depth)
            }),
            other => Err(format!("unknown Thrift type {other}")),
        }
    }

    /// Reads a struct's fields to its stop byte, calling `field` with each
    /// field's id and type to read or skip its value.
    fn fields(&mut self, depth: u32, field: &mut FieldReader<'_, Self>) -> Result<(), String> {
        let mut last: i16 = 0;
        loop {
            let b = self.byte()?;
            if b == 0 {
                return Ok(());
            }
            let ty = b & 0x0f;
            let id = match b >> 4 {
                0 => i16::try_from(self.zigzag()?).map_err(|_| "a field id beyond i16")?,
                delta => last
                    .checked_add(i16::from(delta))
                    .ok_or("a field id beyond i16")?,
            };
            last = id;
            field(self, id, ty, depth)?;
        }
    }
}

/// The length of the page header at the start of `buf`, and its
/// uncompressed and compressed page sizes.
fn page_sizes(buf: &[u8]) -> Result<(usize, i64, i64), String> {
    let mut t = Thrift { buf, pos: 0 };
    let (mut uncompressed, mut compressed) = (None, None);
    t.fields(0, &mut |t: &mut Thrift, id, ty, depth| match (id, ty) {
        (2, 5) => {
            uncompressed = Some(t.zigzag()?);
            Ok(())
        }
        (3, 5) => {
            compressed = Some(t.zigzag()?);
            Ok(())
        }
        _ => t.skip(ty, false, depth),
    })?;
    match (uncompressed, compressed) {
        (Some(u), Some(c)) => Ok((t.pos, u, c)),
        _ => Err("the page header has no page sizes".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A page header written by hand in the compact protocol.
    fn header(uncompressed: i32, compressed: i32) -> Vec<u8> {
        let zigzag = |v: i64| ((v << 1) ^ (v >> 63)) as u64;
        let varint = |mut v: u64, out: &mut Vec<u8>| loop {
            if v < 0x80 {
                out.push(v as u8);
                break;
            }
            out.push((v as u8 & 0x7f) | 0x80);
            v >>= 7;
        };
        let mut b = Vec::new();
        b.push(0x15); // field 1, i32: type
        varint(zigzag(0), &mut b);
        b.push(0x15); // field 2, i32: uncompressed size
        varint(zigzag(i64::from(uncompressed)), &mut b);
        b.push(0x15); // field 3, i32: compressed size
        varint(zigzag(i64::from(compressed)), &mut b);
        b.push(0x2c); // field 5, struct: data page header
        b.push(0x15); // num_values
        varint(zigzag(10), &mut b);
        b.push(0x11); // a bool field, true
        b.push(0x19); // a list of 2 binaries
        b.push(0x28);
        b.extend([2, b'a', b'b', 1, b'c']);
        b.push(0); // end of the data page header
        b.push(0); // end of the page header
        b
    }

    #[test]
    fn reads_the_sizes_and_the_header_length() {
        let h = header(1000, 300);
        let mut buf = h.clone();
        buf.extend([9; 5]);
        assert_eq!(page_sizes(&buf), Ok((h.len(), 1000, 300)));
    }

    #[test]
    fn damaged_headers_are_errors() {
        let h = header(1000, 300);
        for cut in 0..h.len() {
            assert!(page_sizes(&h[..cut]).is_err(), "cut at {cut}");
        }
        let mut list = h.clone();
        let at = list.iter().position(|&b| b == 0x28).unwrap();
        list[at] = 0xf8; // a list whose size follows as a varint
        list.insert(at + 1, 0xff);
        list.insert(at + 2, 0x7f);
        assert!(page_sizes(&list).unwrap_err().contains("a list of"));
    }
}
