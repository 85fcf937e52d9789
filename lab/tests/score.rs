//! The scorer on hand-made fixtures (tests/fixtures): every rate below is counted by hand from
//! the fixture rows (the comments give the rows).

use std::path::PathBuf;

use pipewave_lab::score::{
    clean_cell, latest_std, parse_speed_by_campaign, score_files, Rate, Score,
};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn rate(hits: usize, of: usize) -> Rate {
    Rate { hits, of }
}

fn close(a: Option<f64>, b: f64) -> bool {
    a.is_some_and(|a| (a - b).abs() < 1e-12)
}

fn lab_score() -> Score {
    score_files(&fixture("export.csv"), &fixture("truth_lab.csv"), None).unwrap()
}

#[test]
fn detection_by_z_class_counts_untested_changes_as_missed() {
    let s = lab_score();
    // z >= 5: S06 changed, S07 Changed (case ignored), S08 unchanged, S13 one_campaign.
    assert_eq!(s.detection[3], rate(2, 4));
    // 0-2: S10 unchanged; 2-3: S09 changed; 3-5: S11 changed.
    assert_eq!(s.detection[0], rate(0, 1));
    assert_eq!(s.detection[1], rate(1, 1));
    assert_eq!(s.detection[2], rate(1, 1));
    assert_eq!(s.changed_untested, 1);
}

#[test]
fn false_alarms_are_over_the_tested_unchanged_pipes() {
    let s = lab_score();
    // Tested unchanged: S01, S02, S05 unchanged and S03 changed; S04 untested, S12 missing.
    assert_eq!(s.false_alarms, rate(1, 4));
    assert_eq!(s.unchanged_untested, 2);
    assert_eq!(s.false_alarms.fraction(), Some(0.25));
}

#[test]
fn cause_is_scored_among_detected_changes() {
    let s = lab_score();
    // Detected: S06 soil_change (right), S07 wall_thinning for air (wrong), S09 pipe_loss
    // (right), S11 air_in_water (right).
    assert_eq!(s.cause_right, rate(3, 4));
    assert_eq!(s.cause_right_z5, rate(1, 2));
}

#[test]
fn coverage_of_the_after_change_speed() {
    let s = lab_score();
    // S06 |990-992| = 2 <= 3; S07 20 > 10; S08 50 > 20; S09 1 <= 2; S10 1 <= 2; S11 no σ;
    // S13 5 <= 6.
    assert_eq!(s.coverage, rate(4, 7));
    assert_eq!(s.coverage_z5, rate(2, 4));
}

#[test]
fn sigma_ratios_from_speed_by_campaign() {
    let s = lab_score();
    // Changed: S06 1.5/1.5, S07 5/4, S08 10/12, S09 1/0.8, S13 3/2.5 (S10's latest unfitted,
    // S11 without σ): median of 0.833, 1, 1.2, 1.25, 1.25.
    assert_eq!(s.sigma_ratio_changed.1, 5);
    assert!(
        close(s.sigma_ratio_changed.0, 1.2),
        "{:?}",
        s.sigma_ratio_changed
    );
    // Pooled (unchanged, reported unchanged): S01 2/5, S02 3/4, S05 1/2.
    assert_eq!(s.sigma_ratio_pooled.1, 3);
    assert!(
        close(s.sigma_ratio_pooled.0, 0.5),
        "{:?}",
        s.sigma_ratio_pooled
    );
}

#[test]
fn single_campaign_export_replaces_speed_by_campaign() {
    let s = score_files(
        &fixture("export.csv"),
        &fixture("truth_lab.csv"),
        Some(&fixture("single.csv")),
    )
    .unwrap();
    // Changed: S06 1.5/3, S07 5/5, S08 10/20, S09 1/1, S10 1/1, S13 3/3 (S11 without σ).
    assert_eq!(s.sigma_ratio_changed.1, 6);
    assert!(
        close(s.sigma_ratio_changed.0, 1.0),
        "{:?}",
        s.sigma_ratio_changed
    );
    // Pooled: S01 2/5, S02 3/3, S05 1/1.
    assert_eq!(s.sigma_ratio_pooled.1, 3);
    assert!(
        close(s.sigma_ratio_pooled.0, 1.0),
        "{:?}",
        s.sigma_ratio_pooled
    );
    // Everything else is unchanged by --single.
    let base = lab_score();
    assert_eq!(s.detection, base.detection);
    assert_eq!(s.coverage, base.coverage);
    assert_eq!(s.confusion, base.confusion);
}

#[test]
fn confusion_table_truth_by_reported() {
    let s = lab_score();
    let get = |t: &str, r: &str| {
        s.confusion
            .get(&(t.to_string(), r.to_string()))
            .copied()
            .unwrap_or(0)
    };
    assert_eq!(get("none", "unchanged"), 3);
    assert_eq!(get("none", "soil_change"), 1);
    assert_eq!(get("none", "untested"), 1);
    assert_eq!(get("none", "missing"), 1);
    assert_eq!(get("soil_change", "soil_change"), 1);
    assert_eq!(get("soil_change", "unchanged"), 1);
    assert_eq!(get("air_in_water", "wall_thinning"), 1);
    assert_eq!(get("air_in_water", "air_in_water"), 1);
    assert_eq!(get("wall_thinning", "unchanged"), 1);
    assert_eq!(get("pipe_loss", "pipe_loss"), 1);
    assert_eq!(get("pipe_loss", "one_campaign"), 1);
    assert_eq!(s.confusion.values().sum::<usize>(), 13);
    let table = s.to_string();
    assert!(table.contains("2/4 = 50.0 %"), "{table}");
    assert!(table.contains("1/4 = 25.0 %"), "{table}");
    assert!(table.contains("wall_thinning"), "{table}");
}

#[test]
fn synth_truth_scores_the_same() {
    // Same segments in synth's columns and another order, with a published case and an
    // unmeasured segment whose change columns are blank (not scored).
    let synth = score_files(&fixture("export.csv"), &fixture("truth_synth.csv"), None).unwrap();
    assert_eq!(synth, lab_score());
}

#[test]
fn speed_by_campaign_entries() {
    let v = parse_speed_by_campaign("FD 2026: 1001.5 ± 3.2 m/s; IG-B: 990 ± 4 m/s");
    assert_eq!(v.len(), 2);
    assert_eq!(v[0].campaign, "FD 2026");
    assert_eq!(v[0].speed, Some((1001.5, 3.2)));
    assert_eq!(v[1].speed, Some((990.0, 4.0)));
    assert_eq!(latest_std("A: 1 ± 2 m/s; B: unfitted"), None);
    assert_eq!(latest_std("A: 1 ± 2 m/s"), Some(2.0));
    assert_eq!(latest_std(""), None);
    assert_eq!(clean_cell("'-0.8 %"), "-0.8 %");
    assert_eq!(clean_cell("'abc"), "'abc");
    assert_eq!(clean_cell(" 12 "), "12");
}

#[test]
fn missing_columns_are_named() {
    let e = score_files(&fixture("single.csv"), &fixture("truth_lab.csv"), None).unwrap_err();
    assert!(e.to_string().contains("change_status"), "{e}");
    let e = score_files(&fixture("export.csv"), &fixture("single.csv"), None).unwrap_err();
    assert!(e.to_string().contains("change_effect"), "{e}");
}
