//! The one guard for every file a command writes.
//!
//! A utility's database and its survey files are worth more than any output pipewave makes
//! from them, so an output path is checked before anything is written to it and the write never
//! touches the file it replaces until the new contents are complete:
//!
//! - **Refused:** a directory; the database the command uses (and its `-wal`, `-shm` and
//!   `-journal` files); any other SQLite database (pipewave's or another program's), except a
//!   GeoPackage where a GeoPackage is being written; the command's own input files; a read-only
//!   file. Symlinks and hard links are followed: a link to a protected file is that file.
//! - **Written** through a temporary file `.NAME.tmp-PID` in the same folder, renamed over the
//!   output only when complete (so a reader sees the old file or the new one, never half of
//!   one). The temporary file is removed on every exit path that runs destructors (an error, a
//!   panic); one left by a killed process (kill -9, power loss) is removed by the next write to
//!   the same output, once its process is gone.
//! - A device or FIFO (`/dev/stdout`, `/dev/null`, a named pipe) is written as it is.
//!
//! The command line registers what must not be overwritten ([`protect_database`],
//! [`protect_input`]) as it opens its database and reads its inputs; every [`OutFile`] is checked
//! against that list, so that a file a library module writes deep inside a command (a report
//! inside `diagnose --out DIR`, a network file of `synth`) is guarded as well as the named
//! output. [`check`] runs the same test up front, so a command refuses before it does any work.

use std::fs::File;
use std::io::{self, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Why an output cannot be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The output path is a directory.
    #[error("{} is a directory; give the path of the file to write, such as {}", path.display(), path.join(suggested).display())]
    Directory {
        /// The output path.
        path: PathBuf,
        /// A file name to suggest.
        suggested: String,
    },
    /// The output path is the database the command uses.
    #[error(
        "refusing to write over {}: it is the database this command uses ({}); give another output path",
        path.display(),
        database.display()
    )]
    TheDatabase {
        /// The output path.
        path: PathBuf,
        /// The database it leads to.
        database: PathBuf,
    },
    /// The output path is a SQLite database (pipewave's or another program's).
    #[error("refusing to write over {}: it is {what}; give another output path", path.display())]
    ADatabase {
        /// The output path.
        path: PathBuf,
        /// "a pipewave database" or "a SQLite database".
        what: &'static str,
    },
    /// The output path is one of the command's inputs.
    #[error(
        "refusing to write over {}: it is this command's input {}; give another output path",
        path.display(),
        input.display()
    )]
    AnInput {
        /// The output path.
        path: PathBuf,
        /// The input it leads to.
        input: PathBuf,
    },
    /// The output file exists and is read-only.
    #[error(
        "refusing to replace {}: the file is read-only; make it writable or give another output path",
        path.display()
    )]
    ReadOnly {
        /// The output path.
        path: PathBuf,
    },
    /// Creating, writing or renaming the output failed.
    #[error("cannot write {}", path.display())]
    Write {
        /// The output path.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: io::Error,
    },
}

/// What is written to an output: a GeoPackage may replace or extend a GeoPackage (itself a
/// SQLite database); nothing else may replace a SQLite database.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Contents {
    /// Text or any file that is not a GeoPackage.
    #[default]
    Plain,
    /// A GeoPackage (OGC 12-128r18).
    GeoPackage,
}

/// The role of a protected file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Database,
    Input,
}

/// The files this process must not overwrite, registered by the command line.
static PROTECTED: Mutex<Vec<(PathBuf, Role)>> = Mutex::new(Vec::new());

fn protect(path: &Path, role: Role) {
    let mut list = PROTECTED.lock().unwrap_or_else(|p| p.into_inner());
    if !list.iter().any(|(p, _)| p == path) {
        list.push((path.to_path_buf(), role));
    }
}

/// Register the database a command uses: no output may be it or its `-wal`, `-shm` or
/// `-journal` file.
pub fn protect_database(path: &Path) {
    protect(path, Role::Database);
    for suffix in ["-wal", "-shm", "-journal"] {
        let mut p = path.as_os_str().to_owned();
        p.push(suffix);
        protect(Path::new(&p), Role::Database);
    }
}

/// Register an input file of the command: no output may be it.
pub fn protect_input(path: &Path) {
    protect(path, Role::Input);
}

/// The SQLite file header (https://www.sqlite.org/fileformat.html, section 1.3).
const SQLITE_MAGIC: &[u8; 16] = b"SQLite format 3\0";
/// The GeoPackage's `application_id`, "GPKG" (OGC 12-128r18, requirement 2), at offset 68 of the
/// SQLite header, big-endian.
const GPKG_APPLICATION_ID: u32 = 0x4750_4B47;

/// Whether two paths name the same existing file (after following links).
pub fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (std::fs::metadata(a), std::fs::metadata(b)) {
            (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        match (a.canonicalize(), b.canonicalize()) {
            (Ok(x), Ok(y)) => x == y,
            _ => false,
        }
    }
}

/// What kind of SQLite file `path` is, from its 100-byte header: `None` for anything else.
fn sqlite_kind(path: &Path) -> Option<SqliteKind> {
    // Only a regular file can be a database; opening a FIFO to look would wait for a writer.
    if !std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
        return None;
    }
    let mut header = [0u8; 100];
    let mut f = File::open(path).ok()?;
    let n = read_up_to(&mut f, &mut header);
    if n < 16 || &header[..16] != SQLITE_MAGIC {
        return None;
    }
    if n >= 72
        && u32::from_be_bytes([header[68], header[69], header[70], header[71]])
            == GPKG_APPLICATION_ID
    {
        return Some(SqliteKind::GeoPackage);
    }
    Some(if has_pipewave_tables(path) {
        SqliteKind::Pipewave
    } else {
        SqliteKind::Other
    })
}

fn read_up_to(f: &mut File, buf: &mut [u8]) -> usize {
    let mut n = 0;
    while n < buf.len() {
        match f.read(&mut buf[n..]) {
            Ok(0) | Err(_) => break,
            Ok(k) => n += k,
        }
    }
    n
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SqliteKind {
    GeoPackage,
    Pipewave,
    Other,
}

/// True when the SQLite file has pipewave's `segments` and `fits` tables (read-only look).
fn has_pipewave_tables(path: &Path) -> bool {
    let flags =
        rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY | rusqlite::OpenFlags::SQLITE_OPEN_NO_MUTEX;
    let Ok(conn) = rusqlite::Connection::open_with_flags(path, flags) else {
        return false;
    };
    conn.query_row(
        "SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name IN ('segments', 'fits')",
        [],
        |r| r.get::<_, i64>(0),
    )
    .map(|n| n == 2)
    .unwrap_or(false)
}

/// Check that `out` may be written with `contents`: refuse a directory, a protected file, a
/// SQLite database and a read-only file (module doc). A path that does not exist yet passes.
/// `suggested` is the file name offered when `out` is a directory.
pub fn check(out: &Path, contents: Contents, suggested: &str) -> Result<(), OutputError> {
    if out.is_dir() {
        return Err(OutputError::Directory {
            path: out.to_path_buf(),
            suggested: suggested.to_string(),
        });
    }
    let protected = PROTECTED.lock().unwrap_or_else(|p| p.into_inner()).clone();
    for (p, role) in &protected {
        if same_file(out, p) {
            return Err(match role {
                Role::Database => OutputError::TheDatabase {
                    path: out.to_path_buf(),
                    database: p.clone(),
                },
                Role::Input => OutputError::AnInput {
                    path: out.to_path_buf(),
                    input: p.clone(),
                },
            });
        }
    }
    let Ok(meta) = std::fs::metadata(out) else {
        // Nothing there yet (or a dangling link, whose target the write creates).
        return Ok(());
    };
    match sqlite_kind(out) {
        Some(SqliteKind::GeoPackage) if contents == Contents::GeoPackage => {}
        Some(SqliteKind::Pipewave) => {
            return Err(OutputError::ADatabase {
                path: out.to_path_buf(),
                what: "a pipewave database",
            })
        }
        Some(_) => {
            return Err(OutputError::ADatabase {
                path: out.to_path_buf(),
                what: "a SQLite database",
            })
        }
        None => {}
    }
    if meta.is_file() && meta.permissions().readonly() {
        return Err(OutputError::ReadOnly {
            path: out.to_path_buf(),
        });
    }
    Ok(())
}

/// Where an output path leads: the file it names after following its symlinks, and whether
/// that is a stream (a character device such as `/dev/null` or `/dev/stdout`, or a FIFO) to be
/// written directly rather than replaced.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Target {
    /// A regular file, or a path that does not exist yet: written through a temporary file
    /// renamed over it.
    File(PathBuf),
    /// A device or FIFO: opened for writing as it is, never replaced.
    Stream(PathBuf),
}

/// Follow `out`'s symlinks (also to a target that does not exist yet, which is then created)
/// and tell a stream from a file. A symlink is never replaced: its target is written.
fn resolve(out: &Path) -> Target {
    let mut path = out.to_path_buf();
    // A loop of links ends here and is left to the write to report.
    for _ in 0..40 {
        match std::fs::symlink_metadata(&path) {
            Ok(m) if m.file_type().is_symlink() => match std::fs::read_link(&path) {
                Ok(t) => {
                    path = match path.parent() {
                        Some(dir) if t.is_relative() => dir.join(t),
                        _ => t,
                    }
                }
                Err(_) => break,
            },
            Ok(m) if is_stream(&m.file_type()) => return Target::Stream(path),
            _ => break,
        }
    }
    Target::File(path)
}

#[cfg(unix)]
fn is_stream(t: &std::fs::FileType) -> bool {
    use std::os::unix::fs::FileTypeExt;
    t.is_char_device() || t.is_fifo() || t.is_block_device() || t.is_socket()
}

#[cfg(not(unix))]
fn is_stream(t: &std::fs::FileType) -> bool {
    !t.is_file() && !t.is_dir() && !t.is_symlink()
}

/// The prefix of the temporary files of an output named `name`: `.NAME.tmp-`, then the process
/// id, then nothing or SQLite's `-journal`, `-wal`, `-shm`.
fn temp_prefix(name: &str) -> String {
    format!(".{name}.tmp-")
}

/// Whether a process with this id is running (a temporary file of a live writer is kept).
#[cfg(unix)]
fn process_alive(pid: u32) -> bool {
    let Ok(pid) = libc::pid_t::try_from(pid) else {
        return false;
    };
    // SAFETY: kill with signal 0 sends nothing; it only asks whether the process exists.
    let r = unsafe { libc::kill(pid, 0) };
    r == 0 || io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
}

#[cfg(not(unix))]
fn process_alive(_pid: u32) -> bool {
    true
}

/// Remove the temporary files of `target` left by writers that are no longer running.
fn clean_stale(target: &Path) {
    let (Some(dir), Some(name)) = (target.parent(), target.file_name()) else {
        return;
    };
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let prefix = temp_prefix(&name.to_string_lossy());
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let own = std::process::id();
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        let Some(rest) = file_name.to_str().and_then(|n| n.strip_prefix(&prefix)) else {
            continue;
        };
        let digits: String = rest.chars().take_while(|c| c.is_ascii_digit()).collect();
        let tail = &rest[digits.len()..];
        if !matches!(tail, "" | "-journal" | "-wal" | "-shm") {
            continue;
        }
        let Ok(pid) = digits.parse::<u32>() else {
            continue;
        };
        if pid != own && !process_alive(pid) {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// A file being written to an output path: checked when created, written through a temporary
/// file beside the output, and moved over it by [`OutFile::commit`]. Dropped without a commit
/// (an error, a panic), it removes its temporary files and leaves the output as it was.
#[derive(Debug)]
pub struct OutFile {
    out: PathBuf,
    target: Target,
    tmp: PathBuf,
    file: Option<BufWriter<File>>,
    committed: bool,
}

impl OutFile {
    /// Check `out` ([`check`]) and open a temporary file for its contents.
    pub fn create(out: &Path, contents: Contents) -> Result<OutFile, OutputError> {
        let mut f = OutFile::prepare(out, contents)?;
        let file = File::create(&f.tmp).map_err(|source| OutputError::Write {
            path: out.to_path_buf(),
            source,
        })?;
        f.file = Some(BufWriter::new(file));
        Ok(f)
    }

    /// As [`OutFile::create`] for a writer that opens the temporary file itself by its path
    /// ([`OutFile::temp_path`], e.g. SQLite writing a GeoPackage). With `keep` the output's
    /// current contents are copied into it first, for a writer that adds to the file.
    pub fn for_path(out: &Path, contents: Contents, keep: bool) -> Result<OutFile, OutputError> {
        let f = OutFile::prepare(out, contents)?;
        let err = |source| OutputError::Write {
            path: out.to_path_buf(),
            source,
        };
        match &f.target {
            Target::File(t) if keep && t.is_file() => {
                std::fs::copy(t, &f.tmp).map_err(err)?;
            }
            _ => {
                let _ = std::fs::remove_file(&f.tmp);
            }
        }
        Ok(f)
    }

    fn prepare(out: &Path, contents: Contents) -> Result<OutFile, OutputError> {
        let suggested = out
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "output".into());
        check(out, contents, &suggested)?;
        let target = resolve(out);
        let (dir, name) = match &target {
            Target::File(p) => {
                clean_stale(p);
                (None, p.clone())
            }
            Target::Stream(p) => (Some(std::env::temp_dir()), p.clone()),
        };
        let file_name = name
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "output".into());
        let tmp_name = format!("{}{}", temp_prefix(&file_name), std::process::id());
        let tmp = match dir {
            Some(d) => d.join(tmp_name),
            None => name.with_file_name(tmp_name),
        };
        Ok(OutFile {
            out: out.to_path_buf(),
            target,
            tmp,
            file: None,
            committed: false,
        })
    }

    /// The temporary file the contents go to before [`OutFile::commit`].
    pub fn temp_path(&self) -> &Path {
        &self.tmp
    }

    /// The output path, as given.
    pub fn path(&self) -> &Path {
        &self.out
    }

    /// Flush the contents and move them over the output (or copy them into the stream it
    /// names). On failure the output is left as it was and the temporary file is removed.
    pub fn commit(mut self) -> Result<(), OutputError> {
        let err = |source| OutputError::Write {
            path: self.out.clone(),
            source,
        };
        if let Some(mut w) = self.file.take() {
            w.flush().map_err(err)?;
            let f = w.into_inner().map_err(|e| err(e.into_error()))?;
            f.sync_all().map_err(err)?;
        }
        match &self.target {
            Target::File(t) => std::fs::rename(&self.tmp, t).map_err(err)?,
            Target::Stream(t) => {
                let mut from = File::open(&self.tmp).map_err(err)?;
                let mut to = std::fs::OpenOptions::new()
                    .write(true)
                    .open(t)
                    .map_err(err)?;
                io::copy(&mut from, &mut to).map_err(err)?;
                to.flush().map_err(err)?;
                let _ = std::fs::remove_file(&self.tmp);
            }
        }
        self.committed = true;
        Ok(())
    }
}

impl Write for OutFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match &mut self.file {
            Some(f) => f.write(buf),
            None => Err(io::Error::other("this output is written by its path")),
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        match &mut self.file {
            Some(f) => f.flush(),
            None => Ok(()),
        }
    }
}

impl io::Seek for OutFile {
    fn seek(&mut self, pos: io::SeekFrom) -> io::Result<u64> {
        match &mut self.file {
            Some(f) => f.seek(pos),
            None => Err(io::Error::other("this output is written by its path")),
        }
    }
}

impl Drop for OutFile {
    fn drop(&mut self) {
        if self.committed {
            return;
        }
        self.file = None;
        let _ = std::fs::remove_file(&self.tmp);
        for suffix in ["-journal", "-wal", "-shm"] {
            let mut p = self.tmp.as_os_str().to_owned();
            p.push(suffix);
            let _ = std::fs::remove_file(PathBuf::from(p));
        }
    }
}

/// Write `bytes` to `out` through an [`OutFile`].
pub fn write_bytes(out: &Path, contents: Contents, bytes: &[u8]) -> Result<(), OutputError> {
    let mut f = OutFile::create(out, contents)?;
    f.write_all(bytes).map_err(|source| OutputError::Write {
        path: out.to_path_buf(),
        source,
    })?;
    f.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_uncommitted_file_leaves_the_output_as_it_was() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a.csv");
        std::fs::write(&out, "old").unwrap();
        {
            let mut f = OutFile::create(&out, Contents::Plain).unwrap();
            f.write_all(b"new").unwrap();
            assert!(f.temp_path().exists());
        }
        assert_eq!(std::fs::read_to_string(&out).unwrap(), "old");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        let mut f = OutFile::create(&out, Contents::Plain).unwrap();
        f.write_all(b"new").unwrap();
        f.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&out).unwrap(), "new");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_dead_writers_temporary_files_are_removed_and_a_live_ones_kept() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a.gpkg");
        // Process ids above the kernel's pid_max (4,194,304 at most on Linux) never run.
        let dead = dir.path().join(".a.gpkg.tmp-999999999");
        let dead_journal = dir.path().join(".a.gpkg.tmp-999999999-journal");
        let live = dir.path().join(format!(".a.gpkg.tmp-{}", 1));
        let other = dir.path().join(".b.gpkg.tmp-999999999");
        for p in [&dead, &dead_journal, &live, &other] {
            std::fs::write(p, "x").unwrap();
        }
        write_bytes(&out, Contents::Plain, b"new").unwrap();
        assert!(!dead.exists() && !dead_journal.exists());
        // pid 1 (init) is always running.
        assert!(live.exists());
        assert!(
            other.exists(),
            "another output's temporary file is not ours to remove"
        );
    }

    #[test]
    fn a_read_only_file_a_database_and_a_protected_input_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let ro = dir.path().join("ro.csv");
        std::fs::write(&ro, "keep").unwrap();
        let mut perm = std::fs::metadata(&ro).unwrap().permissions();
        perm.set_readonly(true);
        std::fs::set_permissions(&ro, perm).unwrap();
        assert!(matches!(
            write_bytes(&ro, Contents::Plain, b"x"),
            Err(OutputError::ReadOnly { .. })
        ));
        let db = dir.path().join("other.sqlite");
        rusqlite::Connection::open(&db)
            .unwrap()
            .execute_batch("CREATE TABLE t (x)")
            .unwrap();
        let before = std::fs::read(&db).unwrap();
        for contents in [Contents::Plain, Contents::GeoPackage] {
            assert!(matches!(
                write_bytes(&db, contents, b"x"),
                Err(OutputError::ADatabase {
                    what: "a SQLite database",
                    ..
                })
            ));
        }
        assert_eq!(std::fs::read(&db).unwrap(), before);
        let input = dir.path().join("input.csv");
        std::fs::write(&input, "in").unwrap();
        let link = dir.path().join("link.csv");
        std::os::unix::fs::symlink(&input, &link).unwrap();
        protect_input(&input);
        assert!(matches!(
            write_bytes(&link, Contents::Plain, b"x"),
            Err(OutputError::AnInput { .. })
        ));
        assert_eq!(std::fs::read_to_string(&input).unwrap(), "in");
    }

    #[test]
    fn a_geopackage_may_replace_a_geopackage_and_nothing_else_may() {
        let dir = tempfile::tempdir().unwrap();
        let gpkg = dir.path().join("a.gpkg");
        let conn = rusqlite::Connection::open(&gpkg).unwrap();
        conn.pragma_update(None, "application_id", GPKG_APPLICATION_ID as i32)
            .unwrap();
        conn.execute_batch("CREATE TABLE t (x)").unwrap();
        drop(conn);
        assert!(check(&gpkg, Contents::GeoPackage, "a.gpkg").is_ok());
        assert!(matches!(
            check(&gpkg, Contents::Plain, "a.gpkg"),
            Err(OutputError::ADatabase { .. })
        ));
    }
}
