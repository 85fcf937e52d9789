//! Welch auto- and cross-spectra of several channels (Hann window, 50 % overlap), with the
//! statistics the error estimates need: the effective number of independent averages and the
//! correlation of neighbouring frequency bins.

use num_complex::Complex64;
use realfft::RealFftPlanner;

/// Largest bin offset whose correlation [`Spectra::bin_correlation`] keeps: a Hann window's
/// squared values have Fourier components at offsets 0, 1 and 2 only, so bins 3 or more apart
/// are uncorrelated.
pub const MAX_CORRELATED_BIN_OFFSET: usize = 2;

/// The spectral matrix G_ij(f) = E[X_i* X_j] of a set of channels, by Welch's method.
#[derive(Debug, Clone)]
pub struct Spectra {
    /// Sample rate, Hz.
    pub sample_rate: f64,
    /// Segment length (FFT size), samples.
    pub nfft: usize,
    /// Number of averaged segments.
    pub segments: usize,
    /// Effective number of independent averages n_d of eq. P75 (fewer than the segments: the
    /// overlapping segments are correlated).
    pub n_eff: f64,
    /// |ρ_w(m)|², the correlation of spectral estimates m bins apart, m = 0..=2.
    pub bin_correlation: [f64; MAX_CORRELATED_BIN_OFFSET + 1],
    m: usize,
    /// Upper triangle i ≤ j, packed, each a vector over bins.
    g: Vec<Vec<Complex64>>,
}

impl Spectra {
    /// Number of one-sided frequency bins (0 … Nyquist).
    pub fn bins(&self) -> usize {
        self.nfft / 2 + 1
    }

    /// Frequency spacing, Hz.
    pub fn bin_hz(&self) -> f64 {
        self.sample_rate / self.nfft as f64
    }

    /// Number of channels.
    pub fn channels(&self) -> usize {
        self.m
    }

    fn index(&self, i: usize, j: usize) -> usize {
        // Row-major upper triangle.
        i * self.m - i * (i + 1) / 2 + j
    }

    /// G_ij at bin k (G_ji = conj G_ij).
    pub fn g(&self, i: usize, j: usize, k: usize) -> Complex64 {
        if i <= j {
            self.g[self.index(i, j)][k]
        } else {
            self.g[self.index(j, i)][k].conj()
        }
    }

    /// Ordinary coherence γ²_ij = |G_ij|² / (G_ii G_jj) at bin k; 0 where a channel is silent.
    pub fn coherence(&self, i: usize, j: usize, k: usize) -> f64 {
        let d = self.g(i, i, k).re * self.g(j, j, k).re;
        if d > 0.0 {
            (self.g(i, j, k).norm_sqr() / d).min(1.0)
        } else {
            0.0
        }
    }
}

/// The periodic Hann window of length n.
pub fn hann(n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| 0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / n as f64).cos())
        .collect()
}

/// Welch spectra of equally long channels, segments of `nfft` samples overlapping by half.
/// `None` when the channels hold fewer than two segments. `progress` is called with the frames
/// consumed.
pub fn welch(
    channels: &[&[f64]],
    sample_rate: f64,
    nfft: usize,
    progress: &dyn Fn(u64),
) -> Option<Spectra> {
    let m = channels.len();
    let n = channels.iter().map(|c| c.len()).min()?;
    let hop = nfft / 2;
    if nfft < 4 || n < nfft + hop {
        return None;
    }
    let segments = (n - nfft) / hop + 1;
    let w = hann(nfft);
    let bins = nfft / 2 + 1;
    let mut planner = RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(nfft);
    let mut input = fft.make_input_vec();
    let mut scratch = fft.make_scratch_vec();
    let mut x: Vec<Vec<Complex64>> = vec![fft.make_output_vec(); m];
    let mut g: Vec<Vec<Complex64>> = vec![vec![Complex64::new(0.0, 0.0); bins]; m * (m + 1) / 2];
    for s in 0..segments {
        let start = s * hop;
        for (c, ch) in channels.iter().enumerate() {
            let seg = &ch[start..start + nfft];
            // Remove the segment's mean so a DC offset of the recorder does not leak into the
            // lowest bins through the window's side lobes.
            let mean = seg.iter().sum::<f64>() / nfft as f64;
            for ((o, &v), &wv) in input.iter_mut().zip(seg).zip(&w) {
                *o = (v - mean) * wv;
            }
            fft.process_with_scratch(&mut input, &mut x[c], &mut scratch)
                .expect("buffers sized by the planner");
        }
        let mut idx = 0;
        for i in 0..m {
            for j in i..m {
                let gij = &mut g[idx];
                for k in 0..bins {
                    gij[k] += x[i][k].conj() * x[j][k];
                }
                idx += 1;
            }
        }
        progress(hop as u64);
    }
    let norm = 1.0 / segments as f64;
    for v in &mut g {
        for z in v.iter_mut() {
            *z *= norm;
        }
    }
    // Welch (1967): overlapping segments are correlated through the window; the variance of the
    // average is that of n_eff independent ones.
    let w2: f64 = w.iter().map(|v| v * v).sum();
    let c_overlap: f64 = (0..nfft - hop).map(|i| w[i] * w[i + hop]).sum::<f64>() / w2;
    let k = segments as f64;
    let n_eff = k / (1.0 + 2.0 * (1.0 - 1.0 / k) * c_overlap * c_overlap);
    // Neighbouring bins: the DFT of w² at offset m over its sum.
    let mut bin_correlation = [0.0; MAX_CORRELATED_BIN_OFFSET + 1];
    for (mm, r) in bin_correlation.iter_mut().enumerate() {
        let z: Complex64 = w
            .iter()
            .enumerate()
            .map(|(i, v)| {
                Complex64::from_polar(
                    v * v,
                    -std::f64::consts::TAU * (mm * i) as f64 / nfft as f64,
                )
            })
            .sum();
        *r = (z / w2).norm_sqr();
    }
    Some(Spectra {
        sample_rate,
        nfft,
        segments,
        n_eff,
        bin_correlation,
        m,
        g,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hann_statistics_are_the_textbook_values() {
        let x: Vec<f64> = (0..4000).map(|i| ((i * 7919) % 101) as f64).collect();
        let s = welch(&[&x, &x], 1000.0, 200, &|_| {}).unwrap();
        // Hann: |ρ(1)|² = (2/3)², |ρ(2)|² = (1/6)²; 50 % overlap correlation 1/6.
        assert!((s.bin_correlation[0] - 1.0).abs() < 1e-12);
        assert!((s.bin_correlation[1] - 4.0 / 9.0).abs() < 1e-12);
        assert!((s.bin_correlation[2] - 1.0 / 36.0).abs() < 1e-12);
        let k = s.segments as f64;
        assert!((s.n_eff - k / (1.0 + 2.0 * (1.0 - 1.0 / k) / 36.0)).abs() < 1e-9);
        // A channel with itself is fully coherent.
        assert!((s.coherence(0, 1, 10) - 1.0).abs() < 1e-12);
        assert_eq!(s.g(1, 0, 10), s.g(0, 1, 10).conj());
    }
}
