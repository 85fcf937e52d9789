//! The synthetic networks the benchmarks and the fit's regression cases time and check: a
//! realistic network from [`crate::synth::generate`] with each segment's fit inputs and the seed
//! `calibrate` would give it.

/// Which materials a benchmark network holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MaterialMix {
    /// The synthetic network's own mix ([`crate::synth::MATERIAL_MIX`]: 45 % iron, 40 % plastic).
    #[default]
    Default,
    /// Four plastic segments (PVC, MDPE, HDPE) for every other one.
    PlasticHeavy,
}

impl std::str::FromStr for MaterialMix {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "default" => Ok(MaterialMix::Default),
            "plastic-heavy" => Ok(MaterialMix::PlasticHeavy),
            _ => Err(format!(
                "unknown material mix `{s}` (expected default, plastic-heavy)"
            )),
        }
    }
}

/// Plastic share of a plastic-heavy benchmark network.
pub const PLASTIC_HEAVY_SHARE: f64 = 0.8;

/// One segment of a benchmark network: its id, what the fit is given, and its fit seed.
#[derive(Debug, Clone)]
pub struct BenchSegment {
    /// Asset id.
    pub id: String,
    /// Inventory material.
    pub material: crate::physics::Material,
    /// The fit's inputs.
    pub data: crate::invert::SegmentData,
    /// The fit's seed (as `calibrate` derives it from the run seed and the id).
    pub seed: u64,
}

/// A realistic synthetic network for timing: `segments` segments from `synth` (all materials,
/// 4–8 frequencies spread over each pipe's measurable band, 1 %/5 % noise with stated
/// standard deviations, no defects), seeded by `seed`. `PlasticHeavy` keeps every plastic
/// segment and enough of the others to make them [`PLASTIC_HEAVY_SHARE`] of the network.
pub fn bench_network(segments: usize, seed: u64, mix: MaterialMix) -> Vec<BenchSegment> {
    use crate::synth::{generate, SynthOptions};
    let generated = match mix {
        MaterialMix::Default => generate(&SynthOptions {
            segments,
            seed,
            defect_fraction: 0.0,
            ..SynthOptions::default()
        }),
        MaterialMix::PlasticHeavy => {
            let all = generate(&SynthOptions {
                segments: 3 * segments,
                seed,
                defect_fraction: 0.0,
                ..SynthOptions::default()
            });
            let n_plastic = (PLASTIC_HEAVY_SHARE * segments as f64).round() as usize;
            let plastic = all
                .iter()
                .filter(|s| s.material.is_plastic())
                .take(n_plastic);
            let other = all
                .iter()
                .filter(|s| !s.material.is_plastic())
                .take(segments - n_plastic.min(segments));
            plastic.chain(other).cloned().collect()
        }
    };
    generated
        .into_iter()
        .map(|s| BenchSegment {
            seed: crate::batch::segment_seed(seed, &s.id),
            material: s.material,
            data: s.segment_data(),
            id: s.id,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plastic_heavy_network_is_mostly_plastic() {
        let net = bench_network(20, 3, MaterialMix::PlasticHeavy);
        assert_eq!(net.len(), 20);
        let plastic = net.iter().filter(|s| s.material.is_plastic()).count();
        assert_eq!(plastic, 16);
        let default = bench_network(20, 3, MaterialMix::Default);
        assert!(default.iter().filter(|s| s.material.is_plastic()).count() < 16);
        assert!(default.iter().all(|s| s.data.measurements.len() >= 4));
    }
}
