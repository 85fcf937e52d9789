//! One calibrate run at a time per database.
//!
//! A run takes the single row of table `run_lock` (migration 0002) before it starts and removes
//! it when it ends (also when stopped by Ctrl-C or SIGTERM). A process that is killed cannot
//! remove it, so a lock whose process no longer runs is *stale* and is taken over.
//!
//! Whether the holder still runs is judged on Linux from `/proc`: the lock is live only if a
//! process with its pid exists *and* that process started before the lock was taken. A pid is
//! reused after a kill -9, an OOM kill or a reboot; the process that now has it started after
//! the lock's `started_at` (its start time is `/proc/<pid>/stat` field 22, clock ticks after the
//! boot time `btime` of `/proc/stat`), so the lock is stale. A tolerance of
//! [`START_TOLERANCE_S`] absorbs the one-second resolution of `btime`.
//!
//! Where `/proc` does not exist (macOS, Windows) we cannot tell, and the lock is assumed live:
//! after a crash there, remove the row by hand (`DELETE FROM run_lock`). The check is also
//! wrong for a database shared between machines over a network file system, where the pid
//! belongs to another machine.
//!
//! Taking the lock also marks the runs still `running` as `interrupted`, with their counts
//! taken from the fits they stored: they cannot be running, since no other calibrate holds the
//! lock.

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

/// A process that started more than this after a lock was taken cannot be its holder, s.
pub const START_TOLERANCE_S: f64 = 2.0;

/// When process `pid` started, seconds since the Unix epoch, from `/proc` (`None` where it
/// cannot be read).
fn process_start_s(pid: i64) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Field 2, the command name, is in parentheses and may hold spaces: count after it.
    let after = &stat[stat.rfind(')')? + 1..];
    // Fields from 3 (state) on; the start time is field 22.
    let ticks: f64 = after.split_whitespace().nth(22 - 3)?.parse().ok()?;
    let btime: f64 = std::fs::read_to_string("/proc/stat")
        .ok()?
        .lines()
        .find_map(|l| l.strip_prefix("btime "))?
        .trim()
        .parse()
        .ok()?;
    // SAFETY: sysconf only reads a system constant.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    (hz > 0).then(|| btime + ticks / hz as f64)
}

/// Does the lock taken at `started_at` (ISO 8601, UTC) by `pid` still have its holder? The pid
/// must exist and its process must have started before the lock was taken (otherwise the pid
/// was reused). Without `/proc` every lock is assumed live.
fn holder_alive(conn: &Connection, pid: i64, started_at: &str) -> Result<bool, DbError> {
    if !can_check_processes() {
        return Ok(true);
    }
    if !process_exists(pid) {
        return Ok(false);
    }
    let taken_s: Option<f64> = conn.query_row(
        "SELECT (julianday(?1) - 2440587.5) * 86400.0",
        [started_at],
        |r| r.get(0),
    )?;
    Ok(match (process_start_s(pid), taken_s) {
        (Some(start), Some(taken)) => start <= taken + START_TOLERANCE_S,
        // Cannot tell: assume live.
        _ => true,
    })
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
        if holder_alive(&tx, *hpid, started_at)? {
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
    // A run killed before it finished never wrote its counts: take them from its fits.
    tx.execute(
        "UPDATE runs SET status = 'interrupted', \
         n_ok = (SELECT count(*) FROM fits f WHERE f.run_id = runs.id AND f.status = 'ok'), \
         n_flagged = (SELECT count(*) FROM fits f \
                      WHERE f.run_id = runs.id AND f.status = 'flagged'), \
         n_failed = (SELECT count(*) FROM fits f \
                     WHERE f.run_id = runs.id AND f.status = 'failed') \
         WHERE status = 'running'",
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
    fn a_lock_whose_pid_was_reused_by_a_later_process_is_stale() {
        let mut conn = db();
        // Our own pid, but a lock taken long before this process started: the pid was reused.
        conn.execute(
            "INSERT INTO run_lock (id, pid, started_at) VALUES (1, ?1, '2001-01-01T00:00:00Z')",
            [std::process::id()],
        )
        .unwrap();
        let lock = try_acquire_run_lock(&mut conn).unwrap();
        assert_eq!(
            lock.took_over,
            Some((
                i64::from(std::process::id()),
                "2001-01-01T00:00:00Z".to_string()
            ))
        );
        // Taken now by this very process: live.
        assert!(matches!(
            try_acquire_run_lock(&mut conn),
            Err(DbError::Locked { .. })
        ));
        let start = process_start_s(i64::from(std::process::id())).unwrap();
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_secs_f64();
        assert!(
            start <= now + 1.0 && start > now - 86_400.0 * 365.0,
            "{start} {now}"
        );
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
