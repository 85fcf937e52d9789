//! Segments of `pipewave bench --verify` (realistic synthetic networks) on which the default
//! fit once ended more than 0.1 in χ² above the exhaustive search, for a reason since mended.
//! Each runs through `bench::verify` itself (the same independent yardstick, seeds and pass
//! mark as the command), and some assert the fit's χ² below a bound too: the test never sees a
//! stored answer. Each is named after the property of the misfit landscape the search must
//! cope with, not after the mechanism that copes with it today; the comments say which
//! mechanism that is, so that a new search can be judged on the same cases.

use pipewave::bench::{verify, VerifyRow, VERIFY_DCHI2_MAX};
use pipewave::synth::bench::{bench_network, MaterialMix};

/// `bench --verify` on segment `id` of the 200-segment network of `seed` (default mix).
fn verify_one(seed: u64, id: &str) -> VerifyRow {
    verify_one_of(seed, MaterialMix::Default, id)
}

/// [`verify_one`] on a network of the given material mix.
fn verify_one_of(seed: u64, mix: MaterialMix, id: &str) -> VerifyRow {
    let net = bench_network(200, seed, mix);
    let seg = net.iter().find(|s| s.id == id).expect("segment");
    let mut rows = verify(std::slice::from_ref(seg), 1);
    assert_eq!(rows.len(), 1);
    let r = rows.remove(0);
    assert!(
        r.excess() <= VERIFY_DCHI2_MAX,
        "{id}: default {} against the yardstick's {}",
        r.chi2,
        r.chi2_yardstick
    );
    r
}

/// [`verify_one`], and the default fit's χ² below `bound` (`before`: where it ended without the
/// mechanism under test).
fn verify_below(seed: u64, id: &str, bound: f64, before: &str) {
    verify_below_of(seed, MaterialMix::Default, id, bound, before);
}

/// [`verify_below`] on a network of the given material mix.
fn verify_below_of(seed: u64, mix: MaterialMix, id: &str, bound: f64, before: &str) {
    let r = verify_one_of(seed, mix, id);
    assert!(r.chi2 < bound, "{id}: χ² {} ({before})", r.chi2);
}

/// An MDPE segment whose best optimum lies in a narrow curved valley: the continued polish
/// with a forward-difference Jacobian stopped (small step) at χ² 3.891, 0.126 above the
/// exhaustive search's 3.765; with central differences it reaches the bottom.
#[test]
fn reaches_the_bottom_of_a_narrow_curved_valley() {
    verify_one(848484, "WM10139");
}

/// A ductile-iron segment whose global optimum is a nearly incompressible soil with c_P above
/// the pipe's wave speed (χ² 1.14 at c_P ≈ 2,500 m/s), past the grazing cliff: a search that
/// does not polish from the face r = c_S/c_P → its lower bound ends in the subsonic basin at
/// χ² 2.08 (c_P 166 m/s).
#[test]
fn finds_a_nearly_incompressible_optimum_past_grazing() {
    verify_below(848484, "WM10101", 1.5, "the subsonic basin is at 2.08");
}

/// A cast-iron segment whose global optimum is the fluid-like end of its c_P valley (ν_m at
/// its upper bound, c_S → 0, χ² 10.41): a search that does not polish from the face
/// r = c_S/c_P → its lower bound ends at the other end, ν_m = 0, at χ² 10.63.
#[test]
fn finds_the_fluid_like_end_of_a_valley_of_constant_c_p() {
    verify_below(848484, "WM10095", 10.5, "the ν_m = 0 end is at 10.63");
}

/// A thin MDPE segment whose soil's c_P lies among the measured phase speeds (506–538 m/s):
/// χ² jumps as c_P crosses each of them, and both DE runs ended in the piece just below
/// 507.3 m/s at χ² 9.50, while the piece above reaches 9.10. The grazing probe starts from the
/// best soil moved to the middle of each gap between the phase speeds.
#[test]
fn crosses_a_cliff_in_c_p_to_the_better_piece() {
    verify_below(848709, "WM10039", 9.3, "the piece below is at 9.50");
}

/// An MDPE segment whose better piece lies across a cliff in ξ (the contact moves the model's
/// phase speeds across c_P): the search ended at χ² 5.58 with ξ = 0.81, while the same soil at
/// ξ = 1 has 4.00. The grazing probe's scan of ξ at the best soil finds it.
#[test]
fn crosses_a_cliff_in_the_contact_coefficient() {
    verify_below(848613, "WM10148", 4.5, "the search's piece is at 5.58");
}

/// A PVC segment whose optimum sits on the edge of a grazing cliff (c_P = 493.5 m/s, next to
/// the phase speed 492 m/s): there the search path gives χ² 5.02 and the reference path 10.8,
/// so the answer fell to the next optimum the paths agreed on, χ² 9.11. Just off the cliff
/// (c_P × (1 − 1e-4)) both paths give 5.02.
#[test]
fn confirms_an_optimum_on_the_edge_of_a_cliff() {
    verify_below(848717, "WM10080", 5.5, "the next agreed optimum is at 9.11");
}

/// An MDPE segment whose optimum lies on the edge of a cliff, at the end of a valley that runs
/// along it: Levenberg–Marquardt's finite differences cross the cliff, and the polish stopped
/// where it met the edge, χ² 8.74 at ξ = 0.77; along the edge the misfit falls to 8.38 at
/// ξ = 0.69.
#[test]
fn reaches_the_low_end_of_a_valley_along_a_cliff_edge() {
    verify_below(
        848782,
        "WM10103",
        8.5,
        "the polish stopped on the edge at 8.74",
    );
}

/// Another MDPE segment on a cliff's edge: the polish stopped at χ² 6.60, and the edge leads
/// to 5.92.
#[test]
fn reaches_a_lower_contact_along_a_cliff_edge() {
    verify_below(
        848784,
        "WM10035",
        6.0,
        "the polish stopped on the edge at 6.60",
    );
}

/// An MDPE segment whose better piece (c_P 529 m/s, among the measured phase speeds 527–545
/// m/s) is narrow: a polish from the grazing probe's start inside it (c_P 527 m/s, ξ = 1)
/// leaves it downhill, back to the search's χ² 4.11 at c_P 349 m/s; the downhill simplex
/// from the same start stays in the piece and reaches 3.24.
#[test]
fn stays_in_a_narrow_piece_between_phase_speeds() {
    verify_below(848607, "WM10110", 3.5, "the polish returned to 4.11");
}

/// An MDPE segment whose best piece lies next to a piece that only the grazing probe's first
/// round finds: that round moves the best from χ² 10.54 to 10.34, and the second round, from
/// the new best's soil moved between the phase speeds 541 and 543 m/s, reaches 4.79.
#[test]
fn reaches_a_piece_next_to_one_found_across_a_cliff() {
    verify_below(848784, "WM10052", 5.0, "one round ends at 10.34");
}

/// A PVC segment whose optimum (χ² 14.84, c_P 491.7 m/s) lies where the reference path takes
/// another root at the highest frequency than the search path (phase speed 483.5 against
/// 488.1 m/s) and rates it 20.85: the two paths disagree up to c_P × (1 − 1e-3), so the answer
/// fell to an optimum at ξ = 0.95 with χ² 20.70. At c_P × (1 − 3e-3) both give 14.88.
#[test]
fn confirms_an_optimum_where_the_reference_path_takes_another_root() {
    verify_below_of(
        848860,
        MaterialMix::PlasticHeavy,
        "WM10273",
        15.0,
        "the answer fell to 20.70",
    );
}

/// A ductile-iron segment whose search ended at the fluid-like end of its valley of constant
/// c_P (ν_m = 0.499, c_S = 8 m/s, χ² 13.43, on the face r = c_S/c_P → its lower bound), while the
/// valley's other end (ν_m = 0, c_S 132 m/s) has 13.21. The faces of the speed coordinates
/// polish from that end: r = r_max at the same c_P.
#[test]
fn reaches_the_low_end_of_a_valley_of_constant_c_p() {
    verify_below(848873, "WM10013", 13.3, "the fluid-like end is at 13.43");
}

/// An MDPE segment of a plastic-heavy network whose search ended at χ² 15.80 with c_P 3,676
/// m/s (fit algorithm 13), while the exhaustive search's piece lies between the measured phase
/// speeds 490 and 494 m/s, at its own c_S and ξ (14.68). The gap scan finds that piece's
/// valley in (c_S, ξ) with c_P held.
#[test]
fn reaches_a_narrow_piece_between_phase_speeds_of_a_plastic_pipe() {
    verify_below_of(
        848857,
        MaterialMix::PlasticHeavy,
        "WM10084",
        15.0,
        "algorithm 13 ended at 15.80",
    );
}

/// A ductile-iron segment whose search ended on ν_m's upper bound at χ² 5.32 (fit algorithm
/// 13), while the same bound at c_P 1,342 m/s, just below the highest measured phase speed,
/// has 3.63. The gap scan keeps each target's c_S within ν_m's range.
#[test]
fn reaches_a_piece_on_the_incompressible_bound() {
    verify_below(848854, "WM10027", 4.0, "algorithm 13 ended at 5.32");
}

/// A cast-iron segment whose best piece lies between the measured phase speeds 1,335.4 and
/// 1,338.1 m/s (0.2 % apart): the gap scan's targets, 0.4 % from each phase speed, all fell
/// outside that gap, and the search ended at χ² 5.59 (c_P 1,376 m/s) against the exhaustive
/// search's 5.16 (c_P 1,336.9 m/s). A gap narrower than twice the offset is scanned at its
/// middle.
#[test]
fn reaches_a_piece_in_a_gap_of_0_2_percent_between_phase_speeds() {
    verify_below(
        848918,
        "WM10027",
        5.3,
        "without the gap's middle it ended at 5.59",
    );
}

/// A cast-iron segment whose best piece lies just below its highest model phase speed, where
/// that frequency has just begun to radiate: the search ended at χ² 1.37 with c_P 1,359 m/s
/// (highest model phase speed 1,337.75 m/s), while the exhaustive search's 0.57 lies at
/// 1,336.12 m/s. The gap scan targets c_P just below the best's highest model phase speed.
#[test]
fn reaches_a_piece_just_below_the_highest_model_phase_speed() {
    verify_below(
        848934,
        "WM10157",
        1.0,
        "without that target it ended at 1.37",
    );
}

/// Three cast-iron pipes whose global optimum lies in a basin far past grazing, narrower than a
/// tenth of a decade of E_m (log10 E_m 9.75–9.82, ν_m at its bound, c_P about 23,000 m/s, ξ
/// below 0.02), which a half-decade grid of E_m along the face ν_m = 0.499 steps over: searches
/// ended at χ² 20.09, 15.83 and 10.95 against the exhaustive 12.12, 12.04 and 9.45. The probe
/// also polishes from the stiffest soils, a line of moduli, when they fit promisingly; at
/// log10 E_m 9.75 alone WM10028's best candidate (23.6) was above twice the best's misfit.
#[test]
fn finds_a_narrow_basin_of_the_stiffest_soils() {
    verify_below(848723, "WM10084", 13.0, "the search ended at 20.09");
    verify_below_of(
        848958,
        MaterialMix::PlasticHeavy,
        "WM10046",
        13.0,
        "the search ended at 15.83",
    );
    verify_below_of(
        848977,
        MaterialMix::PlasticHeavy,
        "WM10028",
        9.6,
        "the search ended at 10.95",
    );
}

/// Two plastic pipes whose global optimum lies just above one of the model's phase speeds, in a
/// dip 0.2 % wide where that frequency's compressional wave has just stopped radiating: the
/// searches ended at χ² 14.38 (MDPE, c_P 366 m/s) and 18.49 (PVC, c_P 381 m/s) against the
/// exhaustive 10.38 (c_P 449.09 m/s, 0.3 % above its model phase speed 447.78) and 16.92
/// (507.77 m/s, above 506.01). The gap scan targets c_P just above each model phase speed.
#[test]
fn reaches_a_dip_just_above_a_model_phase_speed() {
    verify_below_of(
        848920,
        MaterialMix::PlasticHeavy,
        "WM10332",
        11.0,
        "the search ended at 14.38",
    );
    verify_below(848941, "WM10146", 17.5, "the search ended at 18.49");
}

/// Three plastic pipes whose best, after the probes, lies near grazing (a model phase speed
/// within 2 % of the soil's c_P or c_S) in a flat valley it has moved along since the gap scan
/// ran: the searches ended at χ² 5.56 (HDPE), 12.78 and 19.38 (MDPE) against the exhaustive
/// 5.39, 12.57 and 17.94. There the gap scan runs once more, from the best the probes left.
#[test]
fn reaches_the_optimum_of_a_flat_valley_near_grazing() {
    verify_below_of(
        849016,
        MaterialMix::PlasticHeavy,
        "WM10312",
        5.45,
        "the search ended at 5.56",
    );
    verify_below(849044, "WM10084", 12.65, "the search ended at 12.78");
    verify_below_of(
        849051,
        MaterialMix::PlasticHeavy,
        "WM10183",
        18.1,
        "the search ended at 19.38",
    );
}

/// A PVC pipe on which, from its own seed, both DE runs and every probe ended at χ² 59.68 (c_P
/// 4,013 m/s, ξ 1), flagged `high_misfit`, against the exhaustive search's 6.32 (c_P 400 m/s, ξ
/// 0.016), which 64 of 64 other seeds reach. A fit flagged `high_misfit` searches once more from
/// another seed.
///
/// Up to χ²/dof 20: WM10067 of plastic-heavy 849544 (MDPE) ended at χ² 69.05 (χ²/dof 13.8, above
/// fit algorithm 17's limit of 10) against the exhaustive 4.86, which 62 of 64 other seeds reach.
#[test]
fn reaches_the_optimum_where_the_first_search_ends_at_a_high_misfit() {
    verify_below(849214, "WM10098", 6.5, "the search ended at 59.68");
    verify_below_of(
        849544,
        MaterialMix::PlasticHeavy,
        "WM10067",
        5.0,
        "the search ended at 69.05",
    );
}

/// An HDPE pipe near grazing on which the search ended at χ² 18.57 against the exhaustive
/// search's 16.28 while a root solve on the search's paths could take 30 Newton and 20 Muller
/// iterations: the grazing probe's walks then took another path. With 12 and 10 (fit
/// algorithm 19, chosen for speed, not on this segment, which it mended by the way) the fit
/// reaches 16.29; a change to those caps shows here.
#[test]
fn reaches_the_optimum_of_an_hdpe_pipe_near_grazing() {
    verify_below_of(
        849533,
        MaterialMix::PlasticHeavy,
        "WM10395",
        16.4,
        "the search ended at 18.57",
    );
}

/// An MDPE segment whose data fix c_S and leave c_P nearly free: the search ended at χ² 3.26
/// with c_P 555 m/s, above the measured phase speeds (463–493 m/s), while the global optimum
/// (the yardstick's 3.08, c_S within 2 %) lies deep in the piece below them, at c_P 303 m/s,
/// where every frequency radiates. The grazing probe starts from the middle in ln c_P of each
/// outer piece (fit algorithm 24).
#[test]
fn finds_a_basin_deep_in_the_piece_below_the_measured_phase_speeds() {
    verify_below(
        981003,
        "WM10106",
        3.15,
        "the search ended at 3.26 above the measured speeds",
    );
}

/// A ductile-iron segment whose optimum lies on the face ν_m = 0 (r = 1/√2) with almost no
/// contact, c_P 1,270 m/s, just below the measured phase speeds (1,349–1,360 m/s): χ² 2.44.
/// The search ended on the same face with ξ = 0 at c_P 313 m/s, χ² 10.05: with ξ → 0 the misfit
/// depends on c_P nearly alone and has basins of its own along it. The faces stage rates a line
/// along that face below grazing and polishes its local minima.
#[test]
fn finds_a_basin_along_the_face_nu_zero_below_grazing() {
    verify_below(
        982008,
        "WM10194",
        2.5,
        "the search ended at 10.05 at c_P 313 m/s",
    );
}

/// A steel segment whose optimum lies on the same face at c_P 356 m/s (χ² 2.92), while the
/// search ended past grazing at c_P 1,746 m/s, r 0.20, ξ = 0 (χ² 3.22).
#[test]
fn finds_a_soft_basin_along_the_face_nu_zero() {
    verify_below(
        982011,
        "WM10086",
        3.0,
        "the search ended at 3.22 past grazing",
    );
}

/// Two segments, each ended by fit algorithm 25 in another piece than the best known one,
/// which the grazing probe's candidates reach only from a start more than twice the best misfit
/// (the gate was 2; it is 4 since algorithm 26): a cast-iron pipe at χ² 12.33 against the
/// yardstick's 11.16, and an MDPE pipe of a plastic-heavy network at 11.26, where the yardstick
/// (a grid in the speed coordinates) does no better and the search with the gate of 4 reaches
/// 6.64.
#[test]
fn crosses_a_cliff_from_a_candidate_well_above_the_best() {
    verify_below(
        990031,
        "WM10104",
        11.3,
        "the search ended at 12.33 with the gate of 2",
    );
    verify_below_of(
        991034,
        MaterialMix::PlasticHeavy,
        "WM10411",
        7.0,
        "the search ended at 11.26 with the gate of 2",
    );
}

/// Two MDPE segments whose global optimum lies below the measured phase speeds at a weak
/// contact (ξ ≈ 0.005): at ξ = 0 their misfit valley runs along constant c_S (the data of a
/// plastic pipe fix c_S, P47), here c_S ≈ 265 and 242 m/s at r = c_S/c_P ≈ 0.53–0.55, and it
/// is narrow in ξ. The face r = r_max meets the valley only at its soft end, where the misfit
/// is about 20 times the optimum's, and the DE runs settle at another c_S. The faces' line at
/// constant c_S from the local minima of the face's line at the weakest contact finds it.
/// Without that line the fits ended at 73.36 (the yardstick 4.17) and 48.44 (4.03).
#[test]
fn follows_a_valley_of_constant_shear_speed_at_a_weak_contact() {
    verify_below(
        995021,
        "WM10192",
        4.2,
        "the search ended at 73.36 without the line at constant c_S",
    );
    verify_below_of(
        989005,
        MaterialMix::PlasticHeavy,
        "WM10185",
        4.1,
        "the search ended at 48.44 without the line at constant c_S",
    );
}
