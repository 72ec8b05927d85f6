//! A world as a fleet on a CAN medium: every vehicle's planners run in a task of their own
//! (a thread with its own CAN node), and so does every junction's manager (its node at its
//! own source address, 0xF1 + its index); they hear each other only through can-gateway
//! frames on that medium — a SocketCAN interface such as `vcan0`, or the in-process
//! frame [`Hub`]. It differs from the in-process world only in the medium: the vehicles,
//! managers, monitors and summary are the world's own.
//!
//! Time is kept by a time master on the bus, in the manner of CANopen SYNC. Per period k
//! (time kh):
//!
//! 1. every vehicle publishes its message for kh (its state on a segment, its crossing
//!    request at a junction; and, for a while after leaving a junction, its exit), then
//!    reports its true state to the harness, which runs the monitors — ground truth never
//!    reaches a planner;
//! 2. with junctions, the master sends SYNC(2k): each manager takes what preceded it,
//!    decides, publishes its grants and tells the harness;
//! 3. the harness hands each vehicle its sensor returns (computed from ground truth, as
//!    in the in-process world), and the master sends SYNC(2k + 1) (without junctions,
//!    SYNC(k)): each vehicle takes what preceded it, plans, and moves one period.
//!
//! The run is lock-step and as repeatable as the in-process one (each period's messages
//! are taken in the in-process bus's order, whatever order the tasks' frames interleaved
//! in); what differs is that every message went through the codec (0.01 m, 0.02 m/s),
//! which the planners and managers allow for, and the kernel's CAN stack. The kernel's
//! receive time stamps measure the latency from publication to reception.
//!
//! The files, one concept each: [`Fleet`] (here) is the builder and its one `run`; the
//! harness (`harness.rs`) sees ground truth — monitors, sensors, trace — beside the
//! tasks; the tasks (`tasks.rs`) are the vehicles' and managers' threads and what they
//! report; the time master (`master.rs`) paces them period by period; `run.rs` opens the
//! nodes, spawns the tasks and gathers the summary (`summary.rs`: what a run reports, and
//! why one failed).

pub mod can;
mod harness;

pub mod intruder;

pub mod ledger;
mod master;
mod run;

pub mod summary;
mod tasks;
pub mod throughput;

use crate::bus::Faults;

use crate::world::{SolverChoice, TraceRow, WorldSpec};

use can::{CanPort, Hub, Keys, SocketCanPort};

use can_gateway::wire::{self};

use intruder::{Attack, INTRUDER_ADDRESS};

use std::fmt;

use std::io;

use std::sync::Arc;

use harness::Harness;
use std::time::{Duration, SystemTime};
/// How long a task waits for the next SYNC, and the master for a report, before the run
/// fails: far above a period's work even under full-system emulation.
pub const TIMEOUT: Duration = Duration::from_secs(60);

pub use summary::{FleetError, FleetSummary, Intrusion, Latency, Messages};

/// Where the fleet's frames travel.
#[derive(Debug, Clone)]
pub enum Medium {
    /// A SocketCAN interface (e.g. `vcan0`).
    SocketCan(String),
    /// The in-process frame hub.
    Hub,
}

impl std::str::FromStr for Medium {
    type Err = String;

    /// `can-hub`, or a Linux network interface's name (1 to 15 bytes, IFNAMSIZ − 1, of
    /// a-z A-Z 0-9 - _ .).
    fn from_str(bus: &str) -> Result<Self, String> {
        match bus {
            "can-hub" => Ok(Medium::Hub),
            iface
                if (1..=15).contains(&iface.len())
                    && iface
                        .bytes()
                        .all(|b| b.is_ascii_alphanumeric() || b"-_.".contains(&b)) =>
            {
                Ok(Medium::SocketCan(iface.to_string()))
            }
            other => Err(format!(
                "--bus {other:?}: expected in-process, can-hub or a network interface name (1–15 of a-z A-Z 0-9 - _ .)"
            )),
        }
    }
}

impl fmt::Display for Medium {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::SocketCan(i) => write!(f, "socketcan:{i}"),
            Self::Hub => write!(f, "can-hub"),
        }
    }
}

/// A node of the fleet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Node {
    /// The time master.
    Clock,
    /// Vehicle id.
    Vehicle(u16),
    /// Junction (index)'s manager.
    Manager(usize),
    /// The attack experiment's intruder ([`intruder`]).
    Intruder,
}

/// Why `spec` cannot run as a fleet, if it cannot: the bus carries frames as they are
/// (no loss, delay, duplicates or reordering injected — a silent vehicle, a liar and a
/// manager's outage are the nodes' own faults, and run); no vehicle enters during the
/// run (every node's socket is open before anyone transmits); every vehicle id a CAN
/// source address; at most as many junctions as manager addresses.
pub fn unsupported(spec: &WorldSpec) -> Option<String> {
    let nodes_only = Faults {
        silent: None,
        liar: None,
        manager_down: None,
        ..spec.faults
    };
    if !nodes_only.is_none() {
        return Some(
            "[faults] loss, delay, jitter, duplicates and reordering are injected by the \
             in-process bus; a fleet carries frames as they are"
                .into(),
        );
    }
    if spec.arrivals != crate::world::Arrivals::None {
        return Some("vehicles that enter while the run goes on need the in-process bus".into());
    }
    if let Some(e) = spec
        .vehicles
        .iter()
        .find_map(|v| can::vehicle_address(v.id).err())
    {
        return Some(e.to_string());
    }
    (0..spec.network.junctions.len())
        .find(|&j| wire::manager_address(j).is_none())
        .map(|_| "more junctions than CAN manager addresses (13)".into())
}

/// Where a fleet's nodes get their CAN ports.
pub enum Ports {
    /// Every node on a medium: a SocketCAN interface, or the in-process hub.
    Medium(Medium),
    /// Every node's port from `open` (a test's, e.g. one that drops or forges frames);
    /// `name` names the medium in the summary.
    Custom {
        /// The medium's name in the summary.
        name: String,
        /// Opens one node's port.
        open: Box<dyn FnMut(Node) -> io::Result<Box<dyn CanPort>>>,
    },
}

impl Ports {
    /// Ports from `open`, named `name` in the summary.
    pub fn custom<P: CanPort + 'static>(
        name: &str,
        mut open: impl FnMut(Node) -> io::Result<P> + 'static,
    ) -> Self {
        Self::Custom {
            name: name.to_string(),
            open: Box::new(move |n| open(n).map(|p| Box::new(p) as Box<dyn CanPort>)),
        }
    }
}

impl From<Medium> for Ports {
    fn from(m: Medium) -> Self {
        Self::Medium(m)
    }
}

/// A fleet: built with [`Fleet::new`] and the settings that differ from the defaults,
/// then [`Fleet::run`] on its ports. Every node is a task that talks to the others only
/// in CAN frames.
///
/// ```no_run
/// # use host_sim::fleet::{Fleet, Medium};
/// # fn f(spec: host_sim::world::WorldSpec) -> Result<(), host_sim::fleet::FleetError> {
/// let summary = Fleet::new().fd(true).run(spec, Medium::Hub, &mut |_| {})?;
/// # Ok(()) }
/// ```
#[derive(Clone)]
pub struct Fleet {
    solver: SolverChoice,
    seed: Option<u64>,
    keys: Option<Arc<Keys>>,
    fd: bool,
    attack: Option<Attack>,
}

impl Default for Fleet {
    fn default() -> Self {
        Self::new()
    }
}

/// When the intruder starts (s): the fleet has settled into its traffic by then.
pub const ATTACK_FROM_S: f64 = 1.0;

impl Fleet {
    /// Our solver, the scenario's seed, no keys, classic frames, no intruder.
    pub fn new() -> Self {
        Self {
            solver: SolverChoice::Ours,
            seed: None,
            keys: None,
            fd: false,
            attack: None,
        }
    }

    /// The planners' solver.
    pub fn solver(self, solver: SolverChoice) -> Self {
        Self { solver, ..self }
    }

    /// Overrides the scenario's seed (`None`: the scenario's).
    pub fn seed(self, seed: Option<u64>) -> Self {
        Self { seed, ..self }
    }

    /// With keys, every node authenticates what it sends and verifies what it accepts.
    pub fn keys(self, keys: Option<Arc<Keys>>) -> Self {
        Self { keys, ..self }
    }

    /// Every message goes as one CAN FD frame (an interface must carry CAN FD: MTU 72).
    pub fn fd(self, fd: bool) -> Self {
        Self { fd, ..self }
    }

    /// An intruder carries out `attack` from [`ATTACK_FROM_S`] on.
    pub fn attack(self, attack: Option<Attack>) -> Self {
        Self { attack, ..self }
    }

    /// Runs `spec` on `ports`; `trace` sees a row per vehicle and period.
    pub fn run(
        self,
        spec: WorldSpec,
        ports: impl Into<Ports>,
        trace: &mut dyn FnMut(&TraceRow),
    ) -> Result<FleetSummary, FleetError> {
        if let Some(why) = unsupported(&spec) {
            return Err(FleetError::Unsupported(why));
        }
        if self.attack.is_some()
            && spec
                .vehicles
                .iter()
                .any(|v| v.id == u16::from(INTRUDER_ADDRESS))
        {
            return Err(FleetError::Unsupported(format!(
                "vehicle {INTRUDER_ADDRESS} holds the intruder's address"
            )));
        }
        match ports.into() {
            Ports::Medium(m) => self.on_medium(spec, &m, trace),
            Ports::Custom { name, open } => self.start(spec, &name, open, trace),
        }
    }

    fn on_medium(
        self,
        spec: WorldSpec,
        medium: &Medium,
        trace: &mut dyn FnMut(&TraceRow),
    ) -> Result<FleetSummary, FleetError> {
        let name = medium.to_string();
        let fd = self.fd;
        match medium {
            Medium::SocketCan(iface) => {
                if let Some(w) = can::order_warning(iface) {
                    eprintln!("warning: {w}");
                }
                let iface = iface.clone();
                let open = move |n: Node| match n {
                    Node::Clock => SocketCanPort::open_transmit_only(&iface, fd),
                    _ if fd => SocketCanPort::open_fd(&iface),
                    _ => SocketCanPort::open(&iface),
                };
                self.start(spec, &name, open, trace)
            }
            Medium::Hub => {
                let hub = Hub::new();
                self.start(spec, &name, move |_| Ok(hub.port()), trace)
            }
        }
    }

    fn start<P: CanPort + 'static>(
        self,
        spec: WorldSpec,
        medium: &str,
        open: impl FnMut(Node) -> io::Result<P>,
        trace: &mut dyn FnMut(&TraceRow),
    ) -> Result<FleetSummary, FleetError> {
        match spec.horizon {
            50 => Harness::<50>::new(spec, self).run(medium, open, trace),
            _ => Harness::<20>::new(spec, self).run(medium, open, trace),
        }
    }
}

/// Microseconds from `from` to `to` (0 if `to` is earlier).
pub fn micros(from: SystemTime, to: SystemTime) -> f64 {
    to.duration_since(from)
        .map_or(0.0, |d| d.as_secs_f64() * 1e6)
}
