//! Approach to a stopped car in f32 and f64, printing each change of planner status:
//! `cargo run --release -p host-sim --example approach`
use planner_core::{CostWeights, Observation, Params, Planner, Real, StepStatus, Vehicle};
fn run<F: Real>() {
    let params = Params::<F>::table_i();
    let mut planner = Planner::<F, 20>::new(params, CostWeights::default()).expect("weights");
    let leader = [Vehicle::wall(F::from_f64(60.0), F::from_f64(4.5))];
    let (mut x, mut v) = (F::ZERO, F::from_f64(15.0));
    let mut last = String::new();
    for step in 0..1000u32 {
        let obs = Observation {
            x,
            v_prev: v,
            vehicles: &leader,
            stop_line: None,
            target_x: F::ZERO,
            v_ref: params.v_max(),
        };
        let cmd = planner.step(&obs).expect("valid input");
        let s = match cmd.status {
            StepStatus::Solved { .. } => "solved".to_string(),
            StepStatus::Reused { .. } => "reused".to_string(),
            StepStatus::Fallback(r) => format!("{r:?}"),
            other => format!("{other:?}"),
        };
        let s: String = s.chars().take(60).collect();
        if s != last {
            println!("step {step}: x={:?} v={:?} gap={:?} {s}", x, v, cmd.gap);
            last = s;
        }
        v = cmd.v;
        x += v * params.h();
    }
}
fn main() {
    run::<f32>();
    println!("--- f64");
    run::<f64>();
}
