//! The misfit of one segment of a realistic synthetic network over a grid of the soil's speed
//! coordinates at a fixed contact: c_P down the rows, r = c_S/c_P across the columns, χ² (the
//! default method's, as the search rates it) in the cells, NaN where (c_P, r) gives no soil of
//! the search box's Poisson range or no root. To see where a fit's valley runs, and how narrow
//! it is.
//!
//! misfit_scan MIX SEED ID XI CP_FROM CP_TO CP_FACTOR R,R,…
//!
//! e.g. `misfit_scan default 995021 WM10192 0.005 380 560 1.01 0.707,0.6,0.55,0.5`: the
//! segment WM10192 of the 200-segment network of seed 995021, at ξ = 0.005, c_P from 380 m/s
//! by factors of 1.01 below 560 m/s.

use pipewave::invert::{FitSettings, Param, Problem};
use pipewave::optimize::Objective;
use pipewave::physics::soil::soil_of;
use pipewave::synth::bench::{bench_network, MaterialMix};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let usage = "misfit_scan MIX SEED ID XI CP_FROM CP_TO CP_FACTOR R,R,…";
    let arg = |i: usize| args.get(i).map(String::as_str).unwrap_or("");
    let num = |i: usize, name: &str| -> Result<f64, String> {
        arg(i).parse().map_err(|e| format!("{name}: {e}"))
    };
    let parsed = (|| -> Result<_, String> {
        let mix: MaterialMix = arg(1).parse()?;
        let seed: u64 = arg(2).parse().map_err(|e| format!("SEED: {e}"))?;
        let rs = arg(8)
            .split(',')
            .map(|r| r.parse::<f64>().map_err(|e| format!("R: {e}")))
            .collect::<Result<Vec<_>, _>>()?;
        let (from, to, factor) = (num(5, "CP_FROM")?, num(6, "CP_TO")?, num(7, "CP_FACTOR")?);
        if !(from > 0.0 && factor > 1.0) {
            return Err("CP_FROM must be > 0 and CP_FACTOR > 1".into());
        }
        Ok((
            mix,
            seed,
            arg(3).to_string(),
            num(4, "XI")?,
            from,
            to,
            factor,
            rs,
        ))
    })();
    let (mix, seed, id, xi, from, to, factor, rs) = match parsed {
        Ok(p) => p,
        Err(e) => {
            eprintln!("{e}\nusage: {usage}");
            std::process::exit(2);
        }
    };
    let net = bench_network(200, seed, mix);
    let Some(seg) = net.iter().find(|s| s.id == id) else {
        eprintln!("no segment {id} in the network of seed {seed}");
        std::process::exit(2);
    };
    let s = FitSettings::default();
    let problem = Problem::new(&seg.data, s.method, s.model, s.contact_mode, &s.effects);
    let index = |p: Param| problem.specs.iter().position(|s| s.param == p);
    let (Some(je), Some(jn), Some(jx)) = (
        index(Param::SoilModulus),
        index(Param::SoilPoisson),
        index(Param::Contact),
    ) else {
        eprintln!("the default problem fits E_m, ν_m and ξ");
        std::process::exit(2);
    };
    let (nu_lo, nu_hi) = (problem.specs[jn].lower, problem.specs[jn].upper);
    print!("{:>8}", "c_P");
    for r in &rs {
        print!(" {:>9}", format!("r={r}"));
    }
    println!();
    let mut cp = from;
    while cp < to {
        print!("{cp:8.1}");
        for &r in &rs {
            let chi2 = soil_of(cp.ln(), r, seg.data.soil_density)
                .filter(|&(_, nu)| (nu_lo..=nu_hi).contains(&nu))
                .map_or(f64::NAN, |(e, nu)| {
                    let mut x = vec![0.0; problem.specs.len()];
                    x[je] = problem.specs[je].coordinate(e);
                    (x[jn], x[jx]) = (nu, xi);
                    problem.value(&x)
                });
            print!(" {chi2:9.2}");
        }
        println!();
        cp *= factor;
    }
}
