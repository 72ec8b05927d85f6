//! The planners' messages as real CAN frames: can-gateway's codec over a [`CanPort`] —
//! SocketCAN on Linux (`socketcan` 4, e.g. `vcan0`) or an in-process frame [`Hub`] —
//! with kernel (or hub) receive time stamps; classic CAN (a message in up to five
//! frames) or CAN FD (a whole message, authenticator included, in one frame).
//!
//! - [`CanNode`]: one node's attachment (its port, alive counters, reassembler, counts);
//! - [`CanBus`]: the message-level [`Bus`] over one node per vehicle, so that the
//!   single-threaded simulator runs unchanged over CAN;
//! - the fleet runner ([`crate::fleet`]) gives every vehicle and every junction
//!   manager its own task and node.
//!
//! Mapping of the simulator's messages onto can-gateway's ([`WireMap`]): on a straight
//! road or at a single junction the messages of the paper's protocols — `State` ↔
//! `State`, `Left` ↔ `Exit`, `Grant` ↔ `Grant` (sent by the manager's address only), a
//! crossing report ↔ `Request` (the route as its inlet and outlet tracks, through the
//! layout's route table, and the arrival time); in a network, the kinds that also carry
//! the place: `Located` (a state and its segment), `JunctionRequest` and `JunctionExit`
//! (with their junction), and grants from each junction manager's own address.

use crate::bus::{Bus, BusError, Clock, Message, Received};
use crate::world::network::Network;
use crate::world::{Fleet, LENGTH_M};
use can_gateway::codec::{
    encode_fd_secured, encode_secured, DecodeError, EncodeError, SecuredFrames, Verifier,
};
use can_gateway::secoc::{derive_key, FreshnessRx, FreshnessTx, Key, KeyStore};
use can_gateway::wire::{self, CLOCK_ADDRESS};
use can_gateway::{encode, encode_fd, FdFrame, Frames, PlainFrame, Reassembler};
use planner_core::crossing::CrossingReport;
use planner_core::intersection::Track;
use planner_core::{BodyLength, Instant};
use serde::Serialize;
use socketcan::{
    CanAnyFrame, CanFdFrame, CanFdSocket, CanFrame, CanSocket, EmbeddedFrame, Socket, SocketOptions,
};
use std::collections::{BTreeMap, VecDeque};
use std::fmt;
use std::io;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant as WallClock, SystemTime};

/// The junction number of a `JunctionExit` that says its vehicle left the network at an
/// exit (no junction has it: a network has at most 64).
pub const NETWORK_EXIT: u8 = 0xFF;

/// The steps to which can-gateway rounds what vehicles broadcast (position 0.01 m, speed
/// 0.02 m/s): the planners' bus resolution over CAN.
pub const RESOLUTION: (f64, f64) = (wire::POS_RES, wire::SPEED_RES);

/// (sender, kind) pairs a node's reassembler tracks: every vehicle a scenario may hold
/// (128) × the kinds a vehicle sends, plus the clock and the manager.
pub const REASSEMBLY_SLOTS: usize = 512;

/// Receive buffer each SocketCAN port asks for (bytes; the kernel accounts about 1 KiB
/// per CAN frame, so some 8,000 frames).
const RECV_BUFFER_BYTES: i32 = 8 << 20;

/// Bounded retries of a transmission the kernel refuses for lack of buffer (ENOBUFS on a
/// busy interface): 100 × 1 ms, then the error is reported.
const TX_RETRIES: u32 = 100;

/// One node's attachment to a CAN medium.
pub trait CanPort: Send {
    /// Transmits one frame (classic, or CAN FD when it carries more than 8 bytes).
    fn transmit(&mut self, frame: &FdFrame) -> io::Result<()>;
    /// The next received frame and its receive time stamp, waiting up to `timeout`
    /// (zero: only a frame already there); `None` when none came in time.
    fn receive(&mut self, timeout: Duration) -> io::Result<Option<(FdFrame, SystemTime)>>;
    /// From now on, takes only frames from source address `sa` where the medium can
    /// filter cheaply (a SocketCAN socket: the kernel's acceptance filter, as a CAN
    /// controller's). The default takes everything still: the hub's deliveries cost a
    /// queue push each, and its tests count every node hearing every frame.
    fn hear_only(&mut self, sa: u8) -> io::Result<()> {
        let _ = sa;
        Ok(())
    }
}

impl<P: CanPort + ?Sized> CanPort for Box<P> {
    fn transmit(&mut self, frame: &FdFrame) -> io::Result<()> {
        (**self).transmit(frame)
    }
    fn receive(&mut self, timeout: Duration) -> io::Result<Option<(FdFrame, SystemTime)>> {
        (**self).receive(timeout)
    }
    fn hear_only(&mut self, sa: u8) -> io::Result<()> {
        (**self).hear_only(sa)
    }
}

/// A raw SocketCAN socket: classic frames only, or classic and CAN FD frames.
enum Sock {
    Classic(CanSocket),
    Fd(CanFdSocket),
}

/// A raw SocketCAN socket bound to one interface, with `SO_TIMESTAMPNS` receive stamps
/// (the kernel's time of arrival at the socket).
pub struct SocketCanPort {
    sock: Sock,
    /// The read timeout last set (avoids a system call per read).
    timeout: Option<Duration>,
}

impl SocketCanPort {
    /// Opens a socket on `iface` (e.g. `vcan0`) with receive time stamps.
    pub fn open(iface: &str) -> io::Result<Self> {
        let sock = CanSocket::open(iface)?;
        Self::tune(&sock)?;
        Ok(Self {
            sock: Sock::Classic(sock),
            timeout: None,
        })
    }

    /// Opens a CAN FD socket on `iface`, which must carry CAN FD frames (a vcan with MTU
    /// 72: `ip link set vcan0 mtu 72`).
    pub fn open_fd(iface: &str) -> io::Result<Self> {
        let mtu = std::fs::read_to_string(format!("/sys/class/net/{iface}/mtu"))
            .ok()
            .and_then(|m| m.trim().parse::<u32>().ok());
        if let Some(mtu) = mtu.filter(|&m| m < CANFD_MTU) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "{iface} has MTU {mtu}: classic CAN only; CAN FD needs {CANFD_MTU} \
                     (ip link set {iface} mtu {CANFD_MTU})"
                ),
            ));
        }
        let sock = CanFdSocket::open(iface)?;
        Self::tune(&sock)?;
        Ok(Self {
            sock: Sock::Fd(sock),
            timeout: None,
        })
    }

    /// Receive time stamps and a receive buffer for a whole fleet's traffic.
    fn tune(sock: &impl SocketOptions) -> io::Result<()> {
        sock.set_recv_timestamp(true)?;
        // Every node hears every frame of the fleet; a task the scheduler starves for a
        // moment (a busy host, a VM under TCG) must not have the kernel drop frames for a
        // full queue (its default holds a few hundred). Root may force a larger buffer;
        // otherwise ask for it within the system's limit.
        const SOL_SOCKET: i32 = 1;
        const SO_RCVBUF: i32 = 8;
        const SO_RCVBUFFORCE: i32 = 33;
        if sock
            .set_socket_option_int(SOL_SOCKET, SO_RCVBUFFORCE, RECV_BUFFER_BYTES)
            .is_err()
        {
            // Best effort: the default still works on an idle machine.
            let _ = sock.set_socket_option_int(SOL_SOCKET, SO_RCVBUF, RECV_BUFFER_BYTES);
        }
        Ok(())
    }

    /// A socket that only transmits (CAN FD ones too when `fd`): it accepts no frames, so
    /// its receive queue cannot fill up with traffic nobody reads.
    pub fn open_transmit_only(iface: &str, fd: bool) -> io::Result<Self> {
        let port = if fd {
            Self::open_fd(iface)?
        } else {
            Self::open(iface)?
        };
        match &port.sock {
            Sock::Classic(s) => s.set_filter_drop_all()?,
            Sock::Fd(s) => s.set_filter_drop_all()?,
        }
        Ok(port)
    }

    /// Writes `frame`, retrying while the interface's queue is full.
    fn write(&self, frame: &FdFrame) -> io::Result<()> {
        let unrepresentable =
            || io::Error::new(io::ErrorKind::InvalidInput, "frame not representable");
        let classic = || CanFrame::new(frame.id(), frame.data()).ok_or_else(unrepresentable);
        match &self.sock {
            Sock::Classic(_) if frame.is_fd() => Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "a CAN FD frame on a classic socket",
            )),
            Sock::Classic(s) => s.write_frame(&classic()?),
            Sock::Fd(s) if frame.is_fd() => {
                let f = CanFdFrame::new(frame.id(), frame.data()).ok_or_else(unrepresentable)?;
                s.write_frame(&f)
            }
            Sock::Fd(s) => s.write_frame(&classic()?),
        }
    }

    /// Reads one frame and its time stamp.
    fn read(&self) -> io::Result<(Option<FdFrame>, SystemTime)> {
        match &self.sock {
            Sock::Classic(s) => {
                let (frame, at) = s.read_frame_with_timestamp()?;
                let f = match frame {
                    CanFrame::Remote(r) => FdFrame::new_remote(r.id(), r.dlc()),
                    other => FdFrame::new(other.id(), other.data()),
                };
                Ok((f, at))
            }
            Sock::Fd(s) => {
                let (frame, at) = s.read_frame_with_timestamp()?;
                let f = match frame {
                    CanAnyFrame::Remote(r) => FdFrame::new_remote(r.id(), r.dlc()),
                    CanAnyFrame::Fd(f) => FdFrame::new_fd(f.id(), f.data()),
                    other => FdFrame::new(other.id(), other.data()),
                };
                Ok((f, at))
            }
        }
    }

    fn set_read_timeout(&self, t: Duration) -> io::Result<()> {
        match &self.sock {
            Sock::Classic(s) => s.set_read_timeout(t),
            Sock::Fd(s) => s.set_read_timeout(t),
        }
    }
}

/// The MTU of a CAN FD interface (`struct canfd_frame`).
const CANFD_MTU: u32 = 72;

impl fmt::Debug for SocketCanPort {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SocketCanPort").finish_non_exhaustive()
    }
}

impl CanPort for SocketCanPort {
    fn transmit(&mut self, frame: &FdFrame) -> io::Result<()> {
        let mut tries = 0;
        loop {
            match self.write(frame) {
                Ok(()) => return Ok(()),
                Err(e) if e.raw_os_error() == Some(ENOBUFS) && tries < TX_RETRIES => {
                    tries += 1;
                    std::thread::sleep(Duration::from_millis(1));
                }
                Err(e) => return Err(e),
            }
        }
    }

    fn receive(&mut self, timeout: Duration) -> io::Result<Option<(FdFrame, SystemTime)>> {
        // SO_RCVTIMEO of zero means "block forever"; a microsecond is the shortest wait.
        let t = timeout.max(Duration::from_micros(1));
        if self.timeout != Some(t) {
            self.set_read_timeout(t)?;
            self.timeout = Some(t);
        }
        match self.read() {
            Ok((frame, at)) => Ok(frame.map(|f| (f, at))),
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                Ok(None)
            }
            Err(e) => Err(e),
        }
    }

    fn hear_only(&mut self, sa: u8) -> io::Result<()> {
        // Extended frames whose low byte, the J1939 source address, is `sa`.
        let filter = (CAN_EFF_FLAG | u32::from(sa), CAN_EFF_FLAG | 0xFF);
        match &self.sock {
            Sock::Classic(s) => s.set_filters(&[filter]),
            Sock::Fd(s) => s.set_filters(&[filter]),
        }
    }
}

/// The flag of an extended (29-bit) identifier in a SocketCAN `can_id` (linux/can.h).
const CAN_EFF_FLAG: u32 = 0x8000_0000;

/// Why frames on `iface` may arrive out of order, if they may: a virtual CAN interface
/// hands each frame to the sending CPU's receive backlog, so on a multi-core host without
/// receive packet steering a frame can overtake an earlier one of the same sender (see
/// docs/can.md). `None` for one CPU, steering set, or an interface without the file (a
/// real controller's driver keeps its own order).
pub fn order_warning(iface: &str) -> Option<String> {
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    let path = format!("/sys/class/net/{iface}/queues/rx-0/rps_cpus");
    let mask = std::fs::read_to_string(&path).ok()?;
    steering_warning(iface, cpus, &path, &mask)
}

/// [`order_warning`] on what it read: `mask` is the hexadecimal CPU mask of `path`.
fn steering_warning(iface: &str, cpus: usize, path: &str, mask: &str) -> Option<String> {
    let unsteered = mask.trim().chars().all(|c| matches!(c, '0' | ','));
    (cpus > 1 && unsteered).then(|| {
        format!(
            "{iface}: {cpus} CPUs and no receive packet steering ({path} is {}); frames may \
             be delivered out of order and refused (OutOfSequence). As root: \
             echo 1 > {path}",
            mask.trim()
        )
    })
}

/// Linux's ENOBUFS (no `ErrorKind` of std names it).
const ENOBUFS: i32 = 105;

type Queues = Vec<VecDeque<(FdFrame, SystemTime)>>;

/// Frames a hub port holds for its reader before it overruns. A CAN controller's receive
/// FIFO (and a SocketCAN socket's buffer) is bounded the same way: a reader that stops
/// reading — a vehicle that left the world — loses frames, and memory stays bounded.
pub const HUB_QUEUE: usize = 4096;

/// An in-process broadcast medium for CAN frames: every frame a port transmits is queued,
/// with the time it was sent, at every other port (CAN's broadcast, no own echo).
#[derive(Debug, Clone, Default)]
pub struct Hub {
    inner: Arc<(Mutex<Queues>, Condvar)>,
}

impl Hub {
    /// An empty hub.
    pub fn new() -> Self {
        Self::default()
    }

    /// A new port on the hub.
    pub fn port(&self) -> HubPort {
        let index = match self.inner.0.lock() {
            Ok(mut q) => {
                q.push(VecDeque::new());
                q.len() - 1
            }
            // A poisoned hub delivers nothing; its ports report the error on use.
            Err(_) => usize::MAX,
        };
        HubPort {
            hub: self.inner.clone(),
            index,
        }
    }
}

/// A port on a [`Hub`].
#[derive(Debug)]
pub struct HubPort {
    hub: Arc<(Mutex<Queues>, Condvar)>,
    index: usize,
}

fn poisoned<T>(_: T) -> io::Error {
    io::Error::other("in-process CAN hub poisoned by a panicked task")
}

impl CanPort for HubPort {
    fn transmit(&mut self, frame: &FdFrame) -> io::Result<()> {
        let (lock, cv) = &*self.hub;
        let mut queues = lock.lock().map_err(poisoned)?;
        let now = SystemTime::now();
        for (i, q) in queues.iter_mut().enumerate() {
            // On overrun the new frame is lost, as in a controller whose FIFO is full.
            if i != self.index && q.len() < HUB_QUEUE {
                q.push_back((*frame, now));
            }
        }
        cv.notify_all();
        Ok(())
    }

    fn receive(&mut self, timeout: Duration) -> io::Result<Option<(FdFrame, SystemTime)>> {
        let (lock, cv) = &*self.hub;
        let deadline = WallClock::now() + timeout;
        let mut queues = lock.lock().map_err(poisoned)?;
        loop {
            let q = queues
                .get_mut(self.index)
                .ok_or_else(|| io::Error::other("port not on its hub"))?;
            if let Some(f) = q.pop_front() {
                return Ok(Some(f));
            }
            let left = deadline.saturating_duration_since(WallClock::now());
            if left.is_zero() {
                return Ok(None);
            }
            queues = cv.wait_timeout(queues, left).map_err(poisoned)?.0;
        }
    }
}

/// Why a message could not go over CAN.
#[derive(Debug)]
pub enum CanError {
    /// The port failed (socket error).
    Io(io::Error),
    /// A value does not fit its field (can-gateway's encoder refused it).
    Encode(EncodeError),
    /// A vehicle id is not a CAN source address below the clock's (0–0xEF).
    BadAddress(u16),
    /// The message kind has no CAN mapping yet.
    Unmapped(&'static str),
    /// An authenticated fleet has no key for this node's address.
    NoKey(u8),
}

impl fmt::Display for CanError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io(e) => write!(f, "CAN port: {e}"),
            Self::Encode(e) => write!(f, "CAN encoding: {e:?}"),
            Self::BadAddress(id) => write!(
                f,
                "vehicle id {id} is not a CAN source address (ids 0..={} on CAN)",
                CLOCK_ADDRESS - 1
            ),
            Self::Unmapped(what) => write!(f, "{what} cannot go over CAN yet"),
            Self::NoKey(sa) => write!(f, "no key for node {sa:#04x} in an authenticated fleet"),
        }
    }
}

impl std::error::Error for CanError {}

impl From<io::Error> for CanError {
    fn from(e: io::Error) -> Self {
        Self::Io(e)
    }
}

impl From<CanError> for BusError {
    fn from(e: CanError) -> Self {
        BusError::Transport(e.to_string())
    }
}

/// What a node's CAN traffic amounted to.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct CanStats {
    /// Frames transmitted.
    pub frames_sent: u64,
    /// Frames received.
    pub frames_received: u64,
    /// Whole, verified messages received.
    pub messages_received: u64,
    /// Frames rejected by the reassembler, by reason (`Crc`, `Duplicate`, `Stale`, …).
    pub rejected: BTreeMap<String, u64>,
}

impl CanStats {
    /// Adds `o`'s counts.
    pub fn add(&mut self, o: &CanStats) {
        self.frames_sent += o.frames_sent;
        self.frames_received += o.frames_received;
        self.messages_received += o.messages_received;
        for (k, v) in &o.rejected {
            *self.rejected.entry(k.clone()).or_default() += v;
        }
    }

    /// Frames rejected for any reason.
    pub fn rejected_total(&self) -> u64 {
        self.rejected.values().sum()
    }
}

/// Vehicle `id`'s CAN source address: the id itself, below the clock's and manager's.
pub fn vehicle_address(id: u16) -> Result<u8, CanError> {
    match u8::try_from(id) {
        Ok(sa) if sa < CLOCK_ADDRESS => Ok(sa),
        _ => Err(CanError::BadAddress(id)),
    }
}

/// What one read from a port gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Polled {
    /// No frame came in time.
    Nothing,
    /// A frame that completed no message (a part, or rejected: counted in the stats).
    Frame,
    /// A frame that completed a verified message, with the frame's receive time stamp and
    /// its sender's source address.
    Message(wire::Message<f64>, SystemTime, u8),
}

/// Keys of every address a fleet may use (one per source address).
pub const KEY_SLOTS: usize = 256;
/// A fleet's keys, shared by its nodes.
pub type Keys = KeyStore<KEY_SLOTS>;

/// The public master key of simulations: `--auth` derives every node's key from it. It
/// is in this source, so it protects nothing outside a simulation; a fleet that must
/// keep secrets takes a key file (`--keys`).
pub const SIMULATION_MASTER: Key = Key(*b"host-sim master!");

/// Every address's key derived from a simulation's `master` key
/// ([`can_gateway::secoc::derive_key`]): for simulations only, where every node is ours.
pub fn simulation_keys(master: &Key) -> Keys {
    let mut keys = Keys::new();
    for sa in 0..=u8::MAX {
        // 256 slots hold every address: the insert cannot fail.
        let _ = keys.insert(sa, derive_key(master, sa));
    }
    keys
}

/// A node's authentication state: the fleet's keys, its own freshness values
/// and what it accepted from each sender.
struct Security {
    keys: Arc<Keys>,
    tx: FreshnessTx,
    rx: FreshnessRx<REASSEMBLY_SLOTS>,
}

/// One node on a CAN medium: the sender address, a port, an alive counter per message
/// kind, and a reassembler for what others send; with keys, every message it sends
/// carries an authenticator and every message it accepts has one that verifies.
pub struct CanNode<P> {
    sa: u8,
    port: P,
    counters: [u8; 16],
    reassembler: Box<Reassembler<REASSEMBLY_SLOTS>>,
    stats: CanStats,
    security: Option<Box<Security>>,
    /// The node's clock: freshness of what it sends, the centre of its acceptance window,
    /// and the reference from which the wire's 32-bit times are restored.
    now: Instant,
    /// It sends each message as one CAN FD frame.
    fd: bool,
    /// It encodes and decodes in `f32` (as the MCU does), else `f64`.
    f32: bool,
    /// The attack experiment's oracle: what it sends is recorded there, and what it
    /// accepts is checked against it (never by the node itself).
    ledger: Option<Arc<super::ledger::Ledger>>,
}

impl<P> fmt::Debug for CanNode<P> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("CanNode")
            .field("sa", &self.sa)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl<P: CanPort> CanNode<P> {
    /// Node `sa` on `port`.
    pub fn new(sa: u8, port: P) -> Self {
        Self {
            sa,
            port,
            counters: [0; 16],
            reassembler: Box::default(),
            stats: CanStats::default(),
            security: None,
            now: Instant::EPOCH,
            fd: false,
            f32: false,
            ledger: None,
        }
    }

    /// This node, a genuine one, telling `ledger` what it sends and accepts.
    pub fn with_ledger(mut self, ledger: Arc<super::ledger::Ledger>) -> Self {
        self.ledger = Some(ledger);
        self
    }

    /// This node, sending each message (with its authenticator, if any) as one CAN FD
    /// frame; it receives both kinds.
    pub fn with_fd(mut self) -> Self {
        self.fd = true;
        self
    }

    /// This node, encoding and decoding in `precision` (`f32`: as the MCU does; the
    /// simulator's messages are rounded to `f32` before encoding and widened after
    /// decoding).
    pub fn with_precision(mut self, precision: crate::world::precision::Precision) -> Self {
        self.f32 = precision == crate::world::precision::Precision::F32;
        self
    }

    /// This node, authenticating with `keys` (its own among them).
    pub fn with_keys(mut self, keys: Arc<Keys>) -> Self {
        self.security = Some(Box::new(Security {
            keys,
            tx: FreshnessTx::new(),
            rx: FreshnessRx::default(),
        }));
        self
    }

    /// Sets the node's clock.
    pub fn set_time(&mut self, now: Instant) {
        self.now = now;
    }

    /// The node of vehicle `id` (its CAN source address is its id).
    pub fn vehicle(id: u16, port: P) -> Result<Self, CanError> {
        Ok(Self::new(vehicle_address(id)?, port))
    }

    /// From now on the node hears only the fleet's clock (its SYNC ticks), where the
    /// medium filters ([`CanPort::hear_only`]): for a vehicle that has left the world,
    /// which plans nothing, so that a kernel under TCG stops waking its task for every
    /// frame of the fleet (a fifth of the corridor's deliveries on vcan0: 6.39 M → 5.11 M).
    pub fn hear_only_clock(&mut self) -> Result<(), CanError> {
        self.port.hear_only(CLOCK_ADDRESS).map_err(CanError::Io)
    }

    /// What the node's traffic amounted to.
    pub fn stats(&self) -> &CanStats {
        &self.stats
    }

    /// Encodes and transmits `msg` (one alive counter per kind, mod 16), in the node's
    /// precision.
    pub fn send_wire(&mut self, msg: &wire::Message<f64>) -> Result<(), CanError> {
        if self.f32 {
            self.send_as(&wire32(msg))
        } else {
            self.send_as(msg)
        }
    }

    fn send_as<F: planner_core::Real>(&mut self, msg: &wire::Message<F>) -> Result<(), CanError> {
        let k = msg.kind() as usize;
        let counter = self.counters.get(k).copied().unwrap_or(0);
        let (sa, fd) = (self.sa, self.fd);
        match &mut self.security {
            None if fd => {
                let frame: FdFrame = encode_fd(msg, sa, counter).map_err(CanError::Encode)?;
                self.transmit_all(&[frame])?;
            }
            None => {
                let frames: Frames<PlainFrame> =
                    encode(msg, sa, counter).map_err(CanError::Encode)?;
                self.transmit_all(&frames)?;
            }
            Some(s) => {
                let key = *s.keys.get(sa).ok_or(CanError::NoKey(sa))?;
                let fv = s.tx.next(msg.kind() as u8, self.now.as_millis());
                if fd {
                    let frame: FdFrame =
                        encode_fd_secured(msg, sa, counter, &key, fv).map_err(CanError::Encode)?;
                    self.transmit_all(&[frame])?;
                } else {
                    let frames: SecuredFrames<PlainFrame> =
                        encode_secured(msg, sa, counter, &key, fv).map_err(CanError::Encode)?;
                    self.transmit_all(&frames)?;
                }
            }
        }
        if let Some(c) = self.counters.get_mut(k) {
            *c = (counter + 1) & 0x0F;
        }
        Ok(())
    }

    fn transmit_all<Fr: Into<FdFrame> + Copy>(&mut self, frames: &[Fr]) -> Result<(), CanError> {
        for f in frames {
            let frame: FdFrame = (*f).into();
            // Recorded first: a receiver may check the frame before `transmit` returns.
            if let Some(l) = &self.ledger {
                l.sent(&frame);
            }
            self.port.transmit(&frame)?;
            self.stats.frames_sent += 1;
        }
        Ok(())
    }

    /// Transmits one of the simulator's messages, mapped by `map` (a crossing report
    /// with the vehicle's `arrival` in A_C).
    pub fn send(
        &mut self,
        msg: &Message,
        map: &WireMap<'_>,
        arrival: Instant,
    ) -> Result<(), CanError> {
        self.send_wire(&map.to_wire(msg, arrival)?)
    }

    /// Reads every frame already queued (at most [`DRAIN_LIMIT`]), handing each verified
    /// message and its sender's address to `each`.
    pub fn drain(&mut self, mut each: impl FnMut(wire::Message<f64>, u8)) -> Result<(), CanError> {
        for _ in 0..DRAIN_LIMIT {
            match self.poll(Duration::ZERO)? {
                Polled::Nothing => break,
                Polled::Frame => {}
                Polled::Message(m, _, sa) => each(m, sa),
            }
        }
        Ok(())
    }

    /// Reads at most one frame, waiting up to `timeout`, and feeds it to the reassembler.
    pub fn poll(&mut self, timeout: Duration) -> Result<Polled, CanError> {
        let Some((frame, at)) = self.port.receive(timeout)? else {
            return Ok(Polled::Nothing);
        };
        self.stats.frames_received += 1;
        let pushed = if self.f32 {
            self.push_as::<f32>(&frame).map(|m| m.map(|m| wire64(&m)))
        } else {
            self.push_as::<f64>(&frame)
        };
        match pushed {
            Ok(Some(m)) => {
                self.stats.messages_received += 1;
                if let Some(l) = &self.ledger {
                    l.accepted(&frame, self.sa);
                }
                let sa = match frame.id() {
                    embedded_can::Id::Extended(x) => (x.as_raw() & 0xFF) as u8,
                    embedded_can::Id::Standard(_) => 0,
                };
                Ok(Polled::Message(m, at, sa))
            }
            Ok(None) => Ok(Polled::Frame),
            Err(e) => {
                *self.stats.rejected.entry(reason(e)).or_default() += 1;
                Ok(Polled::Frame)
            }
        }
    }
}

impl<P> CanNode<P> {
    /// Pushes `frame` into the reassembler, decoding in `F`.
    fn push_as<F: planner_core::Real>(
        &mut self,
        frame: &FdFrame,
    ) -> Result<Option<wire::Message<F>>, DecodeError> {
        match &mut self.security {
            None => self.reassembler.push::<F, _>(frame, self.now),
            Some(s) => {
                let v = Verifier {
                    keys: &s.keys,
                    freshness: &mut s.rx,
                };
                self.reassembler.push_secured(frame, self.now, v)
            }
        }
    }
}

/// A message rounded to `f32` (what an MCU's codec is handed).
pub fn wire32(m: &wire::Message<f64>) -> wire::Message<f32> {
    m.map(|x| x as f32)
}

/// A message widened to `f64` (exact).
pub fn wire64(m: &wire::Message<f32>) -> wire::Message<f64> {
    m.map(f64::from)
}

fn reason(e: DecodeError) -> String {
    match e {
        DecodeError::OutOfRange(f) => format!("OutOfRange({f:?})"),
        DecodeError::UnknownKind(_) => "UnknownKind".into(),
        DecodeError::Auth(a) => format!("Auth({a:?})"),
        other => format!("{other:?}"),
    }
}

/// How the simulator's messages travel as can-gateway's in one world (see the module
/// docs): the paper's kinds on a straight road or at a single junction, the kinds that
/// carry the place in a network.
#[derive(Debug, Clone, Copy)]
pub struct WireMap<'a> {
    net: &'a Network,
    network: bool,
    /// The longest vehicle expected (m): a request that declares no length is taken at it.
    longest_m: f64,
}

impl<'a> WireMap<'a> {
    /// The mapping for `net`, its vehicles Table I's cars.
    pub fn new(net: &'a Network) -> Self {
        let single_road = net.junctions.is_empty() && net.segments.len() <= 1;
        let single_junction = net.junctions.len() == 1 && net.segments.is_empty();
        Self {
            net,
            network: !(single_road || single_junction),
            longest_m: LENGTH_M,
        }
    }

    /// The mapping for a world of `fleet`: a request that declares no length (a plain
    /// request, kind 2, cannot) is taken at the fleet's longest vehicle.
    pub fn for_fleet(mut self, fleet: Fleet) -> Self {
        self.longest_m = fleet.longest_m;
        self
    }

    /// `true` if the world is a network (the kinds with places are used).
    pub fn is_network(&self) -> bool {
        self.network
    }

    /// The source address of junction `j`'s manager.
    pub fn manager_address(&self, j: usize) -> Result<u8, CanError> {
        wire::manager_address(j).ok_or(CanError::Unmapped("more junctions than manager addresses"))
    }

    /// The simulator's message as can-gateway's; a crossing report carries the vehicle's
    /// `arrival` in A_C by its clock (the manager registers arrivals by its own clock
    /// either way, so no vehicle can move itself up the queue), and its length and braking
    /// limit where it travels as a junction request (kind 8: in a network, and at a single
    /// junction whose fleet has vehicles longer than a car). A plain request (kind 2, a
    /// single junction of cars) has no room for them: its receivers take the fleet's
    /// longest vehicle, as a wall.
    pub fn to_wire(&self, msg: &Message, arrival: Instant) -> Result<wire::Message<f64>, CanError> {
        let junction = |j: usize| {
            u8::try_from(j).map_err(|_| CanError::Unmapped("a junction index above 255"))
        };
        Ok(match *msg {
            Message::State { state, segment } if self.network => wire::Message::Located {
                segment: u16::try_from(segment)
                    .map_err(|_| CanError::Unmapped("a segment index above 65,535"))?,
                state,
            },
            Message::State { state, .. } => wire::Message::State(state),
            Message::Crossing {
                report,
                junction: j,
                ..
            } => {
                let request = self.request(&report, arrival, j)?;
                // With trucks about, every request declares its body (kind 8 at a single
                // junction too): one taken at the longest would have its front 6 m into
                // A_S, for the manager, while it waits at the line (a car at a truck's
                // length stalled PIPE in trucks-intersection.toml over CAN).
                if self.network || self.longest_m > LENGTH_M {
                    wire::Message::JunctionRequest {
                        junction: junction(j)?,
                        request,
                    }
                } else if report.length > self.longest_m {
                    // Its receivers would take it at the longest they expect: shorter.
                    return Err(CanError::Unmapped(
                        "a plain request for a vehicle longer than the fleet's longest",
                    ));
                } else {
                    wire::Message::Request(request)
                }
            }
            Message::Left {
                id,
                at,
                junction: j,
            } if self.network => wire::Message::JunctionExit {
                junction: junction(j)?,
                id,
                at,
            },
            Message::Left { id, at, .. } => wire::Message::Exit { id, at },
            Message::Gone { id, at } if self.network => wire::Message::JunctionExit {
                junction: NETWORK_EXIT,
                id,
                at,
            },
            Message::Gone { .. } => {
                return Err(CanError::Unmapped(
                    "leaving a network on a map without segments",
                ))
            }
            Message::Grant { id, until, .. } => wire::Message::Grant { id, until },
        })
    }

    fn request(
        &self,
        r: &CrossingReport<f64>,
        arrival: Instant,
        j: usize,
    ) -> Result<wire::Request<f64>, CanError> {
        let layout = &self
            .net
            .junctions
            .get(j)
            .ok_or(CanError::Unmapped("a junction the network does not have"))?
            .layout;
        let route = layout
            .route(usize::from(r.route))
            .ok_or(CanError::Unmapped("a route the layout does not have"))?;
        let track = |t: Track| wire::TrackWire {
            heading: t.heading,
            lane: t.lane,
        };
        Ok(wire::Request {
            id: r.id,
            inlet: track(route.inlet),
            outlet: track(route.outlet),
            arrival,
            s: r.s,
            v: r.v,
            brake: r.brake,
            length: BodyLength::from_m(r.length),
        })
    }

    /// can-gateway's message from source address `sa`, heard in the period that began at
    /// `now` (the receiver's clock), as the simulator's, if it is one the vehicles and
    /// managers act on (a grant's junction is its sender's). A request carries no send
    /// time of its own: in the lock-step fleet every message of a period is sent at its
    /// start, so that is its stamp.
    pub fn heard(&self, msg: &wire::Message<f64>, sa: u8, now: Instant) -> Option<Message> {
        let m = self.from_wire(msg, sa)?;
        Some(match m {
            Message::Crossing {
                report, junction, ..
            } => Message::Crossing {
                report,
                stamp: now,
                junction,
            },
            other => other,
        })
    }

    /// can-gateway's message from source address `sa` as the simulator's, if it is one the
    /// vehicles and managers act on (a grant's junction is its sender's); a crossing
    /// report's stamp is the request's arrival time (see [`WireMap::heard`]).
    pub fn from_wire(&self, msg: &wire::Message<f64>, sa: u8) -> Option<Message> {
        match *msg {
            wire::Message::State(state) => Some(Message::State { state, segment: 0 }),
            wire::Message::Located { segment, state } => Some(Message::State {
                state,
                segment: usize::from(segment),
            }),
            wire::Message::Request(q) => self.report(&q, 0),
            wire::Message::JunctionRequest { junction, request } => {
                self.report(&request, usize::from(junction))
            }
            wire::Message::Exit { id, at } => Some(Message::Left {
                id,
                at,
                junction: 0,
            }),
            wire::Message::JunctionExit {
                junction: NETWORK_EXIT,
                id,
                at,
            } => Some(Message::Gone { id, at }),
            wire::Message::JunctionExit { junction, id, at } => Some(Message::Left {
                id,
                at,
                junction: usize::from(junction),
            }),
            wire::Message::Grant { id, until } => Some(Message::Grant {
                junction: usize::from(sa.checked_sub(wire::MANAGER_ADDRESS)?),
                id,
                until,
            }),
            // Revocations and ticks are handled apart; kinds this fleet does not use
            // carry nothing for a world view.
            _ => None,
        }
    }

    /// A `Request` at junction `j` as a crossing report, if its (inlet, outlet) is a
    /// route of the junction's layout (each route has its own pair).
    fn report(&self, q: &wire::Request<f64>, j: usize) -> Option<Message> {
        let layout = &self.net.junctions.get(j)?.layout;
        let same = |a: Track, b: wire::TrackWire| a.heading == b.heading && a.lane == b.lane;
        let route = layout
            .routes
            .iter()
            .position(|r| same(r.inlet, q.inlet) && same(r.outlet, q.outlet))?;
        Some(Message::Crossing {
            report: CrossingReport {
                id: q.id,
                route: u8::try_from(route).ok()?,
                s: q.s,
                v: q.v,
                length: q.length.map_or(self.longest_m, BodyLength::m),
                brake: q.brake,
            },
            stamp: q.arrival,
            junction: j,
        })
    }
}

/// Frames one drain of a node reads at most (a bound on the loop; a period carries
/// one state per vehicle, of at most [`can_gateway::wire::MAX_FRAMES`] frames).
pub const DRAIN_LIMIT: usize =
    4 * can_gateway::wire::MAX_FRAMES * crate::scenario::road::MAX_VEHICLES;

/// The message-level [`Bus`] over CAN: one [`CanNode`] per vehicle and per junction
/// manager, each on its own port (its own SocketCAN socket, or hub port). A message is
/// delivered when its frames have reached the receiver's socket; the receive time given
/// to the planner is the period's time (the simulator is in lock-step), the kernel's
/// stamps measure the latency.
#[derive(Debug)]
pub struct CanBus<P> {
    nodes: Vec<(u16, CanNode<P>)>,
    net: Network,
    /// Every node's clock (the bus is driven in the world's time).
    clock: Clock,
    /// The world's fleet (what an undeclared length is taken at).
    fleet: Fleet,
}

impl<P: CanPort> CanBus<P> {
    /// A bus for the world on `net` with a node for each of `ids` (vehicles; and
    /// managers, whose nodes are `world::junction::manager_node(j)`), on the port `open`
    /// gives it; the nodes' clocks read `clock`.
    pub fn new(
        ids: &[u16],
        net: &Network,
        clock: Clock,
        mut open: impl FnMut(u16) -> io::Result<P>,
    ) -> Result<Self, CanError> {
        let map = WireMap::new(net);
        let mut nodes = Vec::with_capacity(ids.len());
        for &id in ids {
            let port = open(id)?;
            let node = match id.checked_sub(0xFF00) {
                Some(j) => CanNode::new(map.manager_address(usize::from(j))?, port),
                None => CanNode::vehicle(id, port)?,
            };
            nodes.push((id, node));
        }
        Ok(Self {
            nodes,
            net: net.clone(),
            clock,
            fleet: Fleet::default(),
        })
    }

    /// The bus of a world of `fleet` (with trucks: a plain request, which declares no
    /// length, is taken at the longest; [`WireMap::for_fleet`]).
    pub fn for_fleet(mut self, fleet: Fleet) -> Self {
        self.fleet = fleet;
        self
    }

    /// Every node's traffic, summed.
    pub fn stats(&self) -> CanStats {
        let mut s = CanStats::default();
        for (_, n) in &self.nodes {
            s.add(n.stats());
        }
        s
    }
}

impl<P: CanPort> Bus for CanBus<P> {
    fn send(&mut self, from: u16, msg: &Message, now: f64) -> Result<(), BusError> {
        let map = WireMap::new(&self.net).for_fleet(self.fleet);
        let at = self.clock.at_secs(now);
        let node = node_mut(&mut self.nodes, from)?;
        node.set_time(at);
        Ok(node.send(msg, &map, at)?)
    }

    fn attach(&mut self, node: u16) -> Result<(), BusError> {
        // A CAN node needs a port of its own, opened before anyone transmits.
        node_mut(&mut self.nodes, node).map(|_| ())
    }

    fn detach(&mut self, _node: u16) {
        // Its port stays open: a closed world brings the vehicle back, and a port nobody
        // reads is bounded (HUB_QUEUE; a socket's receive buffer) like a real controller.
    }

    fn receive(&mut self, node: u16, now: f64, out: &mut Vec<Received>) -> Result<(), BusError> {
        let map = WireMap::new(&self.net).for_fleet(self.fleet);
        let at = self.clock.at_secs(now);
        let node = node_mut(&mut self.nodes, node)?;
        node.set_time(at);
        node.drain(|m, sa| {
            if let Some(msg) = map.heard(&m, sa, at) {
                out.push(Received { msg, at: now });
            }
        })?;
        Ok(())
    }
}

fn node_mut<P>(nodes: &mut [(u16, CanNode<P>)], id: u16) -> Result<&mut CanNode<P>, BusError> {
    nodes
        .iter_mut()
        .find(|(i, _)| *i == id)
        .map(|(_, n)| n)
        .ok_or(BusError::UnknownNode(id))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unsteered_multi_core_vcan_is_reported() {
        let p = "/sys/class/net/vcan0/queues/rx-0/rps_cpus";
        let w = steering_warning("vcan0", 2, p, "0\n").expect("two CPUs, no steering");
        assert!(
            w.contains("echo 1 > /sys/class/net/vcan0/queues/rx-0/rps_cpus"),
            "{w}"
        );
        assert!(steering_warning("vcan0", 2, p, "00000000,00000000\n").is_some());
        assert_eq!(steering_warning("vcan0", 2, p, "1\n"), None);
        assert_eq!(steering_warning("vcan0", 2, p, "00000000,00000001\n"), None);
        assert_eq!(steering_warning("vcan0", 1, p, "0\n"), None);
        assert_eq!(order_warning("no-such-interface"), None);
    }
}
