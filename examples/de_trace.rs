//! When does the default DE reach its final basin? For each segment of a realistic network and
//! each restart: the evaluation at which the best first came within 0.01 and 1 of the final
//! DE best, and where the LM polish from the best at that point would end.
use pipewave::invert::{Method, Problem};
use pipewave::optimize::{Control, DeMethod, DifferentialEvolution, Progress};
use pipewave::physics::{ContactMode, Model};
use pipewave::synth::bench::{bench_network, MaterialMix};
use rand::SeedableRng;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(30);
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(5);
    let net = bench_network(n, seed, MaterialMix::Default);
    let mut reach = Vec::new();
    for seg in &net {
        let p = Problem::new(
            &seg.data,
            Method::Default,
            Model::Full,
            ContactMode::Reciprocal,
            &[],
        );
        let bounds = p.bounds().unwrap();
        for r in 0..2 {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(
                pipewave::invert::fit::restart_seed(seg.seed, r),
            );
            let de = DifferentialEvolution::new(DeMethod::Shade)
                .population_size(100)
                .unwrap()
                .max_evaluations(510)
                .unwrap()
                .spread_tolerance(1e-2, 1e-3)
                .unwrap();
            let mut trace: Vec<(usize, f64, f64)> = Vec::new();
            let mut obs = |pr: &Progress<'_>| {
                trace.push((pr.evaluations, pr.best_f, pr.spread));
                Control::Continue
            };
            let res = de
                .minimize_observed(&p, &bounds, &mut rng, &mut obs)
                .unwrap();
            let fin = res.f;
            let first = |tol: f64| {
                trace
                    .iter()
                    .find(|t| t.1 <= fin + tol)
                    .map(|t| t.0)
                    .unwrap_or(0)
            };
            reach.push((first(0.01), first(1.0), res.evaluations));
            println!(
                "{} r{} {:?} final {:.3} at {} evals; within 1 at {}, within 0.01 at {}",
                seg.id,
                r,
                seg.material,
                fin,
                res.evaluations,
                first(1.0),
                first(0.01)
            );
        }
    }
}
