//! `host-sim export sumo`: every shipped scenario exports to SUMO plain XML that carries
//! its network (a connection per route of every junction, lanes counted from the right),
//! its vehicles and its arrivals; where SUMO is installed (a benchmark dependency:
//! `bench/sumo/.venv`, `$SUMO_HOME/bin` or the PATH), every export round-trips through
//! netconvert into a network with the same edges, lane counts, lengths and connections,
//! and SUMO runs it. Without SUMO the round trip says so, loudly, and is not run.

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A fresh directory under the target directory.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

/// `host-sim export sumo FILE DIR ARGS`: its exit code and stderr.
fn export(file: &Path, dir: &Path, args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .args(["export", "sumo"])
        .arg(file)
        .arg(dir)
        .args(args)
        .output()
        .expect("host-sim runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn read(dir: &Path, file: &str) -> String {
    std::fs::read_to_string(dir.join(file)).unwrap_or_else(|e| panic!("{file}: {e}"))
}

/// The shipped scenarios.
fn scenarios() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root().join("scenarios"))
        .expect("scenarios/")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    v.sort();
    v
}

/// Lines of `text` that hold `tag`.
fn count(text: &str, tag: &str) -> usize {
    text.lines().filter(|l| l.contains(tag)).count()
}

#[test]
fn the_intersection_exports_with_a_connection_per_route_and_its_vehicles() {
    let dir = scratch("sumo-intersection");
    let file = root().join("scenarios/intersection.toml");
    let (code, err) = export(&file, &dir, &["--control", "allway-stop"]);
    assert_eq!(code, Some(0), "{err}");
    let nodes = read(&dir, "intersection.nod.xml");
    assert!(nodes.contains(r#"<node id="J0" x="0.000" y="0.000" type="allway_stop" shape="-12.000,-12.000 12.000,-12.000 12.000,12.000 -12.000,12.000"/>"#), "{nodes}");
    // 4 inlet and 4 outlet stubs, 100 m and 60 m beyond A_S.
    assert!(nodes.contains(r#"<node id="J0_in0_a" x="-112.000" y="0.000"/>"#));
    assert!(nodes.contains(r#"<node id="J0_out1_b" x="0.000" y="72.000"/>"#));
    assert_eq!(count(&read(&dir, "intersection.edg.xml"), "<edge "), 8);
    // SPEC §8: 4 routes per heading (inner straight and left, outer straight and right).
    let con = read(&dir, "intersection.con.xml");
    assert_eq!(count(&con, "<connection "), 16);
    // The inner lane (ours 0, SUMO's 1 of 2) turns left from east-bound into north-bound.
    assert!(
        con.contains(r#"from="J0_in0" to="J0_out1" fromLane="1""#),
        "{con}"
    );
    // The outer lane (SUMO's 0) turns right into south-bound.
    assert!(
        con.contains(r#"from="J0_in0" to="J0_out3" fromLane="0""#),
        "{con}"
    );
    assert!(!con.contains(r#"from="J0_in0" to="J0_out1" fromLane="0""#));
    let routes = read(&dir, "intersection.rou.xml");
    assert_eq!(count(&routes, "<vehicle "), 8);
    // Vehicle 1: east-bound, inner lane, straight, its centre 13.4 m along the inlet.
    assert!(routes.contains(r#"<vehicle id="v1" type="car" depart="0" departLane="1" departPos="15.650" departSpeed="13.900"><route edges="J0_in0 J0_out0"/></vehicle>"#), "{routes}");
    assert!(routes.contains(r#"length="4.5""#) && routes.contains(r#"decel="7.9""#));
}

/// Trucks export as SUMO's own vehicle type, with their length and braking limit, and
/// depart with their front where host-sim has it.
#[test]
fn trucks_export_as_their_own_vehicle_type() {
    let dir = scratch("sumo-trucks");
    let (code, err) = export(&root().join("scenarios/trucks.toml"), &dir, &[]);
    assert_eq!(code, Some(0), "{err}");
    let routes = read(&dir, "trucks.rou.xml");
    assert!(routes.contains(r#"<vType id="truck" length="16.5" width="1.7" accel="3.8" decel="4.5" emergencyDecel="4.5""#), "{routes}");
    assert!(
        routes.contains(r#"<vType id="car" length="4.5""#),
        "{routes}"
    );
    // Truck 1 at x = 0 in lane 0: its front at 8.25 m, never before its own length.
    assert!(
        routes.contains(
            r#"<vehicle id="v1" type="truck" depart="0" departLane="0" departPos="16.500""#
        ),
        "{routes}"
    );
    assert!(
        routes.contains(r#"<vehicle id="v3" type="car""#),
        "{routes}"
    );
    assert_eq!(count(&routes, r#"type="truck""#), 2);
    // Arrivals with a share of trucks: beside each cars' flow a trucks' flow, the rate
    // split as the share says (trucks-grid: 20 %).
    let dir = scratch("sumo-trucks-grid");
    let (code, err) = export(&root().join("scenarios/trucks-grid.toml"), &dir, &[]);
    assert_eq!(code, Some(0), "{err}");
    let routes = read(&dir, "trucks-grid.rou.xml");
    assert!(
        routes.contains(r#"<vType id="truck" length="16.5""#),
        "{routes}"
    );
    let (cars, trucks) = (
        count(&routes, r#"type="car""#),
        count(&routes, r#"type="truck""#),
    );
    assert!(
        cars > 0 && cars == trucks,
        "{cars} car flows, {trucks} truck flows"
    );
    let period = |line: &str| -> f64 {
        let start = line.find("period=\"exp(").expect("a Poisson flow") + 12;
        line[start..]
            .split(')')
            .next()
            .expect("closed")
            .parse()
            .expect("a rate")
    };
    let first = |suffix: &str| {
        routes
            .lines()
            .find(|l| l.contains(&format!(r#"<flow id="f0_0{suffix}""#)))
            .map(period)
            .expect("flow f0_0")
    };
    let (car, truck) = (first(""), first("t"));
    // (The rates are written to six decimals.)
    assert!((truck / (car + truck) - 0.2).abs() < 1e-3, "{car} {truck}");
}

#[test]
fn a_grid_exports_its_arrivals_as_poisson_flows_on_shortest_paths() {
    let dir = scratch("sumo-grid");
    let (code, err) = export(&root().join("scenarios/grid-3x3.toml"), &dir, &[]);
    assert_eq!(code, Some(0), "{err}");
    let nodes = read(&dir, "grid-3x3.nod.xml");
    assert_eq!(count(&nodes, r#"tlType="actuated""#), 9);
    let routes = read(&dir, "grid-3x3.rou.xml");
    let flows = count(&routes, "<flow ");
    assert!(flows > 12, "{flows} flows");
    assert!(routes.contains(r#"period="exp("#));
    // Every flow's route starts on a boundary segment and ends on an exit.
    let edges = read(&dir, "grid-3x3.edg.xml");
    for line in routes.lines().filter(|l| l.contains("<flow ")) {
        let route = line
            .split("edges=\"")
            .nth(1)
            .and_then(|r| r.split('"').next());
        let route: Vec<&str> = route.expect("a route").split(' ').collect();
        let first = format!(r#"<edge id="{}" from="{}_a""#, route[0], route[0]);
        assert!(edges.contains(&first), "{line}");
        let last = route.last().expect("an edge");
        assert!(edges.contains(&format!(r#"to="{last}_b""#)), "{line}");
    }
}

#[test]
fn bad_input_is_refused_and_changes_nothing() {
    let dir = scratch("sumo-refused");
    std::fs::write(dir.join("intersection.nod.xml"), "kept").expect("write");
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "name = \"x\"\n[road]\nlanes = 0\n").expect("write");
    let (code, err) = export(&bad, &dir, &[]);
    assert_eq!(code, Some(2), "{err}");
    let file = root().join("scenarios/intersection.toml");
    let (code, err) = export(&file, &dir.join("intersection.nod.xml"), &[]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("not a directory"), "{err}");
    assert_eq!(read(&dir, "intersection.nod.xml"), "kept");
}

/// SUMO's `tool`, if installed where the benchmark puts it, under `$SUMO_HOME` or on
/// the PATH.
fn sumo_tool(tool: &str) -> Option<PathBuf> {
    let mut places = vec![root().join("bench/sumo/.venv/bin")];
    if let Some(home) = std::env::var_os("SUMO_HOME") {
        places.push(PathBuf::from(home).join("bin"));
    }
    if let Some(path) = std::env::var_os("PATH") {
        places.extend(std::env::split_paths(&path));
    }
    places
        .into_iter()
        .map(|p| p.join(tool))
        .find(|p| p.is_file())
}

/// Says, past the test harness's capture and in the test script's log, that the round
/// trip was not run.
fn not_run(why: &str) {
    use std::io::Write;
    let line = format!("NOT RUN host-sim SUMO round trip (export → netconvert → sumo): {why}");
    let _ = writeln!(std::io::stderr(), "{line}");
    if let Ok(log) = std::env::var("TESTS_SKIP_LOG") {
        if let Ok(mut f) = std::fs::OpenOptions::new()
            .append(true)
            .create(true)
            .open(log)
        {
            let _ = writeln!(f, "{line}");
        }
    }
}

/// Attribute `name` of every line of `text` holding `tag`, as (id, value).
fn attrs(text: &str, tag: &str, name: &str) -> Vec<(String, String)> {
    let get = |l: &str, a: &str| {
        l.split(&format!(" {a}=\""))
            .nth(1)
            .and_then(|r| r.split('"').next())
            .map(str::to_owned)
    };
    text.lines()
        .filter(|l| l.trim_start().starts_with(tag))
        .filter_map(|l| Some((get(l, "id")?, get(l, name)?)))
        .collect()
}

#[test]
fn every_shipped_scenario_round_trips_through_netconvert_and_runs_in_sumo() {
    let (Some(netconvert), Some(sumo)) = (sumo_tool("netconvert"), sumo_tool("sumo")) else {
        not_run("SUMO is not installed (python3 bench/sumo/lane_capacity.py installs it into bench/sumo/.venv)");
        return;
    };
    for file in scenarios() {
        let name = file
            .file_stem()
            .expect("a stem")
            .to_string_lossy()
            .into_owned();
        let dir = scratch(&format!("sumo-rt-{name}"));
        let (code, err) = export(&file, &dir, &[]);
        assert_eq!(code, Some(0), "{name}: {err}");
        let built = Command::new(&netconvert)
            .arg("-c")
            .arg(format!("{name}.netccfg"))
            .current_dir(&dir)
            .output()
            .expect("netconvert runs");
        let said = String::from_utf8_lossy(&built.stderr);
        assert!(built.status.success(), "{name}: {said}");
        assert!(
            !said.contains("Warning"),
            "{name}: netconvert warned: {said}"
        );
        let net = read(&dir, &format!("{name}.net.xml"));
        // Every edge we wrote is in the network with its lanes.
        let ours = attrs(
            &read(&dir, &format!("{name}.edg.xml")),
            "<edge ",
            "numLanes",
        );
        let theirs = attrs(&net, "<edge ", "from");
        for (id, lanes) in &ours {
            assert!(
                theirs.iter().any(|(e, _)| e == id),
                "{name}: edge {id} missing"
            );
            let n: usize = lanes.parse().expect("a lane count");
            for l in 0..n {
                assert!(
                    net.contains(&format!(r#"<lane id="{id}_{l}""#)),
                    "{name}: {id}_{l}"
                );
            }
        }
        // Every connection we wrote, lane to lane.
        for line in read(&dir, &format!("{name}.con.xml"))
            .lines()
            .filter(|l| l.contains("<connection "))
        {
            let key = line.trim().trim_end_matches("/>").trim_end();
            assert!(net.contains(key), "{name}: {key} missing from the network");
        }
        let ran = Command::new(&sumo)
            .args([
                "-c",
                &format!("{name}.sumocfg"),
                "--no-step-log",
                "--end",
                "30",
            ])
            .current_dir(&dir)
            .output()
            .expect("sumo runs");
        let said = String::from_utf8_lossy(&ran.stderr);
        assert!(ran.status.success(), "{name}: {said}");
        assert!(!said.contains("Error"), "{name}: {said}");
    }
}
