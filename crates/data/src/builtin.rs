//! The study's recordings built in: one compressed, checksummed archive in
//! the project's assets, unpacked once into a cache folder and reused.
//!
//! The archive (`assets/study-data/paper-data.tar.zst`, built by
//! `scripts/pack-study-data`) holds the reference study's published
//! recordings (motion capture and simulator runs) and the `kinova_description`
//! robot package. Its SHA-256 is recorded beside it
//! (`paper-data.tar.zst.sha256`) and names the cache folder:
//! `<cache root>/study-data/<first 16 hex digits>/`.
//!
//! - **Unpacking** checks the archive against the recorded SHA-256, unpacks
//!   into a temporary folder beside the final one, writes a manifest (every
//!   file's size, SHA-256 and modification time) last, and renames the folder
//!   into place. A half-unpacked folder is therefore never taken for a
//!   finished one, and two processes unpacking at once (they also take a
//!   lock) cannot corrupt each other's copy.
//! - **Reuse** checks the manifest against the files: every file must exist
//!   with its size; a file whose modification time changed is hashed again.
//!   A damaged cache (a file truncated, edited or removed) is unpacked anew.
//!
//! The cache root is `REALITYGAP_CACHE_DIR` when set, else
//! `$XDG_CACHE_HOME/realitygap`, else `$HOME/.cache/realitygap`.

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::fmt;
use std::fs;
use std::io::{self, Read, Write};
use std::path::{Component, Path, PathBuf};
use std::time::{Instant, UNIX_EPOCH};

/// The archive's path inside the assets folder.
pub const ARCHIVE_IN_ASSETS: &str = "study-data/paper-data.tar.zst";
/// The checksum file's path inside the assets folder (`sha256sum` format).
pub const CHECKSUM_IN_ASSETS: &str = "study-data/paper-data.tar.zst.sha256";
/// Environment variable that overrides the cache root.
pub const CACHE_ENV: &str = "REALITYGAP_CACHE_DIR";
/// The manifest inside an unpacked folder, written last.
pub const MANIFEST_NAME: &str = ".realitygap-unpacked.json";
/// Version of the manifest's layout; another version means unpack again.
const MANIFEST_FORMAT: u32 = 1;
/// Hex digits of the archive's SHA-256 used in the cache folder's name.
const KEY_DIGITS: usize = 16;
/// Makes the names of temporary folders unique within a process.
static UNIQUE: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Something that stops the built-in data from being used. Displayed as
/// `path: what went wrong; what to do`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BuiltinError {
    /// The file or folder concerned.
    pub path: PathBuf,
    /// What went wrong and what to do, phrased for a person.
    pub message: String,
}

impl BuiltinError {
    fn new(path: &Path, message: impl Into<String>) -> Self {
        BuiltinError {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }

    fn io(path: &Path, doing: &str, e: &io::Error) -> Self {
        BuiltinError::new(path, format!("cannot {doing}: {e}"))
    }
}

impl fmt::Display for BuiltinError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.message)
    }
}

impl std::error::Error for BuiltinError {}

/// The study archive and its recorded checksum.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StudyArchive {
    /// The compressed archive (`.tar.zst`).
    pub path: PathBuf,
    /// The checksum file it was checked against.
    pub checksum_file: PathBuf,
    /// Its recorded SHA-256, 64 lower-case hex digits.
    pub sha256: String,
    /// The folders the archive must hold (the study's recordings'
    /// `MotionCapture/`, `Simulation/` and `kinova_description/` unless
    /// [`StudyArchive::requiring`] says otherwise).
    pub required: Vec<String>,
}

impl StudyArchive {
    /// The archive in a project's assets folder (`assets/`): reads the
    /// recorded checksum and checks that the archive is there. The archive's
    /// bytes are only read (and checked) when they are unpacked.
    pub fn in_assets(assets: &Path) -> Result<StudyArchive, BuiltinError> {
        StudyArchive::at(
            &assets.join(ARCHIVE_IN_ASSETS),
            &assets.join(CHECKSUM_IN_ASSETS),
        )
    }

    /// An archive and its checksum file (`sha256sum` format: the hex digest
    /// first on the line).
    pub fn at(archive: &Path, checksum_file: &Path) -> Result<StudyArchive, BuiltinError> {
        let text = fs::read_to_string(checksum_file).map_err(|e| {
            BuiltinError::new(
                checksum_file,
                format!("cannot read the built-in study data's checksum ({e}); restore it from the repository (git checkout -- assets/study-data) or pass --data DIR with your own copy"),
            )
        })?;
        let sha256 = text
            .split_whitespace()
            .next()
            .unwrap_or_default()
            .to_ascii_lowercase();
        if sha256.len() != 64 || !sha256.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(BuiltinError::new(
                checksum_file,
                "expected a SHA-256 (64 hex digits) at the start of the file; restore it from the repository (git checkout -- assets/study-data)",
            ));
        }
        if !archive.is_file() {
            return Err(BuiltinError::new(
                archive,
                "the built-in study data is missing; restore it from the repository (git checkout -- assets/study-data), rebuild it with scripts/pack-study-data, or pass --data DIR with your own copy",
            ));
        }
        Ok(StudyArchive {
            path: archive.to_path_buf(),
            checksum_file: checksum_file.to_path_buf(),
            sha256,
            required: ["MotionCapture", "Simulation", "kinova_description"]
                .map(String::from)
                .to_vec(),
        })
    }

    /// The same archive, required to hold the folders `folders` instead.
    pub fn requiring(mut self, folders: &[&str]) -> StudyArchive {
        self.required = folders.iter().map(|f| f.to_string()).collect();
        self
    }

    /// Name of this archive's folder in the cache: the first 16 hex digits
    /// of its SHA-256.
    pub fn cache_name(&self) -> &str {
        &self.sha256[..KEY_DIGITS]
    }
}

/// The cache root: `REALITYGAP_CACHE_DIR`, else `$XDG_CACHE_HOME/realitygap`,
/// else `$HOME/.cache/realitygap`. Empty variables count as unset.
pub fn default_cache_root() -> Result<PathBuf, BuiltinError> {
    cache_root_from(|name| std::env::var_os(name))
}

/// [`default_cache_root`] with the environment given as a function.
fn cache_root_from(
    var: impl Fn(&str) -> Option<std::ffi::OsString>,
) -> Result<PathBuf, BuiltinError> {
    let var = |name: &str| var(name).filter(|v| !v.is_empty());
    if let Some(dir) = var(CACHE_ENV) {
        return Ok(PathBuf::from(dir));
    }
    if let Some(dir) = var("XDG_CACHE_HOME") {
        return Ok(PathBuf::from(dir).join("realitygap"));
    }
    if let Some(home) = var("HOME") {
        return Ok(PathBuf::from(home).join(".cache/realitygap"));
    }
    Err(BuiltinError::new(
        Path::new("$HOME"),
        format!("no cache folder for the built-in study data: set {CACHE_ENV} (or XDG_CACHE_HOME or HOME) to a writable folder"),
    ))
}

/// What [`open_or_unpack`] did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CacheAction {
    /// A verified copy was already in the cache.
    Reused,
    /// Nothing was cached: the archive was unpacked.
    Unpacked,
    /// The cached copy was damaged (the reason) and was unpacked anew.
    Rebuilt(String),
}

/// The unpacked study data.
#[derive(Debug, Clone, PartialEq)]
pub struct Unpacked {
    /// The folder holding `MotionCapture/`, `Simulation/`,
    /// `kinova_description/` and `LICENSE.txt`.
    pub dir: PathBuf,
    /// Whether it was reused, unpacked or rebuilt.
    pub action: CacheAction,
    /// Number of files in it.
    pub files: usize,
    /// Their total size, bytes.
    pub bytes: u64,
    /// Wall time of this call (checking, and unpacking if needed), seconds.
    pub elapsed_s: f64,
}

/// One file in the manifest.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Eq)]
struct FileEntry {
    /// Path relative to the unpacked folder, `/`-separated.
    path: String,
    /// Size, bytes.
    bytes: u64,
    /// SHA-256, lower-case hex.
    sha256: String,
    /// Modification time after unpacking, nanoseconds since 1970.
    mtime_ns: u64,
}

/// The manifest written last into an unpacked folder.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Eq)]
struct Manifest {
    format: u32,
    archive_sha256: String,
    files: Vec<FileEntry>,
}

/// The verified unpacked copy of `archive` under `cache_root`, unpacking it
/// first when the cache has none or a damaged one. Safe to call from
/// several processes at once.
pub fn open_or_unpack(archive: &StudyArchive, cache_root: &Path) -> Result<Unpacked, BuiltinError> {
    let started = Instant::now();
    let parent = cache_root.join("study-data");
    fs::create_dir_all(&parent).map_err(|e| {
        BuiltinError::new(
            &parent,
            format!("cannot create the cache folder for the built-in study data ({e}); set {CACHE_ENV} to a writable folder"),
        )
    })?;
    let dir = parent.join(archive.cache_name());
    let done = |manifest: &Manifest, action| Unpacked {
        dir: dir.clone(),
        action,
        files: manifest.files.len(),
        bytes: manifest.files.iter().map(|f| f.bytes).sum(),
        elapsed_s: started.elapsed().as_secs_f64(),
    };
    // Fast path: a finished copy is only ever renamed into place whole.
    if let Ok(m) = check_unpacked(&dir, &archive.sha256) {
        return Ok(done(&m, CacheAction::Reused));
    }
    let _lock = lock(&parent, archive.cache_name())?;
    // Another process may have finished while this one waited.
    let damage = match check_unpacked(&dir, &archive.sha256) {
        Ok(m) => return Ok(done(&m, CacheAction::Reused)),
        Err(reason) => dir.exists().then_some(reason),
    };
    remove_leftovers(&parent, archive.cache_name());
    if damage.is_some() {
        let trash = scratch(&parent, "trash", archive.cache_name());
        fs::rename(&dir, &trash)
            .map_err(|e| BuiltinError::io(&dir, "move the damaged cached copy aside", &e))?;
        let _ = fs::remove_dir_all(&trash);
    }
    let bytes = read_checked(archive)?;
    let tmp = scratch(&parent, "tmp", archive.cache_name());
    let manifest = match unpack_into(&bytes, archive, &tmp) {
        Ok(m) => m,
        Err(e) => {
            let _ = fs::remove_dir_all(&tmp);
            return Err(e);
        }
    };
    if let Err(e) = fs::rename(&tmp, &dir) {
        let _ = fs::remove_dir_all(&tmp);
        return match check_unpacked(&dir, &archive.sha256) {
            Ok(m) => Ok(done(&m, CacheAction::Reused)),
            Err(_) => Err(BuiltinError::io(
                &dir,
                "move the unpacked copy into place",
                &e,
            )),
        };
    }
    Ok(done(
        &manifest,
        match damage {
            Some(reason) => CacheAction::Rebuilt(reason),
            None => CacheAction::Unpacked,
        },
    ))
}

/// A new folder name `<parent>/.<kind>-<name>-<pid>-<n>`, unique among
/// processes and threads; [`remove_leftovers`] removes those of dead ones.
fn scratch(parent: &Path, kind: &str, name: &str) -> PathBuf {
    let n = UNIQUE.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    parent.join(format!(".{kind}-{name}-{}-{n}", std::process::id()))
}

/// Holds an exclusive lock on `<parent>/<name>.lock` until dropped. A file
/// system without locks is not an error: the temporary folder and the
/// rename keep the copy whole, the lock only saves duplicate work.
fn lock(parent: &Path, name: &str) -> Result<fs::File, BuiltinError> {
    let path = parent.join(format!("{name}.lock"));
    let file = fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .map_err(|e| {
            BuiltinError::new(
                &path,
                format!("cannot write in the cache folder for the built-in study data ({e}); set {CACHE_ENV} to a writable folder"),
            )
        })?;
    let _ = file.lock();
    Ok(file)
}

/// Removes temporary and trash folders of `name` left by processes that
/// were killed while unpacking (called with the lock held).
fn remove_leftovers(parent: &Path, name: &str) {
    let Ok(entries) = fs::read_dir(parent) else {
        return;
    };
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        let file_name = file_name.to_string_lossy();
        if file_name.starts_with(&format!(".tmp-{name}-"))
            || file_name.starts_with(&format!(".trash-{name}-"))
        {
            let _ = fs::remove_dir_all(entry.path());
        }
    }
}

/// The archive's bytes, checked against the recorded SHA-256.
fn read_checked(archive: &StudyArchive) -> Result<Vec<u8>, BuiltinError> {
    let bytes = fs::read(&archive.path)
        .map_err(|e| BuiltinError::io(&archive.path, "read the built-in study data", &e))?;
    let found = hex(&Sha256::digest(&bytes));
    if found != archive.sha256 {
        return Err(BuiltinError::new(
            &archive.path,
            format!(
                "the built-in study data is damaged: its SHA-256 is {found}, {} records {}; restore it from the repository (git checkout -- assets/study-data) or pass --data DIR with your own copy",
                archive.checksum_file.display(),
                archive.sha256
            ),
        ));
    }
    Ok(bytes)
}

/// Checks an unpacked folder against its manifest: the reason it cannot be
/// used, or the manifest.
fn check_unpacked(dir: &Path, archive_sha256: &str) -> Result<Manifest, String> {
    let path = dir.join(MANIFEST_NAME);
    let text = fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let manifest: Manifest =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    if manifest.format != MANIFEST_FORMAT || manifest.archive_sha256 != archive_sha256 {
        return Err(format!("{} is of another archive", path.display()));
    }
    if manifest.files.is_empty() {
        return Err(format!("{} lists no files", path.display()));
    }
    for f in &manifest.files {
        check_file(dir, f)?;
    }
    Ok(manifest)
}

/// Checks one cached file: size always, content when the modification time
/// differs from the one recorded.
fn check_file(dir: &Path, f: &FileEntry) -> Result<(), String> {
    let path = dir.join(&f.path);
    let meta = fs::metadata(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    if !meta.is_file() {
        return Err(format!("{} is not a file", path.display()));
    }
    if meta.len() != f.bytes {
        return Err(format!(
            "{} has {} bytes, expected {}",
            path.display(),
            meta.len(),
            f.bytes
        ));
    }
    if mtime_ns(&meta) == Some(f.mtime_ns) {
        return Ok(());
    }
    let mut hasher = Sha256::new();
    let mut file = fs::File::open(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    io::copy(&mut file, &mut hasher).map_err(|e| format!("{}: {e}", path.display()))?;
    if hex(&hasher.finalize()) != f.sha256 {
        return Err(format!("{} differs from the archive", path.display()));
    }
    Ok(())
}

/// Unpacks the (checked) archive bytes into `tmp` and writes the manifest
/// there last.
fn unpack_into(bytes: &[u8], archive: &StudyArchive, tmp: &Path) -> Result<Manifest, BuiltinError> {
    let bad = |message: String| BuiltinError::new(&archive.path, message);
    fs::create_dir_all(tmp).map_err(|e| {
        BuiltinError::new(
            tmp,
            format!(
                "cannot create a folder in the cache ({e}); set {CACHE_ENV} to a writable folder"
            ),
        )
    })?;
    let decoder = ruzstd::decoding::StreamingDecoder::new(bytes)
        .map_err(|e| bad(format!("not a zstd archive: {e}")))?;
    let mut tar = tar::Archive::new(decoder);
    let entries = tar
        .entries()
        .map_err(|e| bad(format!("cannot read the tar archive: {e}")))?;
    let mut files = Vec::new();
    for entry in entries {
        let mut entry = entry.map_err(|e| bad(format!("cannot read the tar archive: {e}")))?;
        let name = entry
            .path()
            .map_err(|e| bad(format!("an entry has a bad name: {e}")))?
            .into_owned();
        let rel = safe_relative(&name).ok_or_else(|| {
            bad(format!(
                "entry {} is not a plain relative path",
                name.display()
            ))
        })?;
        let target = tmp.join(&rel);
        match entry.header().entry_type() {
            tar::EntryType::Directory => fs::create_dir_all(&target)
                .map_err(|e| BuiltinError::io(&target, "create a folder in the cache", &e))?,
            tar::EntryType::Regular => files.push(write_entry(&mut entry, &rel, &target)?),
            other => {
                return Err(bad(format!(
                    "entry {} is of type {other:?}; only files and folders are expected",
                    name.display()
                )))
            }
        }
    }
    for required in &archive.required {
        if !tmp.join(required).is_dir() {
            return Err(bad(format!("the archive has no {required}/ folder")));
        }
    }
    let manifest = Manifest {
        format: MANIFEST_FORMAT,
        archive_sha256: archive.sha256.clone(),
        files,
    };
    let path = tmp.join(MANIFEST_NAME);
    let text = serde_json::to_string_pretty(&manifest)
        .map_err(|e| BuiltinError::new(&path, e.to_string()))?;
    fs::write(&path, text).map_err(|e| BuiltinError::io(&path, "write the manifest", &e))?;
    Ok(manifest)
}

/// Writes one file of the archive, hashing it on the way.
fn write_entry(
    entry: &mut impl Read,
    rel: &Path,
    target: &Path,
) -> Result<FileEntry, BuiltinError> {
    if let Some(parent) = target.parent() {
        fs::create_dir_all(parent)
            .map_err(|e| BuiltinError::io(parent, "create a folder in the cache", &e))?;
    }
    let file = fs::File::create(target)
        .map_err(|e| BuiltinError::io(target, "create a file in the cache", &e))?;
    let mut out = HashingWriter {
        inner: io::BufWriter::new(file),
        hasher: Sha256::new(),
        bytes: 0,
    };
    io::copy(entry, &mut out)
        .and_then(|_| out.flush())
        .map_err(|e| BuiltinError::io(target, "unpack into the cache", &e))?;
    let meta =
        fs::metadata(target).map_err(|e| BuiltinError::io(target, "read back the file", &e))?;
    Ok(FileEntry {
        path: rel
            .components()
            .map(|c| c.as_os_str().to_string_lossy())
            .collect::<Vec<_>>()
            .join("/"),
        bytes: out.bytes,
        sha256: hex(&out.hasher.finalize()),
        mtime_ns: mtime_ns(&meta).unwrap_or(0),
    })
}

/// The path if it is relative and has only normal components (no `..`,
/// no root, no prefix), else `None`.
fn safe_relative(path: &Path) -> Option<PathBuf> {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::Normal(part) => out.push(part),
            Component::CurDir => {}
            _ => return None,
        }
    }
    (!out.as_os_str().is_empty()).then_some(out)
}

fn mtime_ns(meta: &fs::Metadata) -> Option<u64> {
    let t = meta.modified().ok()?;
    let d = t.duration_since(UNIX_EPOCH).ok()?;
    u64::try_from(d.as_nanos()).ok()
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// A writer that counts and hashes what passes through.
struct HashingWriter<W: Write> {
    inner: W,
    hasher: Sha256,
    bytes: u64,
}

impl<W: Write> Write for HashingWriter<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.hasher.update(&buf[..n]);
        self.bytes += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assets() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../assets")
    }

    fn archive() -> StudyArchive {
        StudyArchive::in_assets(&assets()).unwrap()
    }

    fn unpack(cache: &Path) -> Unpacked {
        open_or_unpack(&archive(), cache).unwrap()
    }

    const SAMPLE: &str = "Simulation/Experiment1/Single_Mujoco_0.csv";

    #[test]
    fn unpacks_once_then_reuses() {
        let tmp = tempfile::tempdir().unwrap();
        let first = unpack(tmp.path());
        assert_eq!(first.action, CacheAction::Unpacked);
        assert_eq!(
            first.dir,
            tmp.path().join("study-data").join(archive().cache_name())
        );
        // LICENSE.txt, 2 format references, 60 real runs, 420 simulator
        // runs, URDF, MJCF and 10 meshes.
        assert_eq!(first.files, 1 + 2 + 60 + 420 + 12);
        assert!(first.bytes > 70_000_000, "{} bytes", first.bytes);
        for part in ["MotionCapture/Experiment3/CubeExp0020_6D.tsv", SAMPLE] {
            assert!(first.dir.join(part).is_file(), "{part}");
        }
        assert!(first
            .dir
            .join("kinova_description/urdf/m1n6s300.urdf")
            .is_file());
        let second = unpack(tmp.path());
        assert_eq!(second.action, CacheAction::Reused);
        assert_eq!((second.files, second.bytes), (first.files, first.bytes));
    }

    #[test]
    fn damaged_caches_are_detected_and_rebuilt() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = unpack(tmp.path()).dir;
        let sample = dir.join(SAMPLE);
        let original = fs::read(&sample).unwrap();

        // Truncated.
        fs::OpenOptions::new()
            .write(true)
            .open(&sample)
            .unwrap()
            .set_len(10)
            .unwrap();
        let again = unpack(tmp.path());
        match &again.action {
            CacheAction::Rebuilt(reason) => {
                assert!(reason.contains("Single_Mujoco_0.csv"), "{reason}")
            }
            other => panic!("truncation not detected: {other:?}"),
        }
        assert_eq!(fs::read(&sample).unwrap(), original);

        // Edited in place, same size.
        let mut edited = original.clone();
        edited[0] = if edited[0] == b'9' { b'8' } else { b'9' };
        fs::write(&sample, &edited).unwrap();
        assert!(matches!(unpack(tmp.path()).action, CacheAction::Rebuilt(_)));
        assert_eq!(fs::read(&sample).unwrap(), original);

        // Removed file; then a half-unpacked copy (no manifest).
        fs::remove_file(&sample).unwrap();
        assert!(matches!(unpack(tmp.path()).action, CacheAction::Rebuilt(_)));
        fs::remove_file(dir.join(MANIFEST_NAME)).unwrap();
        assert!(matches!(unpack(tmp.path()).action, CacheAction::Rebuilt(_)));
        assert_eq!(unpack(tmp.path()).action, CacheAction::Reused);
    }

    #[test]
    fn a_copied_cache_with_new_times_is_hashed_not_rebuilt() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = unpack(tmp.path()).dir;
        let sample = dir.join(SAMPLE);
        let text = fs::read(&sample).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(20));
        fs::write(&sample, &text).unwrap();
        assert_eq!(unpack(tmp.path()).action, CacheAction::Reused);
    }

    #[test]
    fn an_unwritable_cache_folder_is_a_clear_error() {
        let tmp = tempfile::tempdir().unwrap();
        let file = tmp.path().join("a-file");
        fs::write(&file, "not a folder").unwrap();
        let root = file.join("cache");
        let e = open_or_unpack(&archive(), &root).unwrap_err();
        let text = e.to_string();
        assert!(text.contains(&root.display().to_string()), "{text}");
        assert!(text.contains(CACHE_ENV), "{text}");
    }

    #[test]
    fn a_damaged_or_missing_archive_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let mut bytes = fs::read(assets().join(ARCHIVE_IN_ASSETS)).unwrap();
        let middle = bytes.len() / 2;
        bytes[middle] ^= 0x55;
        let copy = tmp.path().join("copy.tar.zst");
        fs::write(&copy, &bytes).unwrap();
        let a = StudyArchive::at(&copy, &assets().join(CHECKSUM_IN_ASSETS)).unwrap();
        let e = open_or_unpack(&a, &tmp.path().join("cache")).unwrap_err();
        assert_eq!(e.path, copy);
        assert!(e.message.contains("damaged"), "{e}");
        assert!(!tmp
            .path()
            .join("cache/study-data")
            .join(a.cache_name())
            .exists());

        let e = StudyArchive::at(
            &tmp.path().join("none.tar.zst"),
            &assets().join(CHECKSUM_IN_ASSETS),
        )
        .unwrap_err();
        assert!(e.to_string().contains("none.tar.zst"), "{e}");
        let bad_sum = tmp.path().join("bad.sha256");
        fs::write(&bad_sum, "xyz  copy.tar.zst\n").unwrap();
        let e = StudyArchive::at(&copy, &bad_sum).unwrap_err();
        assert!(e.to_string().contains("bad.sha256"), "{e}");
        let e = StudyArchive::at(&copy, &tmp.path().join("no.sha256")).unwrap_err();
        assert!(e.to_string().contains("no.sha256"), "{e}");
    }

    #[test]
    fn concurrent_unpacks_agree_and_leftovers_go() {
        let tmp = tempfile::tempdir().unwrap();
        let parent = tmp.path().join("study-data");
        let stale = parent.join(format!(".tmp-{}-999999", archive().cache_name()));
        fs::create_dir_all(stale.join("MotionCapture")).unwrap();
        let results: Vec<Unpacked> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..3).map(|_| s.spawn(|| unpack(tmp.path()))).collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        let unpacked = results
            .iter()
            .filter(|u| u.action == CacheAction::Unpacked)
            .count();
        assert_eq!(unpacked, 1, "{results:?}");
        assert!(results.iter().all(|u| u.dir == results[0].dir));
        assert!(!stale.exists());
        assert_eq!(unpack(tmp.path()).action, CacheAction::Reused);
    }

    /// The archive holds the study's recordings exactly as published. Always:
    /// the archive matches its recorded SHA-256 (checked while unpacking),
    /// and the unpacked files, and the unpack's own manifest, are exactly the
    /// committed list of the published files with their SHA-256
    /// (`paper-data.files.sha256`, `sha256sum` format, written by
    /// `scripts/pack-study-data`). When the published folder is beside the
    /// project (`../shared/paper-data`), also the full comparison: the same
    /// files, byte for byte, less the folder's README, and the folder matches
    /// the committed list.
    #[test]
    fn the_archive_holds_paper_data_byte_for_byte() {
        let tmp = tempfile::tempdir().unwrap();
        let unpacked = unpack(tmp.path());
        let dir = unpacked.dir;
        assert_eq!(
            archive().sha256,
            hex(&Sha256::digest(fs::read(archive().path).unwrap()))
        );
        let list_path = assets().join("study-data/paper-data.files.sha256");
        let listed: Vec<(String, String)> = fs::read_to_string(&list_path)
            .unwrap()
            .lines()
            .map(|line| {
                let (hash, path) = line.split_once("  ").unwrap_or_else(|| {
                    panic!("{}: not a sha256sum line: {line}", list_path.display())
                });
                (path.to_string(), hash.to_string())
            })
            .collect();
        assert_eq!(listed.len(), 495, "{}", list_path.display());
        let list = |root: &Path| {
            let mut out = Vec::new();
            let mut stack = vec![root.to_path_buf()];
            while let Some(d) = stack.pop() {
                for e in fs::read_dir(&d).unwrap().flatten() {
                    let p = e.path();
                    if p.is_dir() {
                        stack.push(p);
                    } else {
                        out.push(p.strip_prefix(root).unwrap().to_path_buf());
                    }
                }
            }
            out.sort();
            out
        };
        let sha = |p: &Path| hex(&Sha256::digest(fs::read(p).unwrap()));
        let mut found = list(&dir);
        found.retain(|p| p != Path::new(MANIFEST_NAME));
        let mut expected: Vec<PathBuf> = listed.iter().map(|(p, _)| PathBuf::from(p)).collect();
        expected.sort();
        assert_eq!(found, expected, "the unpacked files against the list");
        for (rel, hash) in &listed {
            assert_eq!(&sha(&dir.join(rel)), hash, "{rel} differs from the list");
        }
        let manifest = check_unpacked(&dir, &archive().sha256).unwrap();
        let mut in_manifest: Vec<(String, String)> = manifest
            .files
            .iter()
            .map(|f| (f.path.clone(), f.sha256.clone()))
            .collect();
        in_manifest.sort();
        let mut sorted_list = listed.clone();
        sorted_list.sort();
        assert_eq!(
            in_manifest, sorted_list,
            "the unpack's manifest against the list"
        );

        let Some(paper) = crate::published_paper_data() else {
            eprintln!(
                "../shared/paper-data is not beside the project: checked the archive against its checksum and the committed file list only"
            );
            return;
        };
        let mut published = list(&paper);
        published.retain(|p| p != Path::new("README.md"));
        assert_eq!(
            found, published,
            "the unpacked files against the published folder"
        );
        for rel in &found {
            assert!(
                fs::read(dir.join(rel)).unwrap() == fs::read(paper.join(rel)).unwrap(),
                "{} differs",
                rel.display()
            );
        }
        for (rel, hash) in &listed {
            assert_eq!(
                &sha(&paper.join(rel)),
                hash,
                "published {rel} differs from the list"
            );
        }
    }

    #[test]
    fn only_plain_relative_paths_are_unpacked() {
        assert_eq!(
            safe_relative(Path::new("./a/b.csv")),
            Some(PathBuf::from("a/b.csv"))
        );
        for bad in ["../x", "/etc/passwd", "a/../../x", "", "."] {
            assert_eq!(safe_relative(Path::new(bad)), None, "{bad}");
        }
    }

    #[test]
    fn the_cache_root_follows_the_environment() {
        let env = |pairs: &'static [(&'static str, &'static str)]| {
            move |name: &str| {
                pairs
                    .iter()
                    .find(|(k, _)| *k == name)
                    .map(|(_, v)| std::ffi::OsString::from(v))
            }
        };
        let all = env(&[(CACHE_ENV, "/c"), ("XDG_CACHE_HOME", "/x"), ("HOME", "/h")]);
        assert_eq!(cache_root_from(all).unwrap(), PathBuf::from("/c"));
        let xdg = env(&[(CACHE_ENV, ""), ("XDG_CACHE_HOME", "/x"), ("HOME", "/h")]);
        assert_eq!(
            cache_root_from(xdg).unwrap(),
            PathBuf::from("/x/realitygap")
        );
        let home = env(&[("HOME", "/h")]);
        assert_eq!(
            cache_root_from(home).unwrap(),
            PathBuf::from("/h/.cache/realitygap")
        );
        let e = cache_root_from(env(&[])).unwrap_err();
        assert!(e.message.contains(CACHE_ENV), "{e}");
    }
}
