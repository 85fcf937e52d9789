//! Global-optimum rate and cost of the default fit on the bench's three cases for a given
//! budget: budget_scan EVALS_PER_DIM RESTARTS SEEDS
use pipewave::bench::{paper_case_data, synthetic_iron_data, synthetic_mdpe_data, thread_cpu_ms};
use pipewave::invert::{fit_segment, FitSettings};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let epd: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(170);
    let restarts: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(2);
    let seeds: u64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(100);
    let settings = FitSettings {
        restarts,
        evaluations_per_dimension: epd,
        ..FitSettings::default()
    };
    for (name, data) in [
        ("paper", paper_case_data()),
        ("iron", synthetic_iron_data()),
        ("mdpe", synthetic_mdpe_data()),
    ] {
        let long = FitSettings {
            restarts: 4,
            evaluations_per_dimension: 3000,
            ..FitSettings::default()
        };
        let best = fit_segment(&data, &long, 12345).misfit;
        let t = thread_cpu_ms();
        let mut ms: Vec<f64> = Vec::new();
        let mut worst: f64 = 0.0;
        let mut global = 0;
        let mut stat = 0;
        for s in 0..seeds {
            let r = fit_segment(&data, &settings, s);
            ms.push(r.misfit);
            worst = worst.max(r.misfit - best);
            if r.misfit <= best * (1.0 + 1e-6) {
                global += 1;
            }
            if r.misfit <= best + 1.0 && r.misfit <= best * 1.01 || r.misfit <= best * (1.0 + 1e-6)
            {
                stat += 1;
            }
        }
        println!("{name}: {global}/{seeds} global (1e-6), {stat}/{seeds} loose, worst excess {worst:.3e}, best {best:.6e}, {:.1} ms/fit", (thread_cpu_ms() - t) / seeds as f64);
    }
}
