//! Built-in study data benchmark: the archive's SHA-256, zstd decoding
//! alone, the first unpacking into an empty cache (check, decode, write,
//! hash, manifest) and a later run's check of the cached copy. Prints
//! seconds and MB/s of uncompressed data.
//!
//! Run with `cargo bench -p realitygap-data --bench unpack` (or, in the
//! test profile, `cargo test -p realitygap-data --bench unpack`).

use realitygap_data::builtin::{open_or_unpack, CacheAction, StudyArchive};
use sha2::{Digest, Sha256};
use std::io::Read;
use std::path::PathBuf;
use std::time::Instant;

fn main() {
    let assets = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../assets");
    let archive = StudyArchive::in_assets(&assets).unwrap_or_else(|e| panic!("{e}"));
    let bytes = std::fs::read(&archive.path).unwrap();
    let compressed_mb = bytes.len() as f64 / 1e6;

    let t = Instant::now();
    let digest = Sha256::digest(&bytes);
    let sha_s = t.elapsed().as_secs_f64();
    assert_eq!(
        digest
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect::<String>(),
        archive.sha256
    );
    println!("archive: {compressed_mb:.1} MB; SHA-256 in {sha_s:.3} s");

    let t = Instant::now();
    let mut decoder = ruzstd::decoding::StreamingDecoder::new(&bytes[..]).unwrap();
    let mut buf = vec![0u8; 1 << 20];
    let mut total = 0usize;
    loop {
        let n = decoder.read(&mut buf).unwrap();
        if n == 0 {
            break;
        }
        total += n;
    }
    let decode_s = t.elapsed().as_secs_f64();
    let mb = total as f64 / 1e6;
    println!(
        "decode only: {mb:.1} MB of tar in {decode_s:.3} s ({:.0} MB/s)",
        mb / decode_s
    );

    let cache = tempfile::tempdir().unwrap();
    let first = open_or_unpack(&archive, cache.path()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(first.action, CacheAction::Unpacked);
    println!(
        "first unpacking: {} files, {:.1} MB in {:.3} s ({:.0} MB/s)",
        first.files,
        first.bytes as f64 / 1e6,
        first.elapsed_s,
        first.bytes as f64 / 1e6 / first.elapsed_s
    );
    let mut later = Vec::new();
    for _ in 0..5 {
        let again = open_or_unpack(&archive, cache.path()).unwrap();
        assert_eq!(again.action, CacheAction::Reused);
        later.push(again.elapsed_s);
    }
    later.sort_by(f64::total_cmp);
    println!(
        "later runs (check of the cached copy): median {:.4} s of 5",
        later[2]
    );
}
