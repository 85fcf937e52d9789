//! Elementary random draws. Everything the lab draws comes from a ChaCha8 stream
//! ([`segment_rng`]), so a seed fixes every file bit for bit on one platform.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The random stream of segment `index` (0-based) under `seed`: stream `index + 1` of the
/// seed's ChaCha8 generator. Stream 0 is the network's own (which pipes change). Independent
/// streams make the output independent of the number of threads.
pub fn segment_rng(seed: u64, index: usize) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(index as u64 + 1);
    rng
}

/// The network's stream (stream 0).
pub fn network_rng(seed: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(0);
    rng
}

/// Uniform on [lo, hi).
pub fn uniform<R: Rng>(rng: &mut R, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.gen::<f64>()
}

/// Log-uniform on [lo, hi) (lo, hi > 0).
pub fn log_uniform<R: Rng>(rng: &mut R, lo: f64, hi: f64) -> f64 {
    (lo.ln() + (hi.ln() - lo.ln()) * rng.gen::<f64>()).exp()
}

/// A standard normal draw (Box–Muller, one of the pair used).
pub fn std_normal<R: Rng>(rng: &mut R) -> f64 {
    // 1 − u lies in (0, 1], so the logarithm is finite.
    let u1 = 1.0 - rng.gen::<f64>();
    let u2 = rng.gen::<f64>();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// The stream of zone `g` (groups set): stream g of a generator seeded apart from the
/// segments' (the seed plus the 64-bit golden ratio), so zones and segments never share one.
pub fn zone_rng(seed: u64, g: usize) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_add(0x9e37_79b9_7f4a_7c15));
    rng.set_stream(g as u64);
    rng
}
