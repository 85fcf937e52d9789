//! The thin HDPE pipe of issue 11: where does the continuation lose the s = 1 root?
use pipewave::physics::effects::Effect;
use pipewave::physics::solver::{solve_curve, Continuation, Tolerance};
use pipewave::physics::{ContactMode, Fluid, Material, Model, Pipe, Soil, System};

fn main() {
    if std::env::var_os("AMOS").is_some() {
        return pipewave::special::with_amos_only(run);
    }
    run()
}

fn run() {
    let pipe = Pipe::from_outside_diameter(Material::Hdpe.typical(), 0.090, 0.0054).unwrap();
    let soil = Soil::new(1.8e7, 0.32, 1930.0, 0.0).unwrap();
    let sys = System::new(
        Fluid::water(),
        pipe,
        soil,
        0.30,
        Model::Full,
        ContactMode::Reciprocal,
    )
    .unwrap();
    let sys = Effect::WallThinning.apply(&sys, 0.62).unwrap();
    let (cp, cs) = sys.soil.wave_speeds();
    println!("cp {cp:.1} cs {cs:.1}");
    let f: Vec<f64> = [136.0, 200.0, 300.0, 400.0, 500.0, 600.0, 717.0].to_vec();
    let w: Vec<f64> = f.iter().map(|f| f * std::f64::consts::TAU).collect();
    for (name, opts) in [
        ("reference", Continuation::default()),
        (
            "fast",
            Continuation {
                ramp_points: 0,
                tolerance: Tolerance::FAST,
            },
        ),
        (
            "ramp8",
            Continuation {
                ramp_points: 8,
                tolerance: Tolerance::FAST,
            },
        ),
    ] {
        println!("{name}");
        for (fi, r) in f.iter().zip(solve_curve(&sys, &w, opts)) {
            match r {
                Ok(r) => println!(
                    "  {fi} Hz k1 = {:.6} c = {:.2} flags {}",
                    r.k1,
                    r.phase_speed(),
                    r.flags
                ),
                Err(e) => println!("  {fi} Hz {e}"),
            }
        }
    }
    // Scan the reference ramp at fine steps.
    let fine: Vec<f64> = (1..=400)
        .map(|i| i as f64 * 2.0 * std::f64::consts::TAU)
        .collect();
    let res = solve_curve(&sys, &fine, Continuation::default());
    let mut last = None;
    for (w, r) in fine.iter().zip(&res) {
        match r {
            Ok(r) => last = Some((*w, r.k1, r.phase_speed())),
            Err(e) => {
                println!(
                    "fine scan fails at {:.0} Hz: {e}; last ok {:?}",
                    w / std::f64::consts::TAU,
                    last
                );
                break;
            }
        }
    }
}
