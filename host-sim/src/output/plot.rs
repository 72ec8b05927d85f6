//! `--plot out.png|out.svg`: x–y trajectories with the vehicles' L × W rectangles at
//! snapshots (in the style of the paper's Fig. 7/8), and speed over time.

use crate::world::{TraceRow, LANE_WIDTH_M, LENGTH_M, WIDTH_M};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;

/// One sample of a vehicle: (t, x, y, theta, v).
pub type Sample = (f64, f64, f64, f64, f64);

/// What the plot needs, sampled from the trace.
#[derive(Debug, Default)]
pub struct PlotData {
    /// Per vehicle: (t, x, y, theta, v), sampled every `every_s`.
    pub series: BTreeMap<u16, Vec<Sample>>,
    /// Lanes on the road.
    pub lanes: u8,
    /// Road end, if any.
    pub end_x: Option<f64>,
    /// Only rows with t ≤ this are kept (all if `None`).
    pub until_s: Option<f64>,
    /// Per vehicle: its length (m), as its rows say (a truck is drawn as long as it is).
    pub lengths: BTreeMap<u16, f64>,
}

impl PlotData {
    /// An empty record for a world on `net` (a straight road's lanes and end).
    pub fn of(net: &crate::world::network::Network) -> Self {
        let road = net.segments.first().filter(|_| net.junctions.is_empty());
        Self {
            lanes: road.map_or(0, |s| s.lanes),
            end_x: road.and_then(|s| match s.end {
                crate::world::network::End::DeadEnd(x) => Some(x),
                _ => None,
            }),
            ..Self::default()
        }
    }

    /// Vehicle `id`'s length: as its rows said, Table I's if it has none.
    pub fn length_of(&self, id: u16) -> f64 {
        self.lengths.get(&id).copied().unwrap_or(LENGTH_M)
    }

    /// Samples a trace row (keeps one row every 0.1 s).
    pub fn add(&mut self, r: &TraceRow) {
        // Rows come every h = 0.01 s; t is a multiple of h.
        if ((r.t * 100.0).round() as i64) % 10 == 0 && self.until_s.is_none_or(|u| r.t <= u) {
            self.series
                .entry(r.id)
                .or_default()
                .push((r.t, r.x, r.y, r.theta, r.v));
            self.lengths.insert(r.id, r.length);
        }
    }
}

/// Plot errors.
#[derive(Debug)]
pub struct PlotError(pub String);

impl std::fmt::Display for PlotError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "plot: {}", self.0)
    }
}

impl std::error::Error for PlotError {}

fn e<E: std::fmt::Display>(x: E) -> PlotError {
    PlotError(x.to_string())
}

/// Registers the embedded DejaVu Sans font (so plots need no system fonts).
fn register_font() -> Result<(), PlotError> {
    plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
        .map_err(|_| PlotError("embedded font rejected".into()))
}

/// Draws with `$draw(&root)` on a PNG or SVG backend of `$size` chosen by the path's
/// extension, after registering the embedded font (both backends lay text out with it).
macro_rules! render {
    ($path:expr, $size:expr, |$root:ident| $draw:expr) => {{
        register_font()?;
        match $path.extension().and_then(|s| s.to_str()) {
            Some("png") => {
                let $root = BitMapBackend::new($path, $size).into_drawing_area();
                $draw?;
                $root.present().map_err(e)
            }
            Some("svg") => {
                let $root = SVGBackend::new($path, $size).into_drawing_area();
                $draw?;
                $root.present().map_err(e)
            }
            _ => Err(PlotError(format!(
                "{}: the plot file must end in .png or .svg",
                $path.display()
            ))),
        }
    }};
}

/// The figure of any world: a straight road's (trajectories and speeds), a single
/// junction's, or a network's.
pub fn any(
    data: &PlotData,
    net: &crate::world::network::Network,
    title: &str,
    path: &Path,
) -> Result<(), PlotError> {
    match (net.junctions.as_slice(), net.segments.is_empty()) {
        ([], _) => write(data, title, path),
        ([j], true) => crossing(data, &j.layout, title, path),
        _ => network(data, net, title, path),
    }
}

/// Writes the figure to `path` (PNG or SVG by extension).
pub fn write(data: &PlotData, title: &str, path: &Path) -> Result<(), PlotError> {
    render!(path, (1400, 900), |root| draw(data, title, &root))
}

fn palette(i: usize) -> RGBColor {
    const C: [RGBColor; 10] = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
        RGBColor(227, 119, 194),
        RGBColor(127, 127, 127),
        RGBColor(188, 189, 34),
        RGBColor(23, 190, 207),
    ];
    C[i % C.len()]
}

fn draw<DB: DrawingBackend>(
    data: &PlotData,
    title: &str,
    root: &DrawingArea<DB, Shift>,
) -> Result<(), PlotError>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(e)?;
    let root = root.titled(title, ("sans-serif", 28)).map_err(e)?;
    let (top, bottom) = root.split_vertically(480);
    let all = data.series.values().flatten();
    let (mut x0, mut x1, mut t1) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
    for &(t, x, _, _, _) in all {
        x0 = x0.min(x);
        x1 = x1.max(x);
        t1 = t1.max(t);
    }
    if !x0.is_finite() {
        return Err(PlotError("nothing to plot".into()));
    }
    if let Some(end) = data.end_x {
        x1 = x1.max(end + 5.0);
    }
    let road_w = f64::from(data.lanes.max(1)) * LANE_WIDTH_M;
    let mut xy = ChartBuilder::on(&top)
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .caption(
            "trajectories (rectangles: L × W at snapshots)",
            ("sans-serif", 20),
        )
        .build_cartesian_2d((x0 - 10.0)..(x1 + 10.0), -0.5..(road_w * 1.7 + 2.0))
        .map_err(e)?;
    xy.configure_mesh()
        .x_desc("x (m)")
        .y_desc("y (m)")
        .disable_mesh()
        .draw()
        .map_err(e)?;
    // Lane markings and the road end.
    for l in 0..=data.lanes {
        let y = f64::from(l) * LANE_WIDTH_M;
        xy.draw_series(LineSeries::new(
            [(x0 - 10.0, y), (x1 + 10.0, y)],
            BLACK.mix(0.4),
        ))
        .map_err(e)?;
    }
    if let Some(end) = data.end_x {
        xy.draw_series(LineSeries::new(
            [(end, 0.0), (end, road_w)],
            RED.stroke_width(3),
        ))
        .map_err(e)?;
    }
    let snapshots = 6.0;
    for (i, (id, s)) in data.series.iter().enumerate() {
        let c = palette(i);
        let length = data.length_of(*id);
        xy.draw_series(LineSeries::new(s.iter().map(|p| (p.1, p.2)), c.mix(0.6)))
            .map_err(e)?
            .label(format!("vehicle {id}"))
            .legend(move |(x, y)| Rectangle::new([(x, y - 4), (x + 16, y + 4)], c.filled()));
        for k in 0..=(snapshots as usize) {
            let t_snap = t1 * k as f64 / snapshots;
            if let Some(p) = s
                .iter()
                .min_by(|a, b| (a.0 - t_snap).abs().total_cmp(&(b.0 - t_snap).abs()))
            {
                let pts = footprint(p, length);
                xy.draw_series(std::iter::once(Polygon::new(pts.clone(), c.mix(0.35))))
                    .map_err(e)?;
                xy.draw_series(std::iter::once(PathElement::new(pts, c.stroke_width(1))))
                    .map_err(e)?;
            }
        }
    }
    if data.series.len() <= 12 {
        // Headroom above the road (see the y range) keeps the legend off the vehicles.
        xy.configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(e)?;
    }
    speed_panel(data, &bottom, t1, 30.0)
}

/// The closed outline of a vehicle's L × W rectangle at a sample's pose, `length` long.
fn footprint(p: &Sample, length: f64) -> Vec<(f64, f64)> {
    let (sn, cs) = p.3.sin_cos();
    let (hl, hw) = (0.5 * length, 0.5 * WIDTH_M);
    [(hl, hw), (hl, -hw), (-hl, -hw), (-hl, hw), (hl, hw)]
        .iter()
        .map(|&(u, w)| (p.1 + u * cs - w * sn, p.2 + u * sn + w * cs))
        .collect()
}

/// Speed over time, one line per vehicle, in the same colours as the trajectories.
fn speed_panel<DB: DrawingBackend>(
    data: &PlotData,
    area: &DrawingArea<DB, Shift>,
    t1: f64,
    v_top: f64,
) -> Result<(), PlotError>
where
    DB::ErrorType: 'static,
{
    let mut sv = ChartBuilder::on(area)
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .caption("speed", ("sans-serif", 20))
        .build_cartesian_2d(0.0..t1.max(1e-3), 0.0..v_top)
        .map_err(e)?;
    sv.configure_mesh()
        .x_desc("t (s)")
        .y_desc("v (m/s)")
        .draw()
        .map_err(e)?;
    for (i, s) in data.series.values().enumerate() {
        sv.draw_series(LineSeries::new(s.iter().map(|p| (p.0, p.4)), palette(i)))
            .map_err(e)?;
    }
    Ok(())
}

/// Fig. 9-style bars: vehicles crossed (mean ± std) and mean crossing time per algorithm.
pub fn bars(
    r: &crate::experiments::throughput::ThroughputReport,
    path: &Path,
) -> Result<(), PlotError> {
    render!(path, (1200, 520), |root| draw_bars(r, &root))
}

fn draw_bars<DB: DrawingBackend>(
    r: &crate::experiments::throughput::ThroughputReport,
    root: &DrawingArea<DB, Shift>,
) -> Result<(), PlotError>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(e)?;
    let title = format!(
        "intersection throughput, {} s, {} seeds (Fig. 9 style)",
        r.duration_s, r.seeds
    );
    let root = root.titled(&title, ("sans-serif", 24)).map_err(e)?;
    let (left, right) = root.split_horizontally(600);
    let n = r.results.len();
    let names: Vec<&str> = r.results.iter().map(|x| x.algorithm).collect();
    type Metric = Box<dyn Fn(&crate::experiments::throughput::ThroughputRow) -> (f64, f64)>;
    let panels: [(&DrawingArea<DB, Shift>, &str, Metric); 2] = [
        (
            &left,
            "vehicles crossed",
            Box::new(|x| (x.crossed_mean, x.crossed_std)),
        ),
        (
            &right,
            "mean crossing time (s)",
            Box::new(|x| (x.crossing_time_mean_s, 0.0)),
        ),
    ];
    for (area, caption, value) in panels {
        let top = r
            .results
            .iter()
            .map(|x| {
                let (v, s) = value(x);
                v + s
            })
            .fold(1.0, f64::max)
            * 1.15;
        let mut chart = ChartBuilder::on(area)
            .margin(20)
            .caption(caption, ("sans-serif", 20))
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..n as f64, 0.0..top)
            .map_err(e)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(2 * n + 1)
            .x_label_formatter(&|x| {
                // Ticks fall every half unit; name the ones at bar centres.
                if (x.fract() - 0.5).abs() < 0.01 {
                    names
                        .get(x.floor() as usize)
                        .copied()
                        .unwrap_or("")
                        .to_string()
                } else {
                    String::new()
                }
            })
            .draw()
            .map_err(e)?;
        for (i, row) in r.results.iter().enumerate() {
            let (v, s) = value(row);
            let x0 = i as f64 + 0.2;
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(x0, 0.0), (x0 + 0.6, v)],
                    palette(i).filled(),
                )))
                .map_err(e)?;
            if s > 0.0 {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(x0 + 0.3, v - s), (x0 + 0.3, v + s)],
                        BLACK.stroke_width(2),
                    )))
                    .map_err(e)?;
            }
            chart
                .draw_series(std::iter::once(Text::new(
                    format!("{v:.1}"),
                    (x0 + 0.1, v + top * 0.02),
                    ("sans-serif", 16),
                )))
                .map_err(e)?;
        }
    }
    Ok(())
}

/// An intersection run: trajectories over the layout (A_S red, A_C grey, Fig. 8 style)
/// with L × W rectangles at snapshots, and speeds.
pub fn crossing(
    data: &PlotData,
    layout: &planner_core::intersection::Layout<f64>,
    title: &str,
    path: &Path,
) -> Result<(), PlotError> {
    render!(path, (1500, 860), |root| draw_crossing(
        data, layout, title, &root
    ))
}

fn draw_crossing<DB: DrawingBackend>(
    data: &PlotData,
    layout: &planner_core::intersection::Layout<f64>,
    title: &str,
    root: &DrawingArea<DB, Shift>,
) -> Result<(), PlotError>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(e)?;
    let root = root.titled(title, ("sans-serif", 26)).map_err(e)?;
    let (left, right) = root.split_horizontally(820);
    let a = layout.spec.half_size;
    let c = a + layout.spec.comm_margin;
    let r = a + layout.spec.inlet_length.max(layout.spec.outlet_length) * 0.7;
    let mut xy = ChartBuilder::on(&left)
        .margin(15)
        .x_label_area_size(35)
        .y_label_area_size(45)
        .caption("trajectories: A_S (red), A_C (grey)", ("sans-serif", 18))
        .build_cartesian_2d(-r..r, -r..r)
        .map_err(e)?;
    xy.configure_mesh()
        .disable_mesh()
        .x_desc("x (m)")
        .y_desc("y (m)")
        .draw()
        .map_err(e)?;
    let square = |h: f64| vec![(-h, -h), (h, -h), (h, h), (-h, h), (-h, -h)];
    xy.draw_series(std::iter::once(PathElement::new(square(c), BLACK.mix(0.3))))
        .map_err(e)?;
    xy.draw_series(std::iter::once(PathElement::new(
        square(a),
        RED.stroke_width(2),
    )))
    .map_err(e)?;
    // Road edges: 4 lanes (2 in, 2 out) per road.
    let w = 2.0 * LANE_WIDTH_M;
    for (p, q) in [
        ((-r, -w), (-a, -w)),
        ((-r, w), (-a, w)),
        ((a, -w), (r, -w)),
        ((a, w), (r, w)),
        ((-w, -r), (-w, -a)),
        ((w, -r), (w, -a)),
        ((-w, a), (-w, r)),
        ((w, a), (w, r)),
    ] {
        xy.draw_series(LineSeries::new([p, q], BLACK.mix(0.5)))
            .map_err(e)?;
    }
    let t1 = data
        .series
        .values()
        .flatten()
        .map(|p| p.0)
        .fold(0.0, f64::max);
    for (i, (id, s)) in data.series.iter().enumerate() {
        let col = palette(i);
        let length = data.length_of(*id);
        xy.draw_series(LineSeries::new(s.iter().map(|p| (p.1, p.2)), col.mix(0.7)))
            .map_err(e)?
            .label(format!("vehicle {id}"))
            .legend(move |(x, y)| Rectangle::new([(x, y - 4), (x + 16, y + 4)], col.filled()));
        for p in s.iter().step_by(20) {
            let pts = footprint(p, length);
            xy.draw_series(std::iter::once(Polygon::new(pts.clone(), col.mix(0.3))))
                .map_err(e)?;
            xy.draw_series(std::iter::once(PathElement::new(pts, col)))
                .map_err(e)?;
        }
    }
    xy.configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(e)?;
    speed_panel(data, &right, t1, layout.spec.v_limit * 1.2)
}

/// A network's figure: its roads and intersections, every vehicle's path and its
/// rectangle at snapshots, and speeds over time.
pub fn network(
    data: &PlotData,
    net: &crate::world::network::Network,
    title: &str,
    path: &Path,
) -> Result<(), PlotError> {
    render!(path, (1600, 900), |root| draw_network(
        data, net, title, &root
    ))
}

/// The world rectangle a segment covers: (x0, y0, x1, y1).
fn segment_box(s: &crate::world::network::Segment) -> [(f64, f64); 5] {
    let len = s.end.x().unwrap_or(0.0);
    let w = f64::from(s.lanes) * LANE_WIDTH_M;
    let c = |x: f64, y: f64| {
        let p = s.to_world(x, y, 0.0);
        (p.x, p.y)
    };
    [c(0.0, 0.0), c(len, 0.0), c(len, w), c(0.0, w), c(0.0, 0.0)]
}

fn draw_network<DB: DrawingBackend>(
    data: &PlotData,
    net: &crate::world::network::Network,
    title: &str,
    root: &DrawingArea<DB, Shift>,
) -> Result<(), PlotError>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(e)?;
    let root = root.titled(title, ("sans-serif", 26)).map_err(e)?;
    let (left, right) = root.split_horizontally(900);
    let boxes: Vec<[(f64, f64); 5]> = net.segments.iter().map(segment_box).collect();
    let (x0, x1, y0, y1) = network_bounds(net, &boxes)?;
    // Equal scales: the longer side sets both.
    let span = (x1 - x0).max(y1 - y0) + 20.0;
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let mut xy = ChartBuilder::on(&left)
        .margin(15)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .caption(
            "network: roads, A_S (red), A_C (grey), paths",
            ("sans-serif", 18),
        )
        .build_cartesian_2d(
            (cx - span / 2.0)..(cx + span / 2.0),
            (cy - span / 2.0)..(cy + span / 2.0),
        )
        .map_err(e)?;
    xy.configure_mesh()
        .disable_mesh()
        .x_desc("x (m)")
        .y_desc("y (m)")
        .draw()
        .map_err(e)?;
    for b in &boxes {
        xy.draw_series(std::iter::once(Polygon::new(b.to_vec(), BLACK.mix(0.06))))
            .map_err(e)?;
        xy.draw_series(std::iter::once(PathElement::new(
            b.to_vec(),
            BLACK.mix(0.4),
        )))
        .map_err(e)?;
    }
    for j in &net.junctions {
        draw_junction(&mut xy, j)?;
    }
    let t1 = data
        .series
        .values()
        .flatten()
        .map(|p| p.0)
        .fold(0.0, f64::max);
    for (i, (id, s)) in data.series.iter().enumerate() {
        let col = palette(i);
        let length = data.length_of(*id);
        xy.draw_series(LineSeries::new(s.iter().map(|p| (p.1, p.2)), col.mix(0.6)))
            .map_err(e)?;
        for p in s.iter().step_by(50) {
            let pts = footprint(p, length);
            xy.draw_series(std::iter::once(Polygon::new(pts, col.mix(0.5))))
                .map_err(e)?;
        }
    }
    let vmax = net
        .junctions
        .iter()
        .map(|j| j.layout.spec.v_limit)
        .fold(0.0, f64::max);
    speed_panel(data, &right, t1, vmax * 1.2)
}

/// The extent (x0, x1, y0, y1) of a network's segment boxes and junctions' A_C.
fn network_bounds(
    net: &crate::world::network::Network,
    boxes: &[[(f64, f64); 5]],
) -> Result<(f64, f64, f64, f64), PlotError> {
    let mut b = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    let mut grow = |x: f64, y: f64| {
        b = (b.0.min(x), b.1.max(x), b.2.min(y), b.3.max(y));
    };
    for &(x, y) in boxes.iter().flatten() {
        grow(x, y);
    }
    for j in &net.junctions {
        let r = j.layout.spec.half_size + j.layout.spec.comm_margin;
        grow(j.centre.0 - r, j.centre.1 - r);
        grow(j.centre.0 + r, j.centre.1 + r);
    }
    if !b.0.is_finite() {
        return Err(PlotError("nothing to plot".into()));
    }
    Ok(b)
}

/// A chart with metres on both axes.
type XyChart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// A junction's A_C (grey) and A_S (red) squares.
fn draw_junction<DB: DrawingBackend>(
    xy: &mut XyChart<'_, DB>,
    j: &crate::world::network::Junction,
) -> Result<(), PlotError>
where
    DB::ErrorType: 'static,
{
    let sq = |h: f64| {
        vec![
            (j.centre.0 - h, j.centre.1 - h),
            (j.centre.0 + h, j.centre.1 - h),
            (j.centre.0 + h, j.centre.1 + h),
            (j.centre.0 - h, j.centre.1 + h),
            (j.centre.0 - h, j.centre.1 - h),
        ]
    };
    let a = j.layout.spec.half_size;
    let outer = PathElement::new(sq(a + j.layout.spec.comm_margin), BLACK.mix(0.25));
    xy.draw_series(std::iter::once(outer)).map_err(e)?;
    let inner = PathElement::new(sq(a), RED.stroke_width(2));
    xy.draw_series(std::iter::once(inner)).map_err(e)?;
    Ok(())
}

/// Mean delay against demand, one curve per algorithm, with each algorithm's capacity
/// marked and one lane's physical limit.
pub fn demand(r: &crate::experiments::demand::DemandReport, path: &Path) -> Result<(), PlotError> {
    render!(path, (1100, 700), |root| draw_demand(r, &root))
}

fn draw_demand<DB: DrawingBackend>(
    r: &crate::experiments::demand::DemandReport,
    root: &DrawingArea<DB, Shift>,
) -> Result<(), PlotError>
where
    DB::ErrorType: 'static,
{
    let curves = r
        .capacity
        .iter()
        .map(|cap| Curve {
            label: format!(
                "{} (capacity {:.0} veh/h/lane)",
                cap.algorithm, cap.capacity_vph_per_lane
            ),
            points: r
                .results
                .iter()
                .filter(|x| x.algorithm == cap.algorithm)
                .map(|x| (x.rate_vph_per_lane, x.mean_delay_s))
                .collect(),
            reference: false,
        })
        .collect::<Vec<_>>();
    let chart = LineChart {
        caption: format!(
            "Open-system demand at the SPEC §8 intersection ({} s, {} seeds; one lane's limit {:.0} veh/h)",
            r.duration_s, r.seeds, r.lane_limit_vph
        ),
        axes: ("arrivals per inlet lane (veh/h)", "mean delay (s)"),
        y_floor: 1.0,
        y_label_area: 60,
    };
    line_chart(root, &chart, &curves)
}

/// A chart of curves against one x axis.
struct LineChart<'a> {
    caption: String,
    /// x and y descriptions.
    axes: (&'a str, &'a str),
    /// The y range reaches at least this.
    y_floor: f64,
    y_label_area: u32,
}

/// One curve: its legend, its points; a reference line is thin, black and unmarked.
struct Curve {
    label: String,
    points: Vec<(f64, f64)>,
    reference: bool,
}

/// Draws `curves` (coloured in turn, points marked) on `root` from 0 to 5 % past the
/// largest x and y, with the legend in the upper left.
fn line_chart<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    chart: &LineChart<'_>,
    curves: &[Curve],
) -> Result<(), PlotError>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(e)?;
    let all = || curves.iter().flat_map(|c| c.points.iter());
    let x1 = all().map(|p| p.0).fold(0.0, f64::max) * 1.05;
    let y1 = all().map(|p| p.1).fold(chart.y_floor, f64::max) * 1.1;
    let mut c = ChartBuilder::on(root)
        .margin(20)
        .caption(&chart.caption, ("sans-serif", 20))
        .x_label_area_size(45)
        .y_label_area_size(chart.y_label_area)
        .build_cartesian_2d(0.0..x1, 0.0..y1)
        .map_err(e)?;
    c.configure_mesh()
        .x_desc(chart.axes.0)
        .y_desc(chart.axes.1)
        .draw()
        .map_err(e)?;
    let mut colour = 0;
    for curve in curves {
        let col = if curve.reference {
            BLACK
        } else {
            colour += 1;
            palette(colour - 1)
        };
        let width = if curve.reference { 1 } else { 2 };
        c.draw_series(LineSeries::new(
            curve.points.clone(),
            col.stroke_width(width),
        ))
        .map_err(e)?
        .label(curve.label.as_str())
        .legend(move |(x, y)| Rectangle::new([(x, y - 4), (x + 16, y + 4)], col.filled()));
        if !curve.reference {
            c.draw_series(
                curve
                    .points
                    .iter()
                    .map(|&p| Circle::new(p, 4, col.filled())),
            )
            .map_err(e)?;
        }
    }
    c.configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(e)?;
    Ok(())
}

/// The fault grid as heat maps, one panel per workload: rows are loss, columns delay,
/// and a last row of the other faults; each cell's colour is the share of vehicles that
/// met their goals (red 0 % → green 100 %) and its text the completion and the unsafe
/// events (the target is 0 in every cell).
pub fn fault_grid(
    r: &crate::experiments::fault_grid::GridReport,
    path: &Path,
) -> Result<(), PlotError> {
    render!(path, (1600, 900), |root| draw_fault_grid(r, &root))
}

fn draw_fault_grid<DB: DrawingBackend>(
    r: &crate::experiments::fault_grid::GridReport,
    root: &DrawingArea<DB, Shift>,
) -> Result<(), PlotError>
where
    DB::ErrorType: 'static,
{
    use crate::experiments::fault_grid::VARIANTS;
    let (losses, delays) = (r.losses.as_slice(), r.delays.as_slice());
    root.fill(&WHITE).map_err(e)?;
    let title = format!(
        "fault grid: completion per cell (colour), unsafe events (\"!n\", target none); {} runs per cell",
        r.runs
    );
    let root = root.titled(&title, ("sans-serif", 22)).map_err(e)?;
    let mut workloads: Vec<&str> = Vec::new();
    for c in &r.cells {
        if !workloads.contains(&c.workload.as_str()) {
            workloads.push(&c.workload);
        }
    }
    let panels = root.split_evenly((2, workloads.len().div_ceil(2)));
    for (w, area) in workloads.iter().zip(panels.iter()) {
        let mut chart = ChartBuilder::on(area)
            .margin(8)
            .caption(*w, ("sans-serif", 18))
            .x_label_area_size(34)
            .y_label_area_size(70)
            .build_cartesian_2d(
                -0.5..(delays.len().max(VARIANTS.len() + 1)) as f64 - 0.5,
                -0.5..losses.len() as f64 + 0.5,
            )
            .map_err(e)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_labels(delays.len().max(VARIANTS.len() + 1))
            .y_labels(losses.len() + 1)
            .x_label_formatter(&|x| {
                let i = x.round();
                match delays.get(i as usize) {
                    Some(d) if (x - i).abs() < 1e-6 && i >= 0.0 => format!("{d} s"),
                    _ => String::new(),
                }
            })
            .y_label_formatter(&|y| {
                let i = y.round();
                if (y - i).abs() > 1e-6 || i < 0.0 {
                    return String::new();
                }
                match losses.get(i as usize) {
                    Some(l) => format!("loss {l}"),
                    None => "other".into(),
                }
            })
            .x_desc("delay")
            .draw()
            .map_err(e)?;
        for c in r.cells.iter().filter(|c| c.workload == *w) {
            draw_grid_cell(&mut chart, c, losses, delays)?;
        }
    }
    Ok(())
}

/// One cell of a workload's heat map: its colour by completion, its label, and "!n" for
/// n unsafe events. Loss × delay cells sit at their row and column; the other variants
/// in a row of their own above.
fn draw_grid_cell<DB: DrawingBackend>(
    chart: &mut XyChart<'_, DB>,
    c: &crate::experiments::fault_grid::CellResult,
    losses: &[f64],
    delays: &[f64],
) -> Result<(), PlotError>
where
    DB::ErrorType: 'static,
{
    use crate::experiments::fault_grid::VARIANTS;
    let (col, row) = match c.cell.variant {
        "grid" => (
            delays
                .iter()
                .position(|&d| d == c.cell.delay_s)
                .unwrap_or(0),
            losses.iter().position(|&l| l == c.cell.loss).unwrap_or(0),
        ),
        v => (
            VARIANTS.iter().position(|&x| x == v).unwrap_or(0) + 1,
            losses.len(),
        ),
    };
    let (x, y) = (col as f64 - 0.5, row as f64 - 0.5);
    let p = c.completion.clamp(0.0, 1.0);
    let fill = RGBColor((230.0 * (1.0 - p)) as u8 + 25, (200.0 * p) as u8 + 40, 60);
    let cell = Rectangle::new([(x + 0.03, y + 0.03), (x + 0.97, y + 0.97)], fill.filled());
    chart.draw_series(std::iter::once(cell)).map_err(e)?;
    let bad = c.safety().events();
    let label = match c.cell.variant {
        "grid" => format!("{:.0}%", 100.0 * p),
        v => format!("{v} {:.0}%", 100.0 * p),
    };
    let text = if bad > 0 {
        format!("{label} !{bad}")
    } else {
        label
    };
    let font = ("sans-serif", 13).into_font().color(&BLACK);
    chart
        .draw_series(std::iter::once(Text::new(text, (x + 0.08, y + 0.62), font)))
        .map_err(e)?;
    Ok(())
}

/// `scale --sweep`: planner steps/s against vehicles, one curve per kind of road and
/// thread count, and the steps/s real time needs (vehicles / h).
pub fn scale(r: &crate::experiments::scale::ScaleSweep, path: &Path) -> Result<(), PlotError> {
    render!(path, (1100, 700), |root| draw_scale(r, &root))
}

fn draw_scale<DB: DrawingBackend>(
    r: &crate::experiments::scale::ScaleSweep,
    root: &DrawingArea<DB, Shift>,
) -> Result<(), PlotError>
where
    DB::ErrorType: 'static,
{
    let x1 = r.runs.iter().map(|x| x.vehicles as f64).fold(1.0, f64::max);
    let mut curves = vec![Curve {
        label: "real time (vehicles / h): above it, faster than real time".into(),
        points: vec![(0.0, 0.0), (x1, x1 * r.steps_per_vehicle_second)],
        reference: true,
    }];
    for x in &r.runs {
        let label = format!("{:?}, {} thread(s)", x.kind, x.threads);
        let point = (x.vehicles as f64, x.planner_steps_per_second);
        match curves.iter_mut().find(|c| c.label == label) {
            Some(c) => c.points.push(point),
            None => curves.push(Curve {
                label,
                points: vec![point],
                reference: false,
            }),
        }
    }
    let chart = LineChart {
        caption: format!(
            "host-sim scale --sweep: planner steps/s ({} s simulated per run, h = {} s)",
            r.sim_seconds,
            1.0 / r.steps_per_vehicle_second
        ),
        axes: ("vehicles", "planner steps per second"),
        y_floor: 0.0,
        y_label_area: 80,
    };
    line_chart(root, &chart, &curves)
}
