//! The scorer of `pipewave diagnose` (`pipewave-lab score-diagnosis`): `diagnosis.csv` (and,
//! for the groups set, `groups.csv`) against the truth.csv of `pipewave-lab diagnosis`, over one
//! or more runs.
//!
//! Definitions (every rate is printed with its numerator and denominator):
//! * *right effect*: `named_effect` equals truth's `effect`, over the segments that hide an
//!   effect; *right or tied*: truth's effect is the named one or in `ambiguous_with`;
//! * *controls `none`*: `named_effect` is `none` (or blank), over the controls. A segment
//!   missing from diagnosis.csv counts as named `none` (diagnose lists the segments it
//!   diagnosed), and how many were missing is printed;
//! * *record named*: for an inventory error, `named_effect` is `inventory_error`; *record right*:
//!   also the first record of `record_set` (else `effect_value`), `material=…; OD … mm; wall …
//!   mm`, is the true record: the same material, OD within [`OD_TOLERANCE`] and wall within
//!   [`WALL_TOLERANCE`] (pipewave's catalogue walls differ from the lab's by rounding, e.g. ISO
//!   4065's 5.4 mm for 90 mm SDR 17 against 90/17 = 5.3); *true record in the set*: any entry of
//!   `record_set` is;
//! * *groups*: a zone of truth (`soil_zone`) is matched to the groups.csv row whose `group` is
//!   the zone's name or ends in it (`soil_zone=Z01`). A group is *detected* when its
//!   `named_effect` is an effect (not blank or `none`), or with `--group-level P` when its
//!   `p_value` < P; *detected right*: detected and `named_effect` is the zone's effect; *false
//!   alarm*: a clean zone detected; a run has a *family-wise false alarm* when any of its clean
//!   zones is detected; *carriers*: among the detected-right zones, the true carriers listed in
//!   `members` (recall) and the listed members that carry it (precision).

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use pipewave::db::import::aliases;
use pipewave::physics::Material;

use crate::score::{cell, cell_opt, number, Rate, Table};

/// Relative tolerance on the outside diameter of a named record.
pub const OD_TOLERANCE: f64 = 0.03;
/// Relative tolerance on the wall of a named record.
pub const WALL_TOLERANCE: f64 = 0.10;

/// A record as pipewave writes it: material code, OD and wall in mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Record {
    /// Material.
    pub material: Material,
    /// Outside diameter, mm.
    pub od_mm: f64,
    /// Wall, mm.
    pub wall_mm: f64,
}

/// Parse `material=DI; OD 170 mm; wall 6 mm` (order of the parts free, case ignored, the
/// material a code or a spelling pipewave's import reads).
pub fn parse_record(s: &str) -> Option<Record> {
    let (mut material, mut od, mut wall) = (None, None, None);
    for part in s.split(';').map(str::trim) {
        let lower = part.to_ascii_lowercase();
        if lower.starts_with("material=") {
            // The material as pipewave's import reads it: a code or a common spelling.
            material = aliases::material(part["material=".len()..].trim()).ok();
        } else if let Some(v) = lower.strip_prefix("od") {
            od = number(v.trim().trim_end_matches("mm"));
        } else if let Some(v) = lower.strip_prefix("wall") {
            wall = number(v.trim().trim_end_matches("mm"));
        }
    }
    Some(Record {
        material: material?,
        od_mm: od?,
        wall_mm: wall?,
    })
}

/// Whether a named record is the true one (same material, OD and wall within tolerance).
pub fn same_record(named: &Record, truth: &Record) -> bool {
    named.material == truth.material
        && (named.od_mm / truth.od_mm - 1.0).abs() <= OD_TOLERANCE
        && (named.wall_mm / truth.wall_mm - 1.0).abs() <= WALL_TOLERANCE
}

/// One segment of truth.csv.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthRow {
    /// `set`.
    pub set: String,
    /// `effect`: `none`, an effect name or `inventory_error`.
    pub effect: String,
    /// `kind`: the effect, the record error, or `none`.
    pub kind: String,
    /// `true_record`.
    pub true_record: Option<Record>,
    /// `soil_zone` (blank outside the groups set).
    pub zone: String,
    /// `group_effect`.
    pub group_effect: String,
}

/// Read a truth.csv of `pipewave-lab diagnosis`.
pub fn read_truth(path: &Path) -> Result<BTreeMap<String, TruthRow>> {
    let t = Table::read(path)?;
    let what = format!("truth file {}", path.display());
    let id = t.require("segment_id", &what)?;
    let set = t.require("set", &what)?;
    let effect = t.require("effect", &what)?;
    let kind = t.require("kind", &what)?;
    let rec = t.require("true_record", &what)?;
    let zone = t.column("soil_zone");
    let group_effect = t.column("group_effect");
    Ok(t.rows
        .iter()
        .map(|r| {
            (
                cell(r, id).to_string(),
                TruthRow {
                    set: cell(r, set).to_ascii_lowercase(),
                    effect: cell(r, effect).to_ascii_lowercase(),
                    kind: cell(r, kind).to_ascii_lowercase(),
                    true_record: parse_record(cell(r, rec)),
                    zone: cell_opt(r, zone).to_string(),
                    group_effect: cell_opt(r, group_effect).to_ascii_lowercase(),
                },
            )
        })
        .collect())
}

/// One row of diagnosis.csv.
#[derive(Debug, Clone, PartialEq)]
pub struct DiagnosisRow {
    /// `named_effect`, lower case (`none` when blank).
    pub named: String,
    /// `ambiguous_with`, split on `,`, `;`, `|` or spaces.
    pub ambiguous: Vec<String>,
    /// The records of `record_set` (split on ` | `), else of `effect_value`.
    pub records: Vec<Record>,
}

/// Split a list cell into names.
fn names(s: &str) -> Vec<String> {
    s.split([',', ';', '|', ' '])
        .map(|x| x.trim().to_ascii_lowercase())
        .filter(|x| !x.is_empty())
        .collect()
}

/// Read a diagnosis.csv (docs/interface.md, "`diagnose` output").
pub fn read_diagnosis(path: &Path) -> Result<BTreeMap<String, DiagnosisRow>> {
    let t = Table::read(path)?;
    let what = format!("diagnosis {}", path.display());
    let id = t.require("segment_id", &what)?;
    let named = t.require("named_effect", &what)?;
    let amb = t.column("ambiguous_with");
    let value = t.column("effect_value");
    let set = t.column("record_set");
    Ok(t.rows
        .iter()
        .map(|r| {
            let n = cell(r, named).to_ascii_lowercase();
            let mut records: Vec<Record> = cell_opt(r, set)
                .split('|')
                .filter_map(parse_record)
                .collect();
            if records.is_empty() {
                records.extend(parse_record(cell_opt(r, value)));
            }
            (
                cell(r, id).to_string(),
                DiagnosisRow {
                    named: if n.is_empty() { "none".into() } else { n },
                    ambiguous: names(cell_opt(r, amb)),
                    records,
                },
            )
        })
        .collect())
}

/// One row of groups.csv.
#[derive(Debug, Clone, PartialEq)]
pub struct GroupRow {
    /// `group`.
    pub group: String,
    /// `named_effect`, lower case.
    pub named: String,
    /// `p_value`.
    pub p_value: Option<f64>,
    /// `members` (the members carrying the named effect), split on `;`.
    pub members: BTreeSet<String>,
}

/// Read a groups.csv.
pub fn read_groups(path: &Path) -> Result<Vec<GroupRow>> {
    let t = Table::read(path)?;
    let what = format!("groups {}", path.display());
    let g = t.require("group", &what)?;
    let named = t.require("named_effect", &what)?;
    let p = t.require("p_value", &what)?;
    let members = t.column("members");
    Ok(t.rows
        .iter()
        .map(|r| GroupRow {
            group: cell(r, g).to_string(),
            named: cell(r, named).to_ascii_lowercase(),
            p_value: number(cell(r, p)),
            members: cell_opt(r, members)
                .split(';')
                .map(|m| m.trim().to_string())
                .filter(|m| !m.is_empty())
                .collect(),
        })
        .collect())
}

/// Whether a groups.csv `group` cell names `zone`: equal, or ending in it after `=`, `:` or a
/// space.
pub fn group_names_zone(group: &str, zone: &str) -> bool {
    let g = group.trim();
    g == zone
        || g.strip_suffix(zone)
            .is_some_and(|rest| rest.ends_with(['=', ':', ' ']))
}

/// One run to score.
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    /// truth.csv.
    pub truth: PathBuf,
    /// diagnosis.csv.
    pub diagnosis: PathBuf,
    /// groups.csv (groups set).
    pub groups: Option<PathBuf>,
}

/// The score of one or more runs.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Score {
    /// The set scored.
    pub set: String,
    /// Runs.
    pub runs: usize,
    /// Right effect over the segments hiding a physical effect.
    pub right_effect: Rate,
    /// Right effect or tied with it (`ambiguous_with`).
    pub right_or_tied: Rate,
    /// Right effect per hidden effect.
    pub by_effect: BTreeMap<String, Rate>,
    /// Controls named `none`.
    pub controls_none: Rate,
    /// Record errors named `inventory_error`.
    pub record_named: Rate,
    /// Record errors named with the true record first.
    pub record_right: Rate,
    /// Record errors whose true record is in `record_set`.
    pub record_in_set: Rate,
    /// Record right per kind.
    pub by_record: BTreeMap<String, Rate>,
    /// Truth segments missing from diagnosis.csv (counted as `none`).
    pub missing: usize,
    /// Affected zones detected with the right effect.
    pub groups_right: Rate,
    /// Affected zones detected (any effect).
    pub groups_detected: Rate,
    /// Clean zones detected.
    pub clean_false: Rate,
    /// Runs with a family-wise false alarm (any clean zone detected), over runs with clean zones.
    pub family_false: Rate,
    /// True carriers listed in `members` of detected-right zones.
    pub carriers_recall: Rate,
    /// Listed members of detected-right zones that carry the effect.
    pub carriers_precision: Rate,
    /// Zones of truth with no groups.csv row (counted as not detected).
    pub zones_missing: usize,
    /// Truth kind × named effect → count.
    pub confusion: BTreeMap<(String, String), usize>,
}

/// Score runs of one set. `set` must be each truth's `set`; `group_level` replaces the
/// method's own call of a group by `p_value < level`.
pub fn score_runs(set: &str, runs: &[Run], group_level: Option<f64>) -> Result<Score> {
    let mut s = Score {
        set: set.to_string(),
        runs: runs.len(),
        ..Score::default()
    };
    for run in runs {
        let truth = read_truth(&run.truth)?;
        if truth.is_empty() {
            bail!("truth file {} has no segment", run.truth.display());
        }
        if let Some((id, t)) = truth.iter().find(|(_, t)| t.set != set) {
            bail!(
                "truth file {}: segment {id} is of set `{}`, not `{set}`",
                run.truth.display(),
                t.set
            );
        }
        let diag = read_diagnosis(&run.diagnosis)?;
        for (id, t) in &truth {
            let d = diag.get(id);
            if d.is_none() {
                s.missing += 1;
            }
            let named = d.map_or("none", |d| d.named.as_str());
            *s.confusion
                .entry((t.kind.clone(), named.to_string()))
                .or_insert(0) += 1;
            match t.effect.as_str() {
                "none" => s.controls_none.add(named == "none"),
                "inventory_error" => {
                    let is_named = named == "inventory_error";
                    s.record_named.add(is_named);
                    let recs = d.map_or(&[][..], |d| &d.records[..]);
                    let first = is_named
                        && t.true_record
                            .zip(recs.first())
                            .is_some_and(|(tr, r)| same_record(r, &tr));
                    s.record_right.add(first);
                    s.by_record.entry(t.kind.clone()).or_default().add(first);
                    s.record_in_set.add(
                        t.true_record
                            .is_some_and(|tr| recs.iter().any(|r| same_record(r, &tr))),
                    );
                }
                e => {
                    let right = named == e;
                    s.right_effect.add(right);
                    s.by_effect.entry(e.to_string()).or_default().add(right);
                    s.right_or_tied
                        .add(right || d.is_some_and(|d| d.ambiguous.iter().any(|a| a == e)));
                }
            }
        }
        // Zones.
        let mut zones: BTreeMap<&str, (&str, BTreeSet<&str>)> = BTreeMap::new();
        for (id, t) in &truth {
            if t.zone.is_empty() {
                continue;
            }
            let z = zones
                .entry(t.zone.as_str())
                .or_insert((t.group_effect.as_str(), BTreeSet::new()));
            if t.effect != "none" {
                z.1.insert(id.as_str());
            }
        }
        if zones.is_empty() {
            continue;
        }
        let groups = match &run.groups {
            Some(p) => read_groups(p)?,
            None => bail!(
                "truth file {} has zones: give its groups.csv (--groups)",
                run.truth.display()
            ),
        };
        let mut any_false = false;
        let mut any_clean = false;
        for (zone, (effect, carriers)) in &zones {
            let row = groups.iter().find(|g| group_names_zone(&g.group, zone));
            if row.is_none() {
                s.zones_missing += 1;
            }
            let detected = row.is_some_and(|g| match group_level {
                Some(level) => g.p_value.is_some_and(|p| p < level),
                None => !g.named.is_empty() && g.named != "none",
            });
            if effect.is_empty() || *effect == "none" {
                any_clean = true;
                s.clean_false.add(detected);
                any_false |= detected;
                continue;
            }
            s.groups_detected.add(detected);
            let right = detected && row.is_some_and(|g| g.named == *effect);
            s.groups_right.add(right);
            if let (true, Some(g)) = (right, row) {
                for c in carriers {
                    s.carriers_recall.add(g.members.contains(*c));
                }
                for m in &g.members {
                    s.carriers_precision.add(carriers.contains(m.as_str()));
                }
            }
        }
        if any_clean {
            s.family_false.add(any_false);
        }
    }
    Ok(s)
}

impl std::fmt::Display for Score {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut t = String::new();
        let mut line = |name: &str, v: &dyn std::fmt::Display| {
            writeln!(t, "{name:<52} {v}").ok();
        };
        line("set", &self.set);
        line("runs", &self.runs);
        if self.right_effect.of > 0 {
            line("right effect, hidden effects", &self.right_effect);
            line("  right or tied (ambiguous_with)", &self.right_or_tied);
            for (e, r) in &self.by_effect {
                line(&format!("  right effect, {e}"), r);
            }
        }
        if self.record_named.of > 0 {
            line("record errors named inventory_error", &self.record_named);
            line(
                "record errors named as the actual record",
                &self.record_right,
            );
            for (k, r) in &self.by_record {
                line(&format!("  actual record, {k}"), r);
            }
            line("  actual record in record_set", &self.record_in_set);
        }
        line("controls named none", &self.controls_none);
        line(
            "  segments missing from diagnosis.csv (as none)",
            &self.missing,
        );
        if self.groups_detected.of > 0 || self.clean_false.of > 0 {
            line(
                "affected groups detected, right effect first",
                &self.groups_right,
            );
            line(
                "  affected groups detected, any effect",
                &self.groups_detected,
            );
            line(
                "  carriers listed in members (recall)",
                &self.carriers_recall,
            );
            line(
                "  members listed that carry it (precision)",
                &self.carriers_precision,
            );
            line("clean groups detected", &self.clean_false);
            line("runs with a family-wise false alarm", &self.family_false);
            line("  zones without a groups.csv row", &self.zones_missing);
        }
        writeln!(t).ok();
        writeln!(t, "confusion (rows: truth kind; columns: named_effect)").ok();
        let rows: BTreeSet<&String> = self.confusion.keys().map(|k| &k.0).collect();
        let cols: BTreeSet<&String> = self.confusion.keys().map(|k| &k.1).collect();
        write!(t, "{:<18}", "truth").ok();
        for c in &cols {
            write!(t, " {:>17}", c).ok();
        }
        writeln!(t).ok();
        for r in &rows {
            write!(t, "{:<18}", r).ok();
            for c in &cols {
                let n = self
                    .confusion
                    .get(&((*r).clone(), (*c).clone()))
                    .copied()
                    .unwrap_or(0);
                write!(t, " {:>17}", n).ok();
            }
            writeln!(t).ok();
        }
        f.write_str(&t)
    }
}
