//! Segments of `pipewave bench --verify` (realistic synthetic networks) on which the default
//! fit once ended more than 0.1 in χ² above the exhaustive search, for a reason since mended.
//! Each runs through `bench::verify` itself (the same exhaustive search, seeds and pass mark
//! as the command): the test never sees a stored answer.

use pipewave::bench::{bench_network, verify, MaterialMix, VERIFY_DCHI2_MAX};

/// An MDPE segment whose best optimum lies in a narrow curved valley: the continued polish
/// with a forward-difference Jacobian stopped (small step) at χ² 3.891, 0.126 above the
/// exhaustive search's 3.765; with central differences it reaches the bottom.
#[test]
fn the_continued_polish_reaches_the_bottom_of_a_narrow_curved_valley() {
    let net = bench_network(200, 848484, MaterialMix::Default);
    let seg = net.iter().find(|s| s.id == "WM10139").expect("segment");
    let rows = verify(std::slice::from_ref(seg), 1);
    assert_eq!(rows.len(), 1);
    let r = &rows[0];
    assert!(
        r.excess() <= VERIFY_DCHI2_MAX,
        "default {} against exhaustive {}",
        r.chi2,
        r.chi2_exhaustive
    );
}
