//! Schema migrations: the SQL files of `migrations/`, embedded in the binary, applied in order
//! inside one `BEGIN EXCLUSIVE` transaction and tracked by `PRAGMA user_version` (the number of
//! the last migration applied). Append-only, as cargo does it: a migration that has landed is
//! never edited; a change is a new numbered file.

use std::path::Path;

use rusqlite::{Connection, TransactionBehavior};

use super::DbError;

/// One migration: its number (the `user_version` after it), file name and SQL.
#[derive(Debug, Clone, Copy)]
pub struct Migration {
    /// Schema version after this migration; migrations are numbered 1, 2, 3, ...
    pub version: i64,
    /// File name in `migrations/`, for messages.
    pub name: &'static str,
    /// The SQL.
    pub sql: &'static str,
}

/// All migrations, in order. Add a new file here (and only at the end).
pub const MIGRATIONS: &[Migration] = &[
    Migration {
        version: 1,
        name: "0001_initial.sql",
        sql: include_str!("../../migrations/0001_initial.sql"),
    },
    Migration {
        version: 2,
        name: "0002_run_lock.sql",
        sql: include_str!("../../migrations/0002_run_lock.sql"),
    },
    Migration {
        version: 3,
        name: "0003_segment_effects.sql",
        sql: include_str!("../../migrations/0003_segment_effects.sql"),
    },
    Migration {
        version: 4,
        name: "0004_determined.sql",
        sql: include_str!("../../migrations/0004_determined.sql"),
    },
    Migration {
        version: 5,
        name: "0005_soil_zone.sql",
        sql: include_str!("../../migrations/0005_soil_zone.sql"),
    },
    Migration {
        version: 6,
        name: "0006_zone_fits.sql",
        sql: include_str!("../../migrations/0006_zone_fits.sql"),
    },
    Migration {
        version: 7,
        name: "0007_diagnose_viscoelastic.sql",
        sql: include_str!("../../migrations/0007_diagnose_viscoelastic.sql"),
    },
    Migration {
        version: 8,
        name: "0008_predictions.sql",
        sql: include_str!("../../migrations/0008_predictions.sql"),
    },
    Migration {
        version: 9,
        name: "0009_honest_errors.sql",
        sql: include_str!("../../migrations/0009_honest_errors.sql"),
    },
    Migration {
        version: 10,
        name: "0010_forced_refits.sql",
        sql: include_str!("../../migrations/0010_forced_refits.sql"),
    },
    Migration {
        version: 11,
        name: "0011_field.sql",
        sql: include_str!("../../migrations/0011_field.sql"),
    },
    Migration {
        version: 12,
        name: "0012_risk_weight.sql",
        sql: include_str!("../../migrations/0012_risk_weight.sql"),
    },
    Migration {
        version: 13,
        name: "0013_prediction_field_run.sql",
        sql: include_str!("../../migrations/0013_prediction_field_run.sql"),
    },
    Migration {
        version: 14,
        name: "0014_inputs_hash_v2.sql",
        sql: include_str!("../../migrations/0014_inputs_hash_v2.sql"),
    },
    Migration {
        version: 15,
        name: "0015_measurement_campaigns.sql",
        sql: include_str!("../../migrations/0015_measurement_campaigns.sql"),
    },
    Migration {
        version: 16,
        name: "0016_changes.sql",
        sql: include_str!("../../migrations/0016_changes.sql"),
    },
];

/// The schema version this program writes: that of the last migration.
pub fn latest_version() -> i64 {
    MIGRATIONS.last().map_or(0, |m| m.version)
}

/// `PRAGMA user_version`.
pub fn user_version(conn: &Connection) -> rusqlite::Result<i64> {
    conn.query_row("PRAGMA user_version", [], |r| r.get(0))
}

/// Whether the database has no schema at all: no pipewave version and no table (a new or empty
/// file, never imported into).
pub fn is_uninitialised(conn: &Connection) -> rusqlite::Result<bool> {
    let tables: i64 = conn.query_row(
        "SELECT count(*) FROM sqlite_master WHERE type = 'table'",
        [],
        |r| r.get(0),
    )?;
    Ok(user_version(conn)? == 0 && tables == 0)
}

/// Bring the schema up to date. `path` is only for messages.
pub fn migrate(conn: &mut Connection, path: &Path) -> Result<(), DbError> {
    let latest = latest_version();
    // Fast path without a write lock: an up-to-date database opened while a calibrate writes.
    if user_version(conn)? == latest {
        return Ok(());
    }
    let tx = conn.transaction_with_behavior(TransactionBehavior::Exclusive)?;
    // Re-read inside the lock: another process may have migrated meanwhile.
    let current = user_version(&tx)?;
    if current > latest {
        return Err(DbError::TooNew {
            path: path.to_path_buf(),
            found: current,
            known: latest,
        });
    }
    if current == 0 {
        let tables: Vec<String> = tx
            .prepare("SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY name")?
            .query_map([], |r| r.get(0))?
            .collect::<Result<_, _>>()?;
        if !tables.is_empty() {
            return Err(DbError::ForeignDatabase {
                path: path.to_path_buf(),
                tables: tables.join(", "),
            });
        }
    }
    for m in MIGRATIONS.iter().filter(|m| m.version > current) {
        let wrap = |source| DbError::Migration {
            version: m.version,
            name: m.name,
            source,
        };
        tx.execute_batch(m.sql).map_err(wrap)?;
        tx.pragma_update(None, "user_version", m.version)
            .map_err(wrap)?;
    }
    tx.commit()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn migrations_are_numbered_consecutively_from_one_and_named_by_number() {
        for (i, m) in MIGRATIONS.iter().enumerate() {
            let expected = i64::try_from(i).unwrap() + 1;
            assert_eq!(m.version, expected, "{}", m.name);
            assert!(
                m.name.starts_with(&format!("{expected:04}_")),
                "{} should start with {expected:04}_",
                m.name
            );
        }
    }

    #[test]
    fn migrating_twice_is_a_no_op_and_sets_user_version() {
        let mut conn = Connection::open_in_memory().unwrap();
        migrate(&mut conn, Path::new(":memory:")).unwrap();
        assert_eq!(user_version(&conn).unwrap(), latest_version());
        migrate(&mut conn, Path::new(":memory:")).unwrap();
        assert_eq!(user_version(&conn).unwrap(), latest_version());
    }

    #[test]
    fn a_newer_schema_is_refused() {
        let mut conn = Connection::open_in_memory().unwrap();
        conn.pragma_update(None, "user_version", latest_version() + 1)
            .unwrap();
        let err = migrate(&mut conn, Path::new("x.sqlite")).unwrap_err();
        assert!(matches!(err, DbError::TooNew { .. }), "{err}");
        assert!(err.to_string().contains("newer pipewave"), "{err}");
    }

    #[test]
    fn another_programs_database_is_refused_and_left_alone() {
        let mut conn = Connection::open_in_memory().unwrap();
        conn.execute_batch("CREATE TABLE customers (id INTEGER)")
            .unwrap();
        let err = migrate(&mut conn, Path::new("x.sqlite")).unwrap_err();
        assert!(matches!(err, DbError::ForeignDatabase { .. }), "{err}");
        assert_eq!(user_version(&conn).unwrap(), 0);
    }
}
