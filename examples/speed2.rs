use num_complex::Complex64;
use pipewave::bench::time_per_call;
use std::hint::black_box;
fn main() {
    for z in [0.5, 1.13, 2.27, 5.0, 20.0] {
        let t = time_per_call(7, 4000, |i| {
            black_box(
                pipewave::special::hankel_ratio(black_box(Complex64::new(
                    z + 1e-9 * i as f64,
                    -0.001,
                )))
                .ok(),
            );
        });
        println!("hankel at {z}: {t:.3} us");
    }
    let sys = pipewave::bench::case_a();
    let ev = pipewave::physics::Evaluator::new(&sys, 3121.958);
    let t = time_per_call(7, 4000, |i| {
        black_box(
            ev.stiffness(black_box(Complex64::new(2.48 + 1e-9 * i as f64, -0.006)))
                .ok(),
        );
    });
    println!("stiffness {t:.3}");
    let t = time_per_call(7, 4000, |i| {
        black_box(
            ev.psi(black_box(Complex64::new(2.48 + 1e-9 * i as f64, -0.006)))
                .ok(),
        );
    });
    println!("psi {t:.3}");
}
