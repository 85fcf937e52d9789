//! The scorer of the change test (`pipewave-lab score-campaigns`): a pipewave CSV export
//! against a truth.csv, of this lab's generator or of `pipewave synth --campaigns 2` (both
//! carry `change_effect`, `change_value`, `leak_band_speed_before_m_per_s`,
//! `leak_band_speed_after_m_per_s` and `change_z`).
//!
//! Definitions (every rate has its numerator and denominator printed):
//! * a truth row is *changed* when `change_effect` is neither `none` nor blank, *unchanged*
//!   when it is `none`; rows with a blank `change_effect` (synth's segments measured once) are
//!   not scored;
//! * *detected*: the export's `change_status` is `changed`. A changed pipe missing from the
//!   export, or reported `one_campaign` or `untested`, counts as not detected;
//! * *false alarms*: unchanged pipes reported `changed`, over the unchanged pipes that were
//!   tested (reported `changed` or `unchanged`); untested ones are counted apart;
//! * *cause right*: the export's `change_effect` equals truth's, over the detected changes;
//! * *coverage*: |after − v| ≤ 2σ with v, σ the export's `leak_band_speed_m_per_s` and
//!   `leak_band_speed_std_m_per_s`, over the changed pipes (a pipe without both counts as not
//!   covered);
//! * *σ ratio*: the export's `leak_band_speed_std_m_per_s` over the σ of the latest campaign
//!   fitted alone: the last entry of `speed_by_campaign`, or with `--single` the
//!   `leak_band_speed_std_m_per_s` of that export. Medians over the changed pipes, and over the
//!   unchanged pipes reported `unchanged` (the pooled ones).

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{bail, Context, Result};

/// A CSV file read as rows of named text cells (header names lower-cased and trimmed).
pub struct Table {
    /// Header names.
    pub headers: Vec<String>,
    /// Rows.
    pub rows: Vec<Vec<String>>,
}

/// A cell as written by a CSV exporter that guards against spreadsheet formulas: a leading
/// `'` before `=`, `+`, `-`, `@`, a tab or a carriage return is dropped (docs/interface.md).
pub fn clean_cell(s: &str) -> String {
    let t = s.trim();
    let mut chars = t.chars();
    if chars.next() == Some('\'') {
        if let Some(c) = chars.next() {
            if matches!(c, '=' | '+' | '-' | '@' | '\t' | '\r') {
                return t[1..].to_string();
            }
        }
    }
    t.to_string()
}

impl Table {
    /// Read a CSV file.
    pub fn read(path: &Path) -> Result<Self> {
        let mut r = csv::ReaderBuilder::new()
            .flexible(true)
            .from_path(path)
            .with_context(|| format!("reading {}", path.display()))?;
        let headers = r
            .headers()
            .with_context(|| format!("reading the header of {}", path.display()))?
            .iter()
            .map(|h| h.trim().trim_start_matches('\u{feff}').to_ascii_lowercase())
            .collect();
        let mut rows = Vec::new();
        for rec in r.records() {
            let rec = rec.with_context(|| format!("reading {}", path.display()))?;
            rows.push(rec.iter().map(clean_cell).collect());
        }
        Ok(Table { headers, rows })
    }

    /// Index of a column.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.headers.iter().position(|h| h == name)
    }

    /// Index of a column that must exist.
    pub fn require(&self, name: &str, what: &str) -> Result<usize> {
        match self.column(name) {
            Some(i) => Ok(i),
            None => bail!("{what} has no column `{name}`"),
        }
    }
}

/// Cell i of a row, blank when the row is short.
pub fn cell(row: &[String], i: usize) -> &str {
    row.get(i).map_or("", |s| s.as_str())
}

/// Cell of an optional column, blank when the column is missing.
pub fn cell_opt(row: &[String], i: Option<usize>) -> &str {
    i.map_or("", |i| cell(row, i))
}

/// A finite number, or None for a blank or unparsable cell.
pub fn number(s: &str) -> Option<f64> {
    s.trim().parse::<f64>().ok().filter(|v| v.is_finite())
}

/// One entry of `speed_by_campaign`: the campaign and, when the entry reads as
/// `SPEED ± STD m/s`, its leak-band speed and σ (m/s) fitted alone.
#[derive(Debug, Clone, PartialEq)]
pub struct CampaignSpeed {
    /// Campaign name.
    pub campaign: String,
    /// (speed, σ), None when the entry gives no number (e.g. the campaign's fit failed).
    pub speed: Option<(f64, f64)>,
}

/// Parse `CAMPAIGN: SPEED ± STD m/s` entries joined by `; ` (oldest first).
pub fn parse_speed_by_campaign(s: &str) -> Vec<CampaignSpeed> {
    s.split(';')
        .map(str::trim)
        .filter(|e| !e.is_empty())
        .map(|entry| {
            let (name, rest) = entry.rsplit_once(':').unwrap_or((entry, ""));
            let rest = rest.trim().trim_end_matches("m/s").trim();
            let speed = rest
                .split_once('±')
                .or_else(|| rest.split_once("+/-"))
                .and_then(|(v, sd)| Some((number(v)?, number(sd)?)));
            CampaignSpeed {
                campaign: name.trim().to_string(),
                speed,
            }
        })
        .collect()
}

/// σ of the latest campaign (the last entry) of a `speed_by_campaign` cell.
pub fn latest_std(s: &str) -> Option<f64> {
    parse_speed_by_campaign(s)
        .last()
        .and_then(|c| c.speed)
        .map(|v| v.1)
}

/// The truth of one re-measured segment.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthRow {
    /// `change_effect` (`none` when unchanged).
    pub effect: String,
    /// Noiseless leak-band speed after the change, m/s.
    pub speed_after: Option<f64>,
    /// z (P93).
    pub z: f64,
}

/// Read a truth.csv (lab or synth). Rows with a blank `change_effect` are left out.
pub fn read_truth(path: &Path) -> Result<BTreeMap<String, TruthRow>> {
    let t = Table::read(path)?;
    let what = format!("truth file {}", path.display());
    let id = t.require("segment_id", &what)?;
    let eff = t.require("change_effect", &what)?;
    let after = t.require("leak_band_speed_after_m_per_s", &what)?;
    let z = t.require("change_z", &what)?;
    let mut out = BTreeMap::new();
    for row in &t.rows {
        let effect = cell(row, eff).to_ascii_lowercase();
        if effect.is_empty() {
            continue;
        }
        let zv = number(cell(row, z))
            .with_context(|| format!("{what}: segment {} has no change_z", cell(row, id)))?;
        out.insert(
            cell(row, id).to_string(),
            TruthRow {
                effect,
                speed_after: number(cell(row, after)),
                z: zv,
            },
        );
    }
    Ok(out)
}

/// What the export says of one segment.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportRow {
    /// `change_status`, lower case (blank when the column is blank).
    pub status: String,
    /// `change_effect`, lower case.
    pub effect: String,
    /// `leak_band_speed_m_per_s`.
    pub speed: Option<f64>,
    /// `leak_band_speed_std_m_per_s`.
    pub std: Option<f64>,
    /// σ of the latest campaign fitted alone.
    pub single_std: Option<f64>,
}

/// Read an export; with `single`, the latest campaign's σ comes from that export instead of
/// `speed_by_campaign`.
pub fn read_export(path: &Path, single: Option<&Path>) -> Result<BTreeMap<String, ExportRow>> {
    let t = Table::read(path)?;
    let what = format!("export {}", path.display());
    let id = t.require("segment_id", &what)?;
    let status = t.require("change_status", &what)?;
    let effect = t.require("change_effect", &what)?;
    let speed = t.require("leak_band_speed_m_per_s", &what)?;
    let std = t.require("leak_band_speed_std_m_per_s", &what)?;
    let by_campaign = t.column("speed_by_campaign");
    let single_std: Option<HashMap<String, Option<f64>>> = match single {
        None => None,
        Some(p) => {
            let s = Table::read(p)?;
            let w = format!("single-campaign export {}", p.display());
            let sid = s.require("segment_id", &w)?;
            let sstd = s.require("leak_band_speed_std_m_per_s", &w)?;
            Some(
                s.rows
                    .iter()
                    .map(|r| (cell(r, sid).to_string(), number(cell(r, sstd))))
                    .collect(),
            )
        }
    };
    if single_std.is_none() && by_campaign.is_none() {
        bail!("{what} has no column `speed_by_campaign` (give --single FILE)");
    }
    let mut out = BTreeMap::new();
    for row in &t.rows {
        let key = cell(row, id).to_string();
        let single = match &single_std {
            Some(m) => m.get(&key).copied().flatten(),
            None => latest_std(cell_opt(row, by_campaign)),
        };
        out.insert(
            key,
            ExportRow {
                status: cell(row, status).to_ascii_lowercase(),
                effect: cell(row, effect).to_ascii_lowercase(),
                speed: number(cell(row, speed)),
                std: number(cell(row, std)).filter(|s| *s >= 0.0),
                single_std: single.filter(|s| *s > 0.0),
            },
        );
    }
    Ok(out)
}

/// A count out of a total.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Rate {
    /// Numerator.
    pub hits: usize,
    /// Denominator.
    pub of: usize,
}

impl Rate {
    /// Count one case, a hit or not.
    pub fn add(&mut self, hit: bool) {
        self.of += 1;
        self.hits += usize::from(hit);
    }

    /// hits / of, None for an empty denominator.
    pub fn fraction(&self) -> Option<f64> {
        (self.of > 0).then(|| self.hits as f64 / self.of as f64)
    }
}

impl std::fmt::Display for Rate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.fraction() {
            Some(x) => write!(f, "{}/{} = {:.1} %", self.hits, self.of, 100.0 * x),
            None => write!(f, "0/0 = -"),
        }
    }
}

/// The z classes of the detection table.
pub const Z_CLASSES: [(&str, f64, f64); 4] = [
    ("0-2", 0.0, 2.0),
    ("2-3", 2.0, 3.0),
    ("3-5", 3.0, 5.0),
    (">=5", 5.0, f64::INFINITY),
];

/// The score of one export against one truth.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Score {
    /// Detection per z class ([`Z_CLASSES`]).
    pub detection: [Rate; 4],
    /// Changed pipes not in the export, or reported `one_campaign` / `untested` / blank.
    pub changed_untested: usize,
    /// False alarms among tested unchanged pipes.
    pub false_alarms: Rate,
    /// Unchanged pipes not tested (missing, `one_campaign`, `untested`, blank).
    pub unchanged_untested: usize,
    /// Cause named right among detected changes.
    pub cause_right: Rate,
    /// Cause named right among detected changes with z ≥ 5.
    pub cause_right_z5: Rate,
    /// After-change truth within 2σ, changed pipes.
    pub coverage: Rate,
    /// The same for changes with z ≥ 5.
    pub coverage_z5: Rate,
    /// Median σ ratio of the changed pipes, and how many had both σ.
    pub sigma_ratio_changed: (Option<f64>, usize),
    /// Median σ ratio of the unchanged pipes reported `unchanged` (pooled), and how many.
    pub sigma_ratio_pooled: (Option<f64>, usize),
    /// Truth effect × reported outcome → count.
    pub confusion: BTreeMap<(String, String), usize>,
}

/// Median (None when empty).
pub fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

/// What a segment is reported as, for the confusion table: the export's `change_effect`
/// (`unexplained` if blank) when `changed`, `unchanged`, or the status (`one_campaign`,
/// `untested`, `missing` when the segment is not in the export, `blank`).
pub fn reported(e: Option<&ExportRow>) -> String {
    match e {
        None => "missing".into(),
        Some(e) => match e.status.as_str() {
            "changed" if e.effect.is_empty() => "unexplained".into(),
            "changed" => e.effect.clone(),
            "" => "blank".into(),
            s => s.to_string(),
        },
    }
}

/// Score an export against a truth.
pub fn score(truth: &BTreeMap<String, TruthRow>, export: &BTreeMap<String, ExportRow>) -> Score {
    let mut s = Score::default();
    let mut ratio_changed = Vec::new();
    let mut ratio_pooled = Vec::new();
    for (id, t) in truth {
        let e = export.get(id);
        *s.confusion
            .entry((t.effect.clone(), reported(e)))
            .or_insert(0) += 1;
        let status = e.map_or("", |e| e.status.as_str());
        let tested = matches!(status, "changed" | "unchanged");
        let detected = status == "changed";
        let ratio = e.and_then(|e| Some(e.std? / e.single_std?));
        if t.effect == "none" {
            if tested {
                s.false_alarms.add(detected);
            } else {
                s.unchanged_untested += 1;
            }
            if status == "unchanged" {
                ratio_pooled.extend(ratio);
            }
            continue;
        }
        let class = Z_CLASSES
            .iter()
            .position(|c| t.z >= c.1 && t.z < c.2)
            .unwrap_or(0);
        s.detection[class].add(detected);
        if !tested {
            s.changed_untested += 1;
        }
        if detected {
            let right = e.is_some_and(|e| e.effect == t.effect);
            s.cause_right.add(right);
            if t.z >= 5.0 {
                s.cause_right_z5.add(right);
            }
        }
        let covered = match (
            e.and_then(|e| e.speed),
            e.and_then(|e| e.std),
            t.speed_after,
        ) {
            (Some(v), Some(sd), Some(after)) => (after - v).abs() <= 2.0 * sd,
            _ => false,
        };
        s.coverage.add(covered);
        if t.z >= 5.0 {
            s.coverage_z5.add(covered);
        }
        ratio_changed.extend(ratio);
    }
    s.sigma_ratio_changed = (median(&mut ratio_changed), ratio_changed.len());
    s.sigma_ratio_pooled = (median(&mut ratio_pooled), ratio_pooled.len());
    s
}

/// Read both files and score.
pub fn score_files(export: &Path, truth: &Path, single: Option<&Path>) -> Result<Score> {
    let t = read_truth(truth)?;
    if t.is_empty() {
        bail!(
            "truth file {} has no re-measured segment (change_effect blank everywhere)",
            truth.display()
        );
    }
    Ok(score(&t, &read_export(export, single)?))
}

/// The rows and columns of the confusion table, in a fixed order, then any others.
fn confusion_axes(c: &BTreeMap<(String, String), usize>) -> (Vec<String>, Vec<String>) {
    let mut rows: Vec<String> = [
        "none",
        "soil_change",
        "air_in_water",
        "wall_thinning",
        "pipe_loss",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let mut cols: Vec<String> = [
        "unchanged",
        "soil_change",
        "air_in_water",
        "wall_thinning",
        "pipe_loss",
        "unexplained",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    for (r, k) in c.keys() {
        if !rows.contains(r) {
            rows.push(r.clone());
        }
        if !cols.contains(k) {
            cols.push(k.clone());
        }
    }
    rows.retain(|r| c.keys().any(|(a, _)| a == r));
    (rows, cols)
}

impl std::fmt::Display for Score {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let pct = |x: Option<f64>| x.map_or("-".to_string(), |v| format!("{v:.3}"));
        let mut t = String::new();
        writeln!(t, "{:<48} value", "measure").ok();
        writeln!(t, "{:-<48} {:-<24}", "", "").ok();
        writeln!(
            t,
            "{:<48} {}",
            "detected, changes with z >= 5", self.detection[3]
        )
        .ok();
        for (i, c) in Z_CLASSES.iter().enumerate() {
            writeln!(
                t,
                "{:<48} {}",
                format!("  detected, z {}", c.0),
                self.detection[i]
            )
            .ok();
        }
        writeln!(
            t,
            "{:<48} {}",
            "  changes not tested (counted as missed)", self.changed_untested
        )
        .ok();
        writeln!(
            t,
            "{:<48} {}",
            "false alarms, tested unchanged pipes", self.false_alarms
        )
        .ok();
        writeln!(
            t,
            "{:<48} {}",
            "  unchanged pipes not tested", self.unchanged_untested
        )
        .ok();
        writeln!(
            t,
            "{:<48} {}",
            "cause named right, detected", self.cause_right
        )
        .ok();
        writeln!(
            t,
            "{:<48} {}",
            "cause named right, detected with z >= 5", self.cause_right_z5
        )
        .ok();
        writeln!(
            t,
            "{:<48} {}",
            "after-change speed within 2 sigma, changed", self.coverage
        )
        .ok();
        writeln!(
            t,
            "{:<48} {}",
            "after-change speed within 2 sigma, z >= 5", self.coverage_z5
        )
        .ok();
        writeln!(
            t,
            "{:<48} {} (n = {})",
            "median sigma / latest alone, changed",
            pct(self.sigma_ratio_changed.0),
            self.sigma_ratio_changed.1
        )
        .ok();
        writeln!(
            t,
            "{:<48} {} (n = {})",
            "median sigma / latest alone, unchanged pooled",
            pct(self.sigma_ratio_pooled.0),
            self.sigma_ratio_pooled.1
        )
        .ok();
        writeln!(t).ok();
        writeln!(t, "confusion (rows: truth; columns: reported)").ok();
        let (rows, cols) = confusion_axes(&self.confusion);
        write!(t, "{:<14}", "truth").ok();
        for c in &cols {
            write!(t, " {:>13}", c).ok();
        }
        writeln!(t).ok();
        for r in &rows {
            write!(t, "{:<14}", r).ok();
            for c in &cols {
                let n = self
                    .confusion
                    .get(&(r.clone(), c.clone()))
                    .copied()
                    .unwrap_or(0);
                write!(t, " {:>13}", n).ok();
            }
            writeln!(t).ok();
        }
        f.write_str(&t)
    }
}
