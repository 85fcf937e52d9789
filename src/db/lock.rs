//! One calibrate run at a time per database.
//!
//! A run takes the single row of table `run_lock` (migration 0002) before it starts and removes
//! it when it ends. A process that is killed cannot remove it, so a lock whose process no longer
//! exists is *stale* and is taken over. Whether the holder is alive is judged by the existence of
//! `/proc/<pid>`, which works on Linux (where pipewave runs nightly). Where `/proc` does not exist
//! (macOS, Windows) we cannot tell, and the lock is assumed live: after a crash there, remove the
//! row by hand (`DELETE FROM run_lock`). The check is also wrong for a database shared between
//! machines over a network file system, where the pid belongs to another machine; and a pid may
//! be reused by an unrelated process, which keeps a stale lock alive until that process ends.
//!
//! Taking the lock also marks the runs still `running` as `interrupted`: they cannot be running,
//! since no other calibrate holds the lock.

use std::path::Path;

use rusqlite::{params, Connection, OptionalExtension, TransactionBehavior};

use super::DbError;

/// The lock, as held by this process.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunLock {
    /// Our process id.
    pub pid: u32,
    /// When we took it (UTC, ISO 8601).
    pub started_at: String,
    /// The stale lock we took over, if any: (pid, started_at).
    pub took_over: Option<(i64, String)>,
}

/// Can we tell whether a process is alive on this system?
fn can_check_processes() -> bool {
    Path::new("/proc/self").exists()
}

/// Is process `pid` alive? Only meaningful when [`can_check_processes`].
fn process_exists(pid: i64) -> bool {
    pid > 0 && Path::new(&format!("/proc/{pid}")).exists()
}

/// Take the run lock for this process, or fail with [`DbError::Locked`] naming the holder.
pub fn try_acquire_run_lock(conn: &mut Connection) -> Result<RunLock, DbError> {
    acquire(conn, std::process::id())
}

fn acquire(conn: &mut Connection, pid: u32) -> Result<RunLock, DbError> {
    let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
    let holder: Option<(i64, String)> = tx
        .query_row(
            "SELECT pid, started_at FROM run_lock WHERE id = 1",
            [],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .optional()?;
    if let Some((hpid, started_at)) = &holder {
        if !can_check_processes() || process_exists(*hpid) {
            return Err(DbError::Locked {
                pid: *hpid,
                started_at: started_at.clone(),
            });
        }
    }
    tx.execute(
        "INSERT OR REPLACE INTO run_lock (id, pid, started_at) \
         VALUES (1, ?1, strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))",
        params![pid],
    )?;
    tx.execute(
        "UPDATE runs SET status = 'interrupted' WHERE status = 'running'",
        [],
    )?;
    let started_at: String =
        tx.query_row("SELECT started_at FROM run_lock WHERE id = 1", [], |r| {
            r.get(0)
        })?;
    tx.commit()?;
    Ok(RunLock {
        pid,
        started_at,
        took_over: holder,
    })
}

/// Give the lock back. Only removes it if `lock` still holds it (a lock taken over as stale by
/// another run is left alone).
pub fn release_run_lock(conn: &Connection, lock: &RunLock) -> Result<(), DbError> {
    conn.execute(
        "DELETE FROM run_lock WHERE id = 1 AND pid = ?1 AND started_at = ?2",
        params![lock.pid, lock.started_at],
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::db::migrate;

    fn db() -> Connection {
        let mut conn = Connection::open_in_memory().unwrap();
        migrate::migrate(&mut conn, Path::new(":memory:")).unwrap();
        conn
    }

    #[test]
    fn a_live_lock_blocks_and_release_frees_it() {
        let mut conn = db();
        let lock = try_acquire_run_lock(&mut conn).unwrap();
        assert_eq!(lock.pid, std::process::id());
        assert_eq!(lock.took_over, None);
        // We are alive, so a second acquisition (as another run would) fails, naming us.
        let err = try_acquire_run_lock(&mut conn).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.starts_with(&format!(
                "another calibrate run (pid {}, started {}) is using this database",
                lock.pid, lock.started_at
            )),
            "{msg}"
        );
        release_run_lock(&conn, &lock).unwrap();
        let again = try_acquire_run_lock(&mut conn).unwrap();
        release_run_lock(&conn, &again).unwrap();
    }

    #[test]
    fn a_stale_lock_is_taken_over_and_its_running_runs_marked_interrupted() {
        if !can_check_processes() {
            return; // Nothing to test without /proc: every lock is assumed live.
        }
        let mut conn = db();
        // pid_max on Linux is at most 2^22, so this pid cannot exist.
        let dead = 1 << 23;
        conn.execute(
            "INSERT INTO run_lock (id, pid, started_at) VALUES (1, ?1, '2020-01-01T00:00:00Z')",
            [dead],
        )
        .unwrap();
        conn.execute(
            "INSERT INTO runs (started_at, seed, model, program_version) \
             VALUES ('2020-01-01T00:00:00Z', 1, 'full', '0.1.0')",
            [],
        )
        .unwrap();
        let lock = try_acquire_run_lock(&mut conn).unwrap();
        assert_eq!(
            lock.took_over,
            Some((i64::from(dead), "2020-01-01T00:00:00Z".to_string()))
        );
        let status: String = conn
            .query_row("SELECT status FROM runs", [], |r| r.get(0))
            .unwrap();
        assert_eq!(status, "interrupted");
    }

    #[test]
    fn releasing_a_lock_taken_over_by_another_run_leaves_it() {
        let mut conn = db();
        let mine = acquire(&mut conn, 1 << 23).unwrap();
        if !can_check_processes() {
            return;
        }
        // Our pid is "dead", so another process takes over; our release must not free theirs.
        let theirs = try_acquire_run_lock(&mut conn).unwrap();
        release_run_lock(&conn, &mine).unwrap();
        let pid: i64 = conn
            .query_row("SELECT pid FROM run_lock", [], |r| r.get(0))
            .unwrap();
        assert_eq!(pid, i64::from(theirs.pid));
    }
}
