//! `Settings::with_scaled_cold_start`: a cold start whose multipliers are of the cost
//! gradient's size finds the same optimum as one at unit multipliers, in fewer
//! interior-point iterations where the gradient is large — a vehicle standing or slow
//! with its reference speed far above it, the start that made the firmware late in the
//! loop at N = 50.

use planner_core::{CostWeights, Params, Planner, Settings, StepStatus};

/// A fresh planner (its first step is a cold start), with the scaled start or not.
fn planner<const N: usize>(scaled: bool) -> Planner<f32, N> {
    let mut pl = Planner::new(Params::table_i(), CostWeights::default()).expect("table I");
    pl.set_solver_settings(Settings::default().with_scaled_cold_start(scaled));
    pl
}

/// (v_prev, gap ahead, v_ref) of cold starts: standing with room, standing with a stop
/// a few metres or centimetres ahead, slow, and at speed.
const CASES: [(f32, f32, f32); 8] = [
    (0.0, 100.0, 15.0),
    (0.0, 100.0, 27.8),
    (0.0, 8.0, 15.0),
    (0.0, 2.5, 15.0),
    (2.0, 40.0, 27.8),
    (5.0, 100.0, 15.0),
    (14.7, 60.0, 15.0),
    (20.0, 200.0, 27.8),
];

/// Iterations and first speed of each case's cold solve.
fn solves<const N: usize>(scaled: bool) -> Vec<(u32, f32)> {
    CASES
        .iter()
        .map(|&(v, gap, v_ref)| {
            let c = planner::<N>(scaled)
                .step_gap(v, gap, 0.0, v_ref)
                .expect("valid input");
            let StepStatus::Solved { iterations, .. } = c.status else {
                panic!("{v} m/s, gap {gap} m: {:?}", c.status);
            };
            (iterations, c.v)
        })
        .collect()
}

fn compare<const N: usize>() -> (u32, u32) {
    let (plain, scaled) = (solves::<N>(false), solves::<N>(true));
    for (((ip, vp), (is, vs)), case) in plain.iter().zip(&scaled).zip(CASES) {
        // The same optimum, to the solver's f32 tolerance.
        assert!(
            (vp - vs).abs() < 2e-3,
            "N = {N}, {case:?}: {vp} against {vs}"
        );
        println!("N = {N}, {case:?}: {ip} iterations unscaled, {is} scaled");
    }
    let total = |s: &[(u32, f32)]| s.iter().map(|x| x.0).sum::<u32>();
    (total(&plain), total(&scaled))
}

#[test]
fn the_scaled_cold_start_finds_the_same_optimum_in_fewer_iterations() {
    let (plain, scaled) = compare::<50>();
    println!("N = 50: {plain} iterations unscaled, {scaled} scaled");
    assert!(scaled < plain, "N = 50: {scaled} against {plain}");
    let (plain, scaled) = compare::<20>();
    println!("N = 20: {plain} iterations unscaled, {scaled} scaled");
    assert!(scaled <= plain, "N = 20: {scaled} against {plain}");
}

#[test]
fn it_is_off_by_default_and_kept_by_the_setter() {
    assert!(!Settings::<f32>::default().scaled_cold_start());
    assert!(Settings::<f32>::default()
        .with_scaled_cold_start(true)
        .scaled_cold_start());
    let pl = planner::<20>(true);
    assert!(pl.solver().settings().scaled_cold_start());
}
