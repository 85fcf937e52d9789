//! Types shared across the layers: a fit's status and the fitting algorithm's version, which
//! the inversion produces and the database stores, and how far a segment's value can be trusted,
//! which the exports' styles and the audit's maps both draw.

use std::fmt;
use std::str::FromStr;

/// Version of the fitting algorithm, stored with every fit (`fits.algorithm_version`). A fit
/// made by another version is stale: `calibrate` refits it on its own. Bump it whenever a
/// change can move a stored fit; CHANGELOG.md says what each version changed.
pub const FIT_ALGORITHM_VERSION: i64 = 29;

/// Outcome status of a fit (`fits.status`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FitStatus {
    /// The prediction can be trusted: the model explains the data, the optimum is unique where
    /// it matters and the leak-band speed is determined.
    Ok,
    /// A fit with at least one flag: something for the user to act on.
    Flagged,
    /// No fit could be produced (see `message`).
    Failed,
}

impl FitStatus {
    /// Name used in the database.
    pub fn as_str(self) -> &'static str {
        match self {
            FitStatus::Ok => "ok",
            FitStatus::Flagged => "flagged",
            FitStatus::Failed => "failed",
        }
    }
}

impl fmt::Display for FitStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for FitStatus {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "ok" => Ok(FitStatus::Ok),
            "flagged" => Ok(FitStatus::Flagged),
            "failed" => Ok(FitStatus::Failed),
            _ => Err(format!("unknown fit status '{s}'")),
        }
    }
}

/// How far a segment's value can be trusted, which sets how its line is drawn (the colour says
/// the value): the audit's maps and the exports' QGIS style draw the same three kinds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Trust {
    /// A fit the model explains, speed within its limit (status `ok`), or no value at all:
    /// a plain solid line.
    Trusted,
    /// A prediction for a segment without measurements (status `predicted`, model §7.12):
    /// dotted.
    Predicted,
    /// Flagged or failed: dashed over a dark casing.
    Distrusted,
}

impl Trust {
    /// The kind of a segment from its exported status.
    pub fn of_status(status: &str) -> Trust {
        match status {
            "flagged" | "failed" => Trust::Distrusted,
            "predicted" => Trust::Predicted,
            _ => Trust::Trusted,
        }
    }
}
