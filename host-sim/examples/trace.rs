//! Prints our solver's iterations on one instance:
//! `cargo run --release -p host-sim --example trace -- f32|f64 v_prev gap wx wv wd target v_ref`
use host_sim::reference::instances::InstanceSpec;
use planner_core::{IpmSolver, Real};

fn run<F: Real>(spec: &InstanceSpec) {
    let pr = spec.build::<F, 50>().expect("feasible instance");
    let r = IpmSolver::<F, 50>::default().solve_traced(&pr, None, &mut |i| {
        println!(
            "{:2} J={:.8e} rp={:.2e} rd={:.2e} mu={:.2e} step={:.3}",
            i.iteration,
            i.objective.to_f64(),
            i.primal_residual.to_f64(),
            i.dual_residual.to_f64(),
            i.mu.to_f64(),
            i.step.to_f64()
        )
    });
    println!("{:?}", r.map(|s| s.iterations));
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let a: Vec<f64> = args[1..]
        .iter()
        .map(|x| x.parse().expect("number"))
        .collect();
    let spec = InstanceSpec {
        v_prev: a[0],
        gap: a[1],
        weights: [a[2], a[3], a[4]],
        target: a[5],
        v_ref: a[6],
    };
    if args[0] == "f32" {
        run::<f32>(&spec)
    } else {
        run::<f64>(&spec)
    }
}
