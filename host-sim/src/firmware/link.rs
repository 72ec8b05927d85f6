//! One firmware image in QEMU and its UART as a serial-line CAN link: QEMU listens on a
//! local TCP port for its first `-serial` device (the board's UART 0) and waits for this
//! side before it starts the core, so no byte is lost; frames go out as SLCAN lines
//! ([`can_gateway::slcan`]) and come back through can-gateway's reassembler, every CRC,
//! alive counter and sender checked.
//!
//! Every byte that crosses the line is kept, each way in a file beside the log
//! ([`Link::serial`]): the bytes the image received are all its inputs, so replaying them
//! into the same node on the host (`tests/examples/sil_mirror.rs`) must give the bytes it
//! sent, which is how its commands in the loop are compared with the host planner's.

use super::FirmwareError;
use can_gateway::slcan::{self, Line, LineBuffer, MAX_LINE};
use can_gateway::wire::{split_id, Message, MessageKind};
use can_gateway::{encode, Frames, Instant, PlainFrame, Reassembler};
use embedded_can::{Frame, Id};
use std::io::{Read, Write};
use std::net::{Ipv4Addr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// How long the world waits for an answer: far beyond a period's work in QEMU (a few
/// milliseconds of host time, a fraction of a second for a dense road's frames), and
/// beyond a machine shared with many other QEMUs (a run with nine of them on two cores
/// once waited more than 20 s); short enough that a hung image stops the run.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(60);
/// How long QEMU may take to load the image and open its socket.
const START_TIMEOUT: Duration = Duration::from_secs(20);

/// A QEMU machine the firmware is built for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Board {
    /// MPS2 AN386, Cortex-M4F.
    An386,
    /// MPS2 AN500, Cortex-M7.
    An500,
    /// MPS2 AN505, Cortex-M33.
    An505,
}

impl Board {
    /// The board of `run.sh`'s name (`an386`, `an500`, `an505`).
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "an386" => Some(Self::An386),
            "an500" => Some(Self::An500),
            "an505" => Some(Self::An505),
            _ => None,
        }
    }

    /// QEMU's `-machine` and `-cpu`.
    pub fn qemu(self) -> (&'static str, &'static str) {
        match self {
            Self::An386 => ("mps2-an386", "cortex-m4"),
            Self::An500 => ("mps2-an500", "cortex-m7"),
            Self::An505 => ("mps2-an505", "cortex-m33"),
        }
    }
}

/// A running image and its serial line.
pub struct Link {
    child: Child,
    stream: TcpStream,
    /// Bytes read from the line and not yet taken, and where the next one is.
    inbox: (Vec<u8>, usize),
    lines: LineBuffer,
    rx: Box<Reassembler<4>>,
    /// The clock the reassembler restores stamps against (the world's).
    pub now: Instant,
    log: PathBuf,
    /// What the image received and what it sent, byte for byte.
    serial: Serial,
}

/// The two halves of a serial line's record.
struct Serial {
    to: std::io::BufWriter<std::fs::File>,
    from: std::io::BufWriter<std::fs::File>,
    paths: (PathBuf, PathBuf),
}

impl Serial {
    /// Records beside `log`: `<log>.rx.slcan` (into the image) and `.tx.slcan` (out of it).
    fn beside(log: &Path) -> Result<Self, FirmwareError> {
        let paths = (
            log.with_extension("rx.slcan"),
            log.with_extension("tx.slcan"),
        );
        let open = |p: &Path| {
            std::fs::File::create(p)
                .map(std::io::BufWriter::new)
                .map_err(|e| FirmwareError::Log(format!("{}: {e}", p.display())))
        };
        Ok(Self {
            to: open(&paths.0)?,
            from: open(&paths.1)?,
            paths,
        })
    }
}

impl Link {
    /// Starts `elf` on `board` under `-icount shift=3,sleep=off`, its semihosting output
    /// (the defmt log) into `log`, and opens its UART.
    pub fn start(elf: &Path, board: Board, log: &Path) -> Result<Self, FirmwareError> {
        let port = free_port()?;
        let out = std::fs::File::create(log)
            .map_err(|e| FirmwareError::Log(format!("{}: {e}", log.display())))?;
        let serial = Serial::beside(log)?;
        let (machine, cpu) = board.qemu();
        let mut qemu = Command::new("qemu-system-arm");
        qemu.args([
            "-machine",
            machine,
            "-cpu",
            cpu,
            "-nographic",
            "-monitor",
            "none",
        ])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-icount", "shift=3,sleep=off"])
        .arg("-serial")
        .arg(format!("tcp:127.0.0.1:{port},server=on,wait=on,nodelay=on"))
        .arg("-kernel")
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(out)
        .stderr(Stdio::null());
        super::affinity::confine(&mut qemu);
        let child = qemu
            .spawn()
            .map_err(|e| FirmwareError::Start(format!("qemu-system-arm: {e}")))?;
        let stream = connect(port)?;
        let mut link = Self {
            child,
            stream,
            inbox: (Vec::new(), 0),
            lines: LineBuffer::new(),
            rx: Box::default(),
            now: Instant::EPOCH,
            log: log.to_path_buf(),
            serial,
        };
        // As python-can and slcand open an adapter: bit rate, then open the channel.
        link.write(b"S6\rO\r")?;
        Ok(link)
    }

    /// The log file.
    pub fn log(&self) -> &Path {
        &self.log
    }

    /// The files of what the image received and what it sent (whole once it has ended).
    pub fn serial(&self) -> (&Path, &Path) {
        (&self.serial.paths.0, &self.serial.paths.1)
    }

    /// Writes `bytes` to the line, and to its record.
    fn write(&mut self, bytes: &[u8]) -> Result<(), FirmwareError> {
        self.serial.to.write_all(bytes)?;
        self.stream.write_all(bytes)?;
        Ok(())
    }

    /// Sends `m` from source address `sa` with alive counter `counter`.
    pub fn send(&mut self, m: &Message<f64>, sa: u8, counter: u8) -> Result<(), FirmwareError> {
        let frames: Frames<PlainFrame> = encode(m, sa, counter).map_err(FirmwareError::Encode)?;
        let mut bytes = Vec::with_capacity(frames.len() * (MAX_LINE + 1));
        let mut line = [0u8; MAX_LINE + 1];
        for f in &frames {
            let n = slcan::encode(f, &mut line).map_err(FirmwareError::Line)?;
            bytes.extend_from_slice(line.get(..n).unwrap_or(&[]));
        }
        self.write(&bytes)
    }

    /// The next whole message of `kind` from source address `sa` (others are dropped:
    /// the adapter's answers to commands, anything else).
    pub fn receive(&mut self, kind: MessageKind, sa: u8) -> Result<Message<f64>, FirmwareError> {
        loop {
            let byte = self.next_byte()?;
            let Some(Ok(Line::Frame(f))) = self.lines.push::<PlainFrame>(byte) else {
                continue;
            };
            let from = match f.id() {
                Id::Extended(e) => split_id(e.as_raw()),
                Id::Standard(_) => None,
            };
            if let Ok(Some(m)) = self.rx.push::<f64, _>(&f, self.now) {
                if m.kind() == kind && from.is_some_and(|(_, _, s)| s == sa) {
                    return Ok(m);
                }
            }
        }
    }

    /// The next byte from the line, reading more when none is left.
    fn next_byte(&mut self) -> Result<u8, FirmwareError> {
        let (buf, pos) = &mut self.inbox;
        if let Some(&b) = buf.get(*pos) {
            *pos += 1;
            return Ok(b);
        }
        buf.resize(4096, 0);
        let n = self.stream.read(buf).map_err(|e| match e.kind() {
            std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut => {
                FirmwareError::Timeout("a message")
            }
            _ => FirmwareError::Io(e),
        })?;
        buf.truncate(n);
        self.serial.from.write_all(buf)?;
        *pos = 0;
        match buf.first() {
            Some(&b) => {
                *pos = 1;
                Ok(b)
            }
            None => Err(FirmwareError::Timeout(
                "a message: the firmware closed its line",
            )),
        }
    }

    /// Waits (at most `timeout`) for the image to exit; its status, if it did.
    pub fn wait(mut self, timeout: Duration) -> Option<i32> {
        self.flush();
        let deadline = std::time::Instant::now() + timeout;
        while std::time::Instant::now() < deadline {
            match self.child.try_wait() {
                Ok(Some(status)) => return status.code(),
                Ok(None) => std::thread::sleep(Duration::from_millis(20)),
                Err(_) => break,
            }
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
        None
    }
}

impl Link {
    /// Writes out what is kept of the line; a record that cannot be written is only
    /// incomplete (a mirror of it will say so), the run itself is not affected.
    fn flush(&mut self) {
        let _ = self.serial.to.flush();
        let _ = self.serial.from.flush();
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        self.flush();
        // A link dropped before `wait` (a failed run) takes its QEMU with it.
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// A local TCP port nobody listens on now.
fn free_port() -> Result<u16, FirmwareError> {
    let l = TcpListener::bind((Ipv4Addr::LOCALHOST, 0))?;
    Ok(l.local_addr()?.port())
}

/// Connects to QEMU's UART socket once QEMU listens on it; answers time out.
fn connect(port: u16) -> Result<TcpStream, FirmwareError> {
    let deadline = std::time::Instant::now() + START_TIMEOUT;
    loop {
        match TcpStream::connect((Ipv4Addr::LOCALHOST, port)) {
            Ok(s) => {
                // Each line is sent whole: no waiting for the last one's delayed ACK.
                s.set_nodelay(true)?;
                s.set_read_timeout(Some(ANSWER_TIMEOUT))?;
                return Ok(s);
            }
            Err(e) if std::time::Instant::now() >= deadline => {
                return Err(FirmwareError::Start(format!(
                    "its UART socket never opened: {e}"
                )))
            }
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
}
