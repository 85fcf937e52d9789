//! The database: opening and migrating it, the imported inventory, and the calibration results.
//!
//! Only this module speaks SQL. Callers hold a [`Database`] (or the [`Connection`] inside it)
//! and use the functions of the submodules:
//!
//! - [`mod@import`]: `segments.csv` / `measurements.csv` into the inventory, all-or-nothing.
//! - [`inventory`]: reading segments and their measurements back as checked physics inputs.
//! - [`results`]: calibrate runs, fits and curves, and which segments need a (re)fit.
//! - [`lock`]: the one-calibrate-at-a-time lock.
//!
//! Schema changes are append-only SQL files in `migrations/`, embedded in the binary and applied
//! in order in one exclusive transaction, tracked by `PRAGMA user_version` ([`migrate`]).

pub mod changes;
pub mod crs;
pub mod effects;
pub mod field;
pub mod hash;
pub mod import;
pub mod inventory;
pub mod lock;
pub mod migrate;
pub mod pages;
pub mod results;
pub mod speeds;
pub mod staleness;
pub mod wkt;
pub mod zones;

use std::path::{Path, PathBuf};
use std::time::Duration;

pub use rusqlite::Connection;

pub use effects::{
    effects_of, fit_states, mark_forced_refits, segment_effects, set_segment_effects, FitState,
};
pub use import::{
    import, known_columns, CampaignCounts, ColumnRef, ImportOptions, ImportReport, ImportSource,
    RowError, SourceKind,
};
pub use inventory::{
    load_segment, load_segments, load_zoned_segments, MeasurementRecord, SegmentRecord,
};
pub use lock::{release_run_lock, try_acquire_run_lock, RunLock};
pub use results::{
    curves_for, finish_run, fit_states_page, fit_with_settings, insert_fit_with_change,
    insert_fit_with_curves, latest_fits, load_run, segments_needing_fit, start_run, CurvePoint,
    FitRow, FitStatus, NewRun, RunCounts, RunRow, RunStatus,
};
pub use staleness::{
    refresh_all_inputs_hashes, refresh_inputs_hash, stored_inputs_hash, InputsSweep,
};

/// How long a statement waits for another connection's write lock before giving up. A calibrate
/// run commits one segment at a time, each in a few milliseconds, so 10 s is ample.
pub const BUSY_TIMEOUT: Duration = Duration::from_secs(10);

/// Everything that can go wrong at the database boundary, worded for the engineer running the
/// import or the calibration.
#[derive(Debug, thiserror::Error)]
pub enum DbError {
    /// SQLite could not open or create the file.
    #[error("cannot open the database {}", path.display())]
    Open {
        /// The database path.
        path: PathBuf,
        /// What SQLite said.
        #[source]
        source: rusqlite::Error,
    },
    /// The path is a directory.
    #[error(
        "{} is a directory; give the path of the database file, such as {}",
        path.display(),
        path.join("pipewave.sqlite").display()
    )]
    IsDirectory {
        /// The database path.
        path: PathBuf,
    },
    /// The file exists but is not a SQLite database.
    #[error(
        "{} is not a pipewave database (it is not a SQLite file at all); check the --db path, \
         or give a new path and pipewave will create the database",
        path.display()
    )]
    NotADatabase {
        /// The database path.
        path: PathBuf,
    },
    /// A command that reads or fits an existing database was given a path with no file.
    #[error(
        "no pipewave database at {}; nothing was created (only `pipewave import` and \
         `pipewave run` create one): check the --db path, or import first with `pipewave \
         import --db {} --segments segments.csv --measurements measurements.csv`",
        path.display(),
        path.display()
    )]
    Missing {
        /// The database path.
        path: PathBuf,
    },
    /// The file is an SQLite database with no schema at all (an empty file, for instance).
    #[error(
        "{} is not a pipewave database (it is empty: nothing was ever imported into it); \
         import into it first with `pipewave import --db {} ...`, or check the --db path",
        path.display(),
        path.display()
    )]
    NotInitialised {
        /// The database path.
        path: PathBuf,
    },
    /// The file is a SQLite database of some other program.
    #[error(
        "{} is a SQLite database of another program (it has the tables {tables} but no pipewave \
         schema); check the --db path",
        path.display()
    )]
    ForeignDatabase {
        /// The database path.
        path: PathBuf,
        /// Its tables, comma-separated.
        tables: String,
    },
    /// The database was written by a newer pipewave.
    #[error(
        "{} was written by a newer pipewave (schema version {found}; this pipewave knows up to \
         version {known}); use the newer pipewave",
        path.display()
    )]
    TooNew {
        /// The database path.
        path: PathBuf,
        /// The schema version found in the file.
        found: i64,
        /// The newest schema version this program knows.
        known: i64,
    },
    /// A migration failed; the database is left as it was before.
    #[error("could not upgrade the database schema to version {version} ({name}); it was left unchanged")]
    Migration {
        /// The migration's version number.
        version: i64,
        /// The migration's file name.
        name: &'static str,
        /// What SQLite said.
        #[source]
        source: rusqlite::Error,
    },
    /// The database is damaged.
    #[error("the database file is damaged (SQLite reports corruption); restore it from a backup or re-import into a new file")]
    Corrupt(#[source] rusqlite::Error),
    /// SQLite's check of the file found damage when a command that writes opened it.
    #[error(
        "the database {} is damaged (SQLite's quick_check: {report}); nothing was written to \
         it: restore it from a backup or re-import into a new file",
        path.display()
    )]
    Damaged {
        /// The database path.
        path: PathBuf,
        /// The first problems quick_check reported, `; `-separated.
        report: String,
    },
    /// A database of an older schema that cannot be upgraded here.
    #[error(
        "{} has schema version {found} and this pipewave needs version {needed}; upgrading it \
         needs write access, which {} does not give (a read-only file system or folder?): \
         copy the database to a writable place, or run a writing command (such as import) \
         where it can be written",
        path.display(),
        path.parent().map_or_else(|| path.display(), |d| d.display())
    )]
    NeedsUpgrade {
        /// The database path.
        path: PathBuf,
        /// Its schema version.
        found: i64,
        /// The version this program reads.
        needed: i64,
    },
    /// Another connection held the write lock for longer than [`BUSY_TIMEOUT`].
    #[error("the database is busy: another pipewave process kept it locked for more than 10 s; try again when it has finished")]
    Busy(#[source] rusqlite::Error),
    /// An input file could not be read.
    #[error("cannot read {}", path.display())]
    ReadFile {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// Segment ids asked for that are not in the inventory.
    #[error("segment(s) not in the inventory: {ids} (import them first, or check the spelling)")]
    UnknownSegments {
        /// The unknown ids, comma-separated.
        ids: String,
    },
    /// Another calibrate run holds the run lock.
    #[error(
        "another calibrate run (pid {pid}, started {started_at}) is using this database; wait for \
         it to finish (if you are sure no calibrate is running, for instance on another machine \
         sharing the file, delete the row of the table run_lock)"
    )]
    Locked {
        /// Process id of the holder.
        pid: i64,
        /// When it started (UTC, ISO 8601).
        started_at: String,
    },
    /// A stored value that pipewave cannot interpret (the file was edited by hand?).
    #[error("the database holds a value pipewave cannot read: {what}")]
    BadStoredValue {
        /// What and where.
        what: String,
    },
    /// Any other SQLite error.
    #[error("database error")]
    Sqlite(#[source] rusqlite::Error),
}

impl From<rusqlite::Error> for DbError {
    fn from(e: rusqlite::Error) -> Self {
        use rusqlite::ErrorCode;
        match e.sqlite_error_code() {
            Some(ErrorCode::DatabaseBusy | ErrorCode::DatabaseLocked) => DbError::Busy(e),
            Some(ErrorCode::DatabaseCorrupt) => DbError::Corrupt(e),
            _ => DbError::Sqlite(e),
        }
    }
}

/// An open, migrated pipewave database.
#[derive(Debug)]
pub struct Database {
    conn: Connection,
    path: PathBuf,
}

impl Database {
    /// Open the database at `path`, creating the file if it does not exist, and bring its
    /// schema up to date. Sets `foreign_keys = ON`, `journal_mode = WAL`, `synchronous =
    /// NORMAL` and a busy timeout of [`BUSY_TIMEOUT`].
    ///
    /// `synchronous = NORMAL` is SQLite's setting for WAL: a commit does not wait for the disk,
    /// only checkpoints do. A process that is killed loses no commit (the WAL is in the
    /// operating system's cache); a power cut may roll back the last commits, never corrupt the
    /// file, and a calibrate run refits what is missing. With `FULL` (SQLite's default) every
    /// segment's commit waited for its own fsync, and that I/O took about a tenth of the fitting
    /// time from two workers on two cores (`pipewave bench --calibrate 1000`: per-worker time
    /// 12.4–12.7 ms with two jobs against 10.9–11.9 with one, speed-up 1.72–1.84×; with
    /// `NORMAL` 10.7–10.9 against 10.5–10.7, 1.91–1.95×).
    ///
    /// Errors: [`DbError::NotADatabase`] for a file that is not SQLite,
    /// [`DbError::ForeignDatabase`] for another program's database, [`DbError::TooNew`] for a
    /// database of a newer pipewave.
    pub fn open(path: impl AsRef<Path>) -> Result<Database, DbError> {
        Self::open_with(path.as_ref(), true)
    }

    /// Open an existing pipewave database, as every command but `import` and `run` does: it
    /// never creates a file. Errors as [`Database::open`], and [`DbError::Missing`] when no
    /// file is at `path`, [`DbError::NotInitialised`] for a database with no schema at all (an
    /// empty file). An older pipewave database is migrated as by [`Database::open`].
    pub fn open_existing(path: impl AsRef<Path>) -> Result<Database, DbError> {
        Self::open_with(path.as_ref(), false)
    }

    fn open_with(path: &Path, create: bool) -> Result<Database, DbError> {
        use rusqlite::OpenFlags;
        // No file this process writes may replace the database it uses.
        crate::outfile::protect_database(path);
        let path = path.to_path_buf();
        if path.is_dir() {
            return Err(DbError::IsDirectory { path });
        }
        if !create && !path.exists() {
            return Err(DbError::Missing { path });
        }
        let mut flags = OpenFlags::SQLITE_OPEN_READ_WRITE
            | OpenFlags::SQLITE_OPEN_URI
            | OpenFlags::SQLITE_OPEN_NO_MUTEX;
        if create {
            flags |= OpenFlags::SQLITE_OPEN_CREATE;
        }
        let conn = Connection::open_with_flags(&path, flags).map_err(|source| {
            match source.sqlite_error_code() {
                Some(rusqlite::ErrorCode::CannotOpen) if !create && !path.exists() => {
                    DbError::Missing { path: path.clone() }
                }
                _ => DbError::Open {
                    path: path.clone(),
                    source,
                },
            }
        })?;
        let not_a_db = |e: rusqlite::Error| match e.sqlite_error_code() {
            Some(rusqlite::ErrorCode::NotADatabase) => DbError::NotADatabase { path: path.clone() },
            _ => DbError::from(e),
        };
        conn.busy_timeout(BUSY_TIMEOUT).map_err(not_a_db)?;
        // A command that writes must not add to a damaged file (it would store results in a
        // database whose other pages are lost): check the structure first.
        quick_check(&conn, &path).map_err(|e| match e {
            DbError::Sqlite(e) => not_a_db(e),
            e => e,
        })?;
        conn.pragma_update(None, "foreign_keys", true)
            .map_err(not_a_db)?;
        if !create && migrate::is_uninitialised(&conn).map_err(not_a_db)? {
            return Err(DbError::NotInitialised { path });
        }
        // journal_mode returns the mode now in force; a file that is not SQLite fails here.
        let _mode: String = conn
            .query_row("PRAGMA journal_mode = WAL", [], |r| r.get(0))
            .map_err(not_a_db)?;
        conn.pragma_update(None, "synchronous", "NORMAL")
            .map_err(not_a_db)?;
        let mut db = Database { conn, path };
        migrate::migrate(&mut db.conn, &db.path)?;
        Ok(db)
    }

    /// Open an existing database to read it (export, audit). Where the file and its folder
    /// can be written this is [`Database::open_existing`] (the schema is brought up to date,
    /// nothing is created); where
    /// they cannot (a read-only file system, a backup mount), the
    /// file is opened read-only and *immutable* ([`Database::open_immutable`]), so SQLite needs
    /// neither a lock nor its `-wal`/`-shm` files beside it.
    pub fn open_reader(path: impl AsRef<Path>) -> Result<Database, DbError> {
        let path = path.as_ref().to_path_buf();
        if path.is_dir() {
            return Err(DbError::IsDirectory { path });
        }
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        if !path.exists() {
            return Err(DbError::Missing { path });
        }
        if writable(&path) && writable(&dir) {
            return Database::open_existing(&path);
        }
        Database::open_immutable(&path)
    }

    /// Open a database read-only and immutable: nothing is written, not even a lock or a
    /// journal, so it works on a read-only file system. Only for files no process is writing.
    /// Errors: [`DbError::NeedsUpgrade`] for an older schema (upgrading writes).
    pub fn open_immutable(path: impl AsRef<Path>) -> Result<Database, DbError> {
        let path = path.as_ref().to_path_buf();
        crate::outfile::protect_database(&path);
        let flags = rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY
            | rusqlite::OpenFlags::SQLITE_OPEN_URI
            | rusqlite::OpenFlags::SQLITE_OPEN_NO_MUTEX;
        let uri = format!("file:{}?immutable=1", uri_path(&path));
        let conn = Connection::open_with_flags(uri, flags).map_err(|source| DbError::Open {
            path: path.clone(),
            source,
        })?;
        let version = migrate::user_version(&conn).map_err(|e| match e.sqlite_error_code() {
            Some(rusqlite::ErrorCode::NotADatabase) => DbError::NotADatabase { path: path.clone() },
            _ => DbError::from(e),
        })?;
        let latest = migrate::latest_version();
        if version > latest {
            return Err(DbError::TooNew {
                path,
                found: version,
                known: latest,
            });
        }
        if version < latest {
            return Err(DbError::NeedsUpgrade {
                path,
                found: version,
                needed: latest,
            });
        }
        Ok(Database { conn, path })
    }

    /// The connection, for the functions of the submodules.
    pub fn conn(&self) -> &Connection {
        &self.conn
    }

    /// The connection, for the functions of the submodules that write in a transaction.
    pub fn conn_mut(&mut self) -> &mut Connection {
        &mut self.conn
    }

    /// The path the database was opened from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The schema version (`PRAGMA user_version`).
    pub fn schema_version(&self) -> Result<i64, DbError> {
        Ok(migrate::user_version(&self.conn)?)
    }
}

/// `PRAGMA quick_check`: the file's b-trees and pages are sound, or [`DbError::Damaged`] with
/// the first problems SQLite found. It reads every page once (about as long as reading the
/// file).
pub fn quick_check(conn: &Connection, path: &Path) -> Result<(), DbError> {
    let damaged = |report: String| DbError::Damaged {
        path: path.to_path_buf(),
        report: crate::units::escape_controls(&report).into_owned(),
    };
    // Damage that stops the check itself (a broken schema page) is reported the same way.
    let run = || -> rusqlite::Result<Vec<String>> {
        conn.prepare("PRAGMA quick_check(5)")?
            .query_map([], |r| r.get(0))?
            .collect()
    };
    let found = match run() {
        Ok(found) => found,
        Err(e) if e.sqlite_error_code() == Some(rusqlite::ErrorCode::DatabaseCorrupt) => {
            return Err(damaged(e.to_string()))
        }
        Err(e) => return Err(e.into()),
    };
    if found.len() == 1 && found[0] == "ok" {
        return Ok(());
    }
    Err(damaged(found.join("; ")))
}

/// Can this process write `path` (a file or folder)? False on a read-only file system.
#[cfg(unix)]
fn writable(path: &Path) -> bool {
    use std::os::unix::ffi::OsStrExt;
    let Ok(c) = std::ffi::CString::new(path.as_os_str().as_bytes()) else {
        return false;
    };
    // SAFETY: `c` is a valid NUL-terminated path for the duration of the call.
    unsafe { libc::access(c.as_ptr(), libc::W_OK) == 0 }
}

#[cfg(not(unix))]
fn writable(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| !m.permissions().readonly())
}

/// A path for a SQLite `file:` URI: the characters URIs reserve are percent-encoded.
fn uri_path(path: &Path) -> String {
    let mut out = String::new();
    for b in path.to_string_lossy().bytes() {
        match b {
            b'?' | b'#' | b'%' => out.push_str(&format!("%{b:02X}")),
            _ => out.push(char::from(b)),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_immutable_reader_writes_nothing_beside_the_file_and_refuses_an_old_schema() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a #1?.sqlite");
        drop(Database::open(&path).unwrap());
        let before = std::fs::read(&path).unwrap();
        let db = Database::open_immutable(&path).unwrap();
        let n: i64 = db
            .conn()
            .query_row("SELECT count(*) FROM segments", [], |r| r.get(0))
            .unwrap();
        assert_eq!(n, 0);
        drop(db);
        assert_eq!(std::fs::read(&path).unwrap(), before);
        let names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, vec!["a #1?.sqlite".to_string()]);

        let conn = Connection::open(&path).unwrap();
        conn.pragma_update(None, "user_version", 5).unwrap();
        drop(conn);
        let e = Database::open_immutable(&path).unwrap_err().to_string();
        assert!(
            e.contains("has schema version 5 and this pipewave needs version"),
            "{e}"
        );
        assert!(e.contains(&dir.path().display().to_string()), "{e}");
    }
}
