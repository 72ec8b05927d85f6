//! The vehicle computer in the loop: the planner as one vehicle of a world simulated
//! elsewhere, with nothing between them but CAN frames on a serial line.
//!
//! The link is serial-line CAN (SLCAN, [`can_gateway::slcan`]) on the board's UART, as a
//! USB-CAN adapter speaks it: Linux `slcand`, python-can's `slcan` interface or a
//! simulator can be the other end. Commands (`O`, `C`, `Sn`, `V`, …) are answered as an
//! adapter answers them; frames are taken only while the channel is open.
//!
//! Each period, in the manner of CANopen's SYNC (the world is the time master):
//! 1. the world sends the vehicle's own state as its sensors measure it, its road and its
//!    reference speed ([`Message::Ego`], from the time master's address); the computer
//!    answers with its V2V state message (its measured pose and speed, its lane, the
//!    lane it changes to and the one it intends, its braking limit and length);
//! 2. the world sends what the vehicle hears on the bus (the others' V2V states), then
//!    the tick ([`Message::Sync`]); on the tick the computer runs the multi-lane planner
//!    (Sec. IV–V) and answers with its command ([`Message::Command`]: v and ω as the f32
//!    the planner computed, and its lanes ℓ, α, β after the step), which the world
//!    integrates (1).
//!
//! The node's time is the world's: the stamp of the last ego state. The planner's
//! v_{t−h} and ω_{t−h} are the command it gave last period (what the world applied),
//! not the measured speed, which the wire rounds to 0.02 m/s; its pose is the measured
//! one, rounded to 0.01 m, and the planner's bus resolution is doubled in position to
//! cover its own rounding as well as the others'. The tick with `last` set ends the run:
//! the node logs its figures (periods, instructions per step in the board's virtual
//! 125 MHz clock, periods over h = 10 ms, fallbacks, frames refused, peak stack) and
//! exits through semihosting with success only if every period was on time and no frame
//! or line was refused.
//!
//! The node itself ([`sil_node`](crate::sil_node)) is sans I/O; this module is the board's
//! half: the UART, the clock that times each period's work, the log and the exit.

use crate::board;
use crate::clock::Clock;
use crate::measure;
use crate::sil_node::{Event, Lost, Node, Port};
use crate::uart::Uart;
use can_gateway::Instant;
use planner_core::{LanePlanner, LanePlannerSlot};

/// The planner's horizon: 20, or 50 with the `n50` feature.
#[cfg(not(feature = "n50"))]
pub const N: usize = 20;
/// The planner's horizon: 20, or 50 with the `n50` feature.
#[cfg(feature = "n50")]
pub const N: usize = 50;

/// The control period's budget in instructions: 10 ms at the virtual 125 MHz.
const PERIOD_INSTRUCTIONS: u64 = 1_250_000;
/// Most stack the node may use, painted: 8 KiB, as the scripted run.
const STACK_BUDGET: usize = 8 * 1024;
static mut NODE: Node = Node::new();
static mut SLOT: LanePlannerSlot<f32, N> = LanePlannerSlot::new();

/// Runs the node until the world's last tick; never returns.
pub fn run() -> ! {
    measure::paint_stack();
    let Some(cp) = cortex_m::Peripherals::take() else {
        board::exit(false)
    };
    // The clock only times the node's work: its time is the world's (the ego states').
    let mut clock = Clock::start(cp.SYST, Instant::from_micros(0));
    let per_tick = measure::calibrate(&clock);
    defmt::info!(
        "sil: board {=str} ({=str}), N={=usize}, {=u32} instructions per 100 SysTick ticks; SLCAN on UART 0",
        board::MACHINE,
        board::CORE,
        N,
        per_tick
    );
    // SAFETY: the board's UART 0, driven by nothing else.
    let mut uart = unsafe { Uart::new(board::UART0, board::SYSTICK_HZ) };
    // Between periods the core sleeps until a byte comes, SysTick stopped: only the
    // work is timed, and under QEMU a waiting computer costs its host no CPU.
    uart.listen();
    // SAFETY: the receive interrupt's handler (`DefaultHandler`) only acknowledges it, so
    // unmasking it breaks no critical section.
    unsafe { cortex_m::peripheral::NVIC::unmask(UartRx) };
    clock.stop();
    // SAFETY: `run` runs once and never returns; these are the only references.
    let node = unsafe { &mut *core::ptr::addr_of_mut!(NODE) };
    let mut slot = Some(unsafe { &mut *core::ptr::addr_of_mut!(SLOT) });
    let mut planner: Option<&mut LanePlanner<f32, N>> = None;
    loop {
        let Some(byte) = uart.read() else {
            uart.wait();
            continue;
        };
        match node.take(byte, &mut uart) {
            Event::None => {}
            Event::Refused(id, e) => {
                // The first few, said: a world that speaks another protocol shows at once.
                if node.figures.refused <= 4 {
                    defmt::warn!("sil: frame {=u32:08x} refused: {}", id, e);
                }
            }
            Event::Ego => {
                // The planner is built once, on the first ego state.
                if let Some(s) = slot.take() {
                    planner = node.start(s);
                }
                node.announce(&mut uart);
            }
            Event::Tick(period, last) => {
                let Some(lp) = planner.as_deref_mut() else {
                    node.figures.refused += 1;
                    continue;
                };
                // SysTick starts at the tick, and the work starts on its first millisecond
                // boundary: its interrupt ends this `wfi` (the world sends nothing until
                // the command, so no byte can end it), so the count does not depend on
                // the phase SysTick started at. Runs under a loaded host still differ by
                // up to three ticks in a period's count (15 instructions in 1,250,000),
                // where the polling node counted the same every run.
                clock.restart();
                cortex_m::asm::wfi();
                let t0 = clock.now();
                node.plan(lp, period, &mut uart);
                let ticks = clock.now() - t0;
                clock.stop();
                count(node, period, ticks * u64::from(per_tick) / 100);
                if last {
                    finish(node)
                }
            }
        }
    }
}

/// UART 0's receive interrupt, which wakes the waiting core.
#[derive(Debug, Clone, Copy)]
struct UartRx;

// SAFETY: the board's IRQ number for UART 0's receive interrupt.
unsafe impl cortex_m::interrupt::InterruptNumber for UartRx {
    fn number(self) -> u16 {
        board::UART0_RX_IRQ
    }
}

/// Every interrupt without a handler of its own: UART 0's receive interrupt is
/// acknowledged (the byte stays for the loop to read); any other is a fault of the
/// build, and the node exits with failure.
#[cortex_m_rt::exception]
unsafe fn DefaultHandler(irqn: i16) {
    if irqn == board::UART0_RX_IRQ as i16 {
        // SAFETY: UART 0 is this board's CMSDK APB UART.
        unsafe { Uart::clear_receive_interrupt(board::UART0) }
    } else {
        defmt::error!("sil: unexpected interrupt {=i16}", irqn);
        board::exit(false)
    }
}

/// Logs the run's figures and exits: success only if every period was on time and
/// nothing was refused or lost.
fn finish(node: &Node) -> ! {
    let f = node.figures;
    let peak = measure::peak_stack();
    defmt::info!("sil: {}", f);
    defmt::info!(
        "sil: {=u32} periods, worst {=u64} instructions per period (h = {=u64}), {=u32} over h; peak stack {=usize} B",
        f.periods,
        f.worst_instructions,
        PERIOD_INSTRUCTIONS,
        f.overruns,
        peak
    );
    let (flash, ram) = measure::footprint();
    defmt::info!(
        "sil: footprint (N={=usize}): flash={=usize} B, static RAM={=usize} B",
        N,
        flash,
        ram
    );
    let ok = f.overruns == 0
        && f.refused == 0
        && f.bad_lines == 0
        && f.lost == 0
        && peak <= STACK_BUDGET;
    board::exit(ok && f.periods > 0)
}

/// Counts one tick's work of `instructions`.
fn count(node: &mut Node, period: u32, instructions: u64) {
    let (status, (speed, lateral)) = (node.last_status, node.last_iterations);
    let f = &mut node.figures;
    f.periods += 1;
    f.worst_instructions = f.worst_instructions.max(instructions);
    if instructions > PERIOD_INSTRUCTIONS {
        f.overruns += 1;
        defmt::warn!(
            "sil: period {=u32} took {=u64} instructions ({}; {=u32} + {=u32} solver iterations)",
            period,
            instructions,
            status,
            speed,
            lateral
        );
    }
}

impl Port for Uart {
    fn send(&mut self, bytes: &[u8]) -> Result<(), Lost> {
        self.write_all(bytes).map_err(|_| Lost)
    }
}
