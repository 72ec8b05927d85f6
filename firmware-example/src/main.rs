//! planner-core on a Cortex-M4F, M7 or M33 ([`board`]), in f32, as a control loop at h = 10 ms, logging with defmt
//! over semihosting (decode with `defmt-print -e <elf>`):
//! (1) a single-lane approach to a stopped vehicle that the ego knows only from its V2V
//! state messages, received as CAN frames through can-gateway from an `embedded-can`
//! controller (in loopback mode: what it transmits for the leader comes back in its
//! receive FIFO); (2) a lane change on a two-lane road.
//! Each period reads the CAN frames, runs the planner, emits the command and sleeps out the
//! rest of the 10 ms through embedded-hal 1.0's `DelayNs` on SysTick ([`clock`]).
//! The planners live in static slots (`planner_core::slot`, in `.bss`), built in place,
//! so the stack holds only what one control step needs.
//! It also measures what the planner costs here: flash and static RAM (from the linker's
//! symbols), peak stack (stack painting), and instructions per planner step (SysTick
//! under QEMU's `-icount shift=3`, where one instruction is 8 ns of virtual time, so one
//! tick of a 25 MHz SysTick is 5 instructions and of a 20 MHz one 6.25; the factor is
//! calibrated, in hundredths, on a loop of known length). The loop's deadlines are checked
//! in that virtual time: a 125 MHz core.
//! Build with `--features n50` for a horizon of 50; `run.sh BOARD N OUT` builds, runs and
//! decodes it for a board.
#![no_std]
#![no_main]

// The board's UART is the in-the-loop program's (src/bin/sil.rs); this one uses none.
#[allow(dead_code)]
mod board;
mod clock;
mod measure;
mod scenarios;
mod secured;

use board::exit;
use clock::Clock;
use cortex_m_rt::entry;
use defmt_semihosting as _;
use embedded_hal::delay::DelayNs;
use measure::{calibrate, lowest_unpainted, paint_stack, peak_stack, repaint};

#[cfg(not(feature = "n50"))]
const N: usize = 20;
#[cfg(feature = "n50")]
const N: usize = 50;
use planner_core::{CostWeights, LanePlannerSlot, Params, PlannerSlot};
use scenarios::{Node, StepRecord};

/// The control period h = 10 ms, in SysTick ticks.
const PERIOD_TICKS: u64 = clock::TICKS_PER_SECOND / 100;
/// Nanoseconds per SysTick tick.
const NS_PER_TICK: u64 = 1_000_000_000 / clock::TICKS_PER_SECOND;
const STEPS: usize = 1000;
/// Most stack the whole program may use, painted: 8 KiB, at N = 20 and 50.
const STACK_BUDGET: usize = 8 * 1024;
/// Most instructions one N = 20 lane-change step may take: 2.4 ms at the
/// emulated 125 MHz, 1.8 ms at 168 MHz.
const LANE_CHANGE_BUDGET: u32 = 300_000;

/// Per-step tick counts (a measurement buffer, not part of the planner's footprint).
static mut SAMPLES: [u32; STEPS] = [0; STEPS];

/// The two scenarios' planners, in place (all zeros until `init`: `.bss`, no flash).
static mut SLOTS: (PlannerSlot<f32, N>, LanePlannerSlot<f32, N>) =
    (PlannerSlot::new(), LanePlannerSlot::new());

/// The node's CAN side: controller, reassembler, world view, neighbour buffers (`const`,
/// so in `.bss` too, off the stack).
static mut NODE: Node = Node::new();

/// Median and maximum of the first `n` samples, in instructions, at `per_tick` hundredths
/// of an instruction per tick.
fn stats(n: usize, per_tick: u32) -> (u32, u32) {
    let s = unsafe { &mut *core::ptr::addr_of_mut!(SAMPLES) };
    let s = &mut s[..n.min(STEPS)];
    s.sort_unstable();
    let instructions =
        |t: u32| u32::try_from(u64::from(t) * u64::from(per_tick) / 100).unwrap_or(u32::MAX);
    let med = s.get(s.len() / 2).copied().unwrap_or(0);
    let max = s.last().copied().unwrap_or(0);
    (instructions(med), instructions(max))
}

fn record(i: usize, ticks: u32) {
    let s = unsafe { &mut *core::ptr::addr_of_mut!(SAMPLES) };
    if let Some(slot) = s.get_mut(i) {
        *slot = ticks;
    }
}

/// Control-loop timing over one scenario.
#[derive(Debug, Clone, Copy, Default, defmt::Format)]
struct LoopTiming {
    periods: u32,
    /// Periods whose work did not fit in h.
    overruns: u32,
    /// Largest wake-up after a period's deadline, in ns.
    max_late_ns: u64,
}

#[entry]
fn main() -> ! {
    paint_stack();
    let cp = match cortex_m::Peripherals::take() {
        Some(cp) => cp,
        None => exit(false),
    };
    let clock = Clock::start(cp.SYST, scenarios::CLOCK_START);
    let per_tick = calibrate(&clock);
    defmt::info!(
        "board: {=str} ({=str}), SysTick {=u32} Hz; calibration: {=u32} instructions per 100 SysTick ticks",
        board::MACHINE,
        board::CORE,
        board::SYSTICK_HZ,
        per_tick
    );

    // The planners live in static slots (.bss), built in place: the stack
    // holds only what one control step needs.
    // SAFETY: `main` runs once and never returns; this is the only reference to SLOTS.
    let slots = unsafe { &mut *core::ptr::addr_of_mut!(SLOTS) };
    // SAFETY: as for SLOTS: the only reference to NODE.
    let node = unsafe { &mut *core::ptr::addr_of_mut!(NODE) };
    let params = Params::<f32>::table_i();
    let (Ok(planner), Ok(lane_planner)) = (
        slots.0.init(params, CostWeights::default()),
        slots.1.init(params, CostWeights::default(), 0),
    ) else {
        exit(false)
    };

    let now = || clock.now() as u32;
    // A second handle for the loop's sleeping (Clock is a handle; SysTick is the state).
    let mut delay = clock;
    // Every command goes out as a `cmd` line (f32 bits in hex), for CI to compare with the
    // host mirror step for step; timed steps go to the statistics (`timed` counts them and
    // is reset between the scenarios). Then the loop sleeps to the end of its period.
    let timed = core::cell::Cell::new(0usize);
    let timing = core::cell::Cell::new(LoopTiming::default());
    let deadline = core::cell::Cell::new(clock.now() + PERIOD_TICKS);
    let mut last_status = None;
    let mut emit = |r: &StepRecord| {
        defmt::println!(
            "cmd {=char} {=u32} {=u32:08x} {=u32:08x}",
            r.scenario,
            r.k,
            r.v.to_bits(),
            r.omega.to_bits()
        );
        if r.timed {
            record(timed.get(), r.ticks);
            timed.set(timed.get() + 1);
        }
        // The single-lane planner's command in a lane-change period: planned beside the
        // lane planner's, in the same period, which that one ends.
        if r.scenario == 'S' {
            return;
        }
        let kind = r.status.map(|s| core::mem::discriminant(&s));
        if kind != last_status {
            defmt::info!("{=char} k={=u32}: {}", r.scenario, r.k, r.status);
            last_status = kind;
        }
        if let Some(e) = r.event {
            defmt::info!(
                "{=char} k={=u32}: lane event {} at y={=f32} m",
                r.scenario,
                r.k,
                e,
                r.position
            );
        }
        if r.scenario == 'A' && r.k.is_multiple_of(100) {
            defmt::info!("t={=u32}ms x={=f32} v={=f32}", r.k * 10, r.position, r.v);
        }
        // Sleep to this period's deadline (embedded-hal DelayNs), then schedule the next one
        // from the deadline, not from the wake-up, so lateness does not accumulate.
        let mut t = timing.get();
        let end = deadline.get();
        let start = delay.now();
        if start < end {
            delay.delay_ns(((end - start) * NS_PER_TICK) as u32);
        } else {
            t.overruns += 1;
        }
        t.max_late_ns = t
            .max_late_ns
            .max(delay.now().saturating_sub(end) * NS_PER_TICK);
        t.periods += 1;
        timing.set(t);
        deadline.set(end + PERIOD_TICKS);
    };
    // What one planner takes (each lives in a static slot, not on the
    // stack); with a view of 32 neighbours, the most a multi-lane planner is configured
    // for.
    defmt::info!(
        "planner sizes (N={=usize}): Planner {=usize} B, LanePlanner {=usize} B, LanePlanner + a view of 32 neighbours {=usize} B",
        N,
        core::mem::size_of::<planner_core::Planner<f32, N>>(),
        core::mem::size_of::<planner_core::LanePlanner<f32, N>>(),
        core::mem::size_of::<planner_core::LanePlanner<f32, N>>()
            + core::mem::size_of::<planner_core::WorldView<f32, 32>>()
    );
    // The node's clock started at 60 days of uptime. The approach stamps its periods
    // from that nominal start (period k at CLOCK_START + k·h), so that the host mirror,
    // which has no SysTick, computes the same stamps and must plan the same commands.
    let start = clock.instant();
    defmt::info!(
        "clock: {=u64} ms of uptime at the first period",
        start.as_millis()
    );
    // The whole program's peak so far; then each scenario's own, on a fresh paint.
    let mut peak = peak_stack();
    let sp = repaint();
    // Painting 4 MiB took time: the first period starts now.
    deadline.set(clock.now() + PERIOD_TICKS);
    let start = scenarios::CLOCK_START;
    let Some(a) = scenarios::approach::<N>(planner, node, start, &mut { now }, &mut emit) else {
        exit(false)
    };
    let approach_stack = sp - lowest_unpainted();
    peak = peak.max(peak_stack());
    defmt::info!(
        "done: x={=f32} v={=f32} solved={=u32} standstill={=u32} fallback={=u32}",
        a.x,
        a.v,
        a.solved,
        a.standstill,
        a.fallbacks
    );
    defmt::info!(
        "CAN: {=u32} frames received, {=u32} rejected",
        a.frames,
        a.rejected
    );
    let (med, max) = stats(timed.get(), per_tick);
    defmt::info!(
        "instructions per single-lane step (N={=usize}): median={=u32} worst={=u32} over {=usize} solved steps",
        N,
        med,
        max,
        timed.get()
    );
    let t = timing.replace(LoopTiming::default());
    defmt::info!("control loop (approach, h = 10 ms): {}", t);
    // Success needs a stop behind the obstacle point x̄ = 60 − 4.5 − 0.5 = 55 m with no
    // fallback, every frame accepted, and every period on time.
    let approach_ok = a.fallbacks == 0
        && a.v == 0.0
        && a.x < 55.0
        && a.x > 54.9
        && a.rejected == 0
        && t.overruns == 0;

    timed.set(0);
    let sp = repaint();
    deadline.set(clock.now() + PERIOD_TICKS);
    let Some(l) =
        scenarios::lane_change::<N>(lane_planner, planner, node, start, &mut { now }, &mut emit)
    else {
        exit(false)
    };
    let lane_stack = sp - lowest_unpainted();
    peak = peak.max(peak_stack());
    defmt::info!(
        "stack per call (N={=usize}): approach (single-lane planner, CAN, view) {=usize} B; lane change (both planners each period, CAN, view) {=usize} B",
        N,
        approach_stack,
        lane_stack
    );
    defmt::info!(
        "single-lane planner beside the lane planner: {=u32} steps not solved",
        l.single_fallbacks
    );
    let (lmed, lmax) = stats(timed.get(), per_tick);
    defmt::info!(
        "lane change: completed at step {}, y={=f32} fallback={=u32}",
        l.completed_at,
        l.y,
        l.fallbacks
    );
    defmt::info!(
        "instructions per lane-change step (N={=usize}): median={=u32} worst={=u32} over {=u32} steps",
        N,
        lmed,
        lmax,
        l.changing
    );
    let lt = timing.get();
    defmt::info!("control loop (lane change, h = 10 ms): {}", lt);
    // Every period on time at N = 20 and 50 (the active-set step brought
    // N = 50's worst step from 1.9 M to under 0.5 M instructions), and at N = 20 the step
    // within its instruction budget.
    let lane_ok = l.completed_at.is_some()
        && l.fallbacks == 0
        && l.single_fallbacks == 0
        && lt.overruns == 0
        && (N > 20 || lmax <= LANE_CHANGE_BUDGET);

    // SecOC: instructions per verified message, classic (3 data frames + authenticator)
    // and CAN FD (one frame), with the key fixed at build time.
    let mut secoc_ok = true;
    for (fd, name) in [(false, "classic CAN, 5 frames"), (true, "CAN FD, 1 frame")] {
        let v = secured::run(fd, &mut { now }, &mut record);
        let (med, max) = stats(secured::MESSAGES, per_tick);
        defmt::info!(
            "instructions per verified message (SecOC AES-128-CMAC, vehicle state, {=str}): median={=u32} worst={=u32} over {=u32} messages, {=u32} forged accepted",
            name,
            med,
            max,
            v.accepted,
            v.forged_accepted
        );
        secoc_ok &= v.accepted == secured::MESSAGES as u32 && v.forged_accepted == 0;
    }

    let (flash, ram) = measure::footprint();
    let samples = core::mem::size_of::<[u32; STEPS]>();
    let peak = peak.max(peak_stack());
    defmt::info!(
        "footprint (N={=usize}): flash={=usize} B, static RAM={=usize} B (of which {=usize} B measurement buffer), peak stack={=usize} B",
        N,
        flash,
        ram,
        samples,
        peak
    );
    exit(approach_ok && lane_ok && secoc_ok && peak <= STACK_BUDGET)
}
