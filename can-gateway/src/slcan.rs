//! Serial-line CAN (SLCAN, the Lawicel CAN232/CANUSB ASCII protocol): CAN frames as text
//! lines on a byte stream, as USB-CAN adapters speak it over their virtual serial port.
//! Linux's `slcand` attaches such a port as a SocketCAN interface, and python-can's
//! `slcan` interface opens it directly; the firmware speaks it over a UART, so that a
//! simulator, `slcand` or python-can can be the other end of the same link.
//!
//! A line is ASCII and ends in `\r` ([`CR`]):
//!
//! | line | meaning |
//! |---|---|
//! | `tiiiL<data>` | data frame, 11-bit id (3 hex digits), length `L` (0–8), `2·L` hex digits |
//! | `TiiiiiiiiL<data>` | data frame, 29-bit id (8 hex digits) |
//! | `riiiL`, `RiiiiiiiiL` | remote frame |
//! | `O`, `L`, `C` | open the channel, open it listen-only, close it |
//! | `Sn` | bit rate n (0: 10 kbit/s … 8: 1 Mbit/s) |
//! | `V`, `N`, `F` | version, serial number, status flags |
//! | `Zn` | timestamps off (0) or on (1) |
//!
//! An adapter with timestamps on appends four hex digits (milliseconds) to a received
//! frame; [`parse`] accepts and drops them. An adapter answers a command it accepted with
//! `\r` and one it refused with BEL ([`BELL`]). Only classic frames: SLCAN's CAN FD
//! extensions (`d`, `D`, `b`, `B`) are not read (they parse to [`SlcanError::Unknown`]).
//!
//! Everything here is `no_std` and allocation-free: [`encode`] writes into a caller's
//! buffer, [`LineBuffer`] gathers bytes into lines in a fixed array, and any byte sequence
//! gives either a line or a typed error, never a panic (fuzzed by the `slcan` target).

use embedded_can::{ExtendedId, Frame, Id, StandardId};

/// The end of every line.
pub const CR: u8 = b'\r';
/// An adapter's answer to a command it refused.
pub const BELL: u8 = 0x07;
/// The longest line this module reads or writes, without its `\r`: `T`, 8 id digits,
/// the length, 16 data digits and a 4-digit timestamp.
pub const MAX_LINE: usize = 1 + 8 + 1 + 16 + 4;

/// A command to the adapter (every line that is not a frame).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// `O`: open the channel.
    Open,
    /// `L`: open the channel listen-only.
    ListenOnly,
    /// `C`: close the channel.
    Close,
    /// `Sn`: bit rate setting n, 0–8.
    Bitrate(u8),
    /// `V`: hardware and software version.
    Version,
    /// `N`: serial number.
    SerialNumber,
    /// `F`: status flags.
    Status,
    /// `Zn`: timestamps on received frames.
    Timestamps(bool),
}

/// One line read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Line<F> {
    /// A data or remote frame.
    Frame(F),
    /// A command.
    Command(Command),
}

/// Why a line is not one this module reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum SlcanError {
    /// An empty line (a lone `\r`: adapters' keep-alive, answered with `\r`).
    Empty,
    /// A line longer than [`MAX_LINE`]; its bytes up to the next `\r` are dropped.
    TooLong,
    /// A first character this module does not read (e.g. an FD frame), as a byte.
    Unknown(u8),
    /// A character that should be a hex digit is not.
    NotHex,
    /// The data length is beyond 8, or the line has not the digits it announces.
    Length,
    /// An identifier beyond 11 bits (`t`, `r`) or 29 bits (`T`, `R`).
    Id,
    /// A command's argument is missing or out of range.
    Argument,
    /// [`encode`]'s buffer is shorter than the line, or the frame has more than 8 bytes.
    Buffer,
}

impl core::fmt::Display for SlcanError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SlcanError::Empty => f.write_str("empty SLCAN line"),
            SlcanError::TooLong => write!(f, "SLCAN line longer than {MAX_LINE} characters"),
            SlcanError::Unknown(c) => write!(f, "unknown SLCAN line type 0x{c:02x}"),
            SlcanError::NotHex => f.write_str("SLCAN line: not a hex digit"),
            SlcanError::Length => f.write_str("SLCAN frame: bad data length"),
            SlcanError::Id => f.write_str("SLCAN frame: identifier out of range"),
            SlcanError::Argument => f.write_str("SLCAN command: bad argument"),
            SlcanError::Buffer => f.write_str("SLCAN line does not fit the buffer"),
        }
    }
}

impl core::error::Error for SlcanError {}

const HEX: &[u8; 16] = b"0123456789ABCDEF";

fn hex_value(c: u8) -> Result<u32, SlcanError> {
    match c {
        b'0'..=b'9' => Ok(u32::from(c - b'0')),
        b'A'..=b'F' => Ok(u32::from(c - b'A' + 10)),
        b'a'..=b'f' => Ok(u32::from(c - b'a' + 10)),
        _ => Err(SlcanError::NotHex),
    }
}

/// The number written by the hex digits `digits` (at most 8).
fn hex(digits: &[u8]) -> Result<u32, SlcanError> {
    digits
        .iter()
        .try_fold(0u32, |n, &c| Ok(n << 4 | hex_value(c)?))
}

/// Writes `frame` as an SLCAN line, `\r` included, into `out`; the bytes written.
pub fn encode<F: Frame>(frame: &F, out: &mut [u8]) -> Result<usize, SlcanError> {
    let data = frame.data();
    let dlc = frame.dlc();
    if dlc > 8 || data.len() > 8 {
        return Err(SlcanError::Buffer);
    }
    let (kind, id, digits) = match (frame.id(), frame.is_remote_frame()) {
        (Id::Standard(s), false) => (b't', u32::from(s.as_raw()), 3),
        (Id::Extended(e), false) => (b'T', e.as_raw(), 8),
        (Id::Standard(s), true) => (b'r', u32::from(s.as_raw()), 3),
        (Id::Extended(e), true) => (b'R', e.as_raw(), 8),
    };
    let payload = if frame.is_remote_frame() {
        &[][..]
    } else {
        data
    };
    let len = 1 + digits + 1 + 2 * payload.len() + 1;
    let line = out.get_mut(..len).ok_or(SlcanError::Buffer)?;
    let nibble = |n: u32| HEX.get((n & 0xF) as usize).copied().unwrap_or(b'0');
    let mut w = 0;
    let mut put = |b: u8| {
        if let Some(slot) = line.get_mut(w) {
            *slot = b;
        }
        w += 1;
    };
    put(kind);
    for i in (0..digits).rev() {
        put(nibble(id >> (4 * i)));
    }
    put(nibble(dlc as u32));
    for &b in payload {
        put(nibble(u32::from(b >> 4)));
        put(nibble(u32::from(b)));
    }
    put(CR);
    Ok(len)
}

/// Reads one line, without its `\r`.
pub fn parse<F: Frame>(line: &[u8]) -> Result<Line<F>, SlcanError> {
    let (&first, rest) = line.split_first().ok_or(SlcanError::Empty)?;
    if line.len() > MAX_LINE {
        return Err(SlcanError::TooLong);
    }
    let command = |c| Ok(Line::Command(c));
    match first {
        b't' | b'T' | b'r' | b'R' => frame(first, rest).map(Line::Frame),
        b'O' | b'L' | b'C' | b'V' | b'N' | b'F' if !rest.is_empty() => Err(SlcanError::Argument),
        b'O' => command(Command::Open),
        b'L' => command(Command::ListenOnly),
        b'C' => command(Command::Close),
        b'V' => command(Command::Version),
        b'N' => command(Command::SerialNumber),
        b'F' => command(Command::Status),
        b'S' => match rest {
            [d @ b'0'..=b'8'] => command(Command::Bitrate(d - b'0')),
            _ => Err(SlcanError::Argument),
        },
        b'Z' => match rest {
            [b'0'] => command(Command::Timestamps(false)),
            [b'1'] => command(Command::Timestamps(true)),
            _ => Err(SlcanError::Argument),
        },
        other => Err(SlcanError::Unknown(other)),
    }
}

/// A frame line's identifier, length and data (`rest` follows the type letter).
fn frame<F: Frame>(kind: u8, rest: &[u8]) -> Result<F, SlcanError> {
    let extended = matches!(kind, b'T' | b'R');
    let digits = if extended { 8 } else { 3 };
    let id_digits = rest.get(..digits).ok_or(SlcanError::Length)?;
    let raw = hex(id_digits)?;
    let id = if extended {
        Id::Extended(ExtendedId::new(raw).ok_or(SlcanError::Id)?)
    } else {
        let raw = u16::try_from(raw).map_err(|_| SlcanError::Id)?;
        Id::Standard(StandardId::new(raw).ok_or(SlcanError::Id)?)
    };
    let &dlc_digit = rest.get(digits).ok_or(SlcanError::Length)?;
    let dlc = hex_value(dlc_digit)? as usize;
    if dlc > 8 {
        return Err(SlcanError::Length);
    }
    let body = rest.get(digits + 1..).unwrap_or(&[]);
    let remote = matches!(kind, b'r' | b'R');
    let data_digits = if remote { 0 } else { 2 * dlc };
    // What follows the data: nothing, or a 4-digit timestamp.
    let tail = body.get(data_digits..).ok_or(SlcanError::Length)?;
    match tail.len() {
        0 => {}
        4 => {
            hex(tail)?;
        }
        _ => return Err(SlcanError::Length),
    }
    if remote {
        return F::new_remote(id, dlc).ok_or(SlcanError::Length);
    }
    let mut data = [0u8; 8];
    for (i, pair) in body.get(..data_digits).unwrap_or(&[]).chunks(2).enumerate() {
        if let Some(slot) = data.get_mut(i) {
            *slot = hex(pair)? as u8;
        }
    }
    F::new(id, data.get(..dlc).unwrap_or(&[])).ok_or(SlcanError::Length)
}

/// Gathers a byte stream into lines: push each byte received; at each `\r` it gives what
/// the line read ([`parse`]). A line longer than [`MAX_LINE`] gives
/// [`SlcanError::TooLong`] at its `\r` and nothing before, so that a stream that lost a
/// `\r` resynchronises on the next one. A `\n` (some terminals send `\r\n`) is skipped.
#[derive(Debug, Clone)]
pub struct LineBuffer {
    buf: [u8; MAX_LINE],
    len: usize,
    overflow: bool,
}

impl LineBuffer {
    /// An empty buffer.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_LINE],
            len: 0,
            overflow: false,
        }
    }

    /// Takes one byte; at the end of a line, what the line read.
    pub fn push<F: Frame>(&mut self, byte: u8) -> Option<Result<Line<F>, SlcanError>> {
        match byte {
            CR => {
                let result = if self.overflow {
                    Err(SlcanError::TooLong)
                } else {
                    parse(self.buf.get(..self.len).unwrap_or(&[]))
                };
                (self.len, self.overflow) = (0, false);
                Some(result)
            }
            b'\n' => None,
            _ => {
                match self.buf.get_mut(self.len) {
                    Some(slot) => {
                        *slot = byte;
                        self.len += 1;
                    }
                    None => self.overflow = true,
                }
                None
            }
        }
    }
}

impl Default for LineBuffer {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::PlainFrame;
    use proptest::prelude::*;

    fn line(f: &PlainFrame) -> ([u8; MAX_LINE + 1], usize) {
        let mut out = [0u8; MAX_LINE + 1];
        let n = encode(f, &mut out).unwrap();
        (out, n)
    }

    #[test]
    fn frames_read_as_adapters_write_them() {
        let f: PlainFrame = parse(b"t1232DEAD")
            .map(|l| match l {
                Line::Frame(f) => f,
                Line::Command(_) => panic!("a frame"),
            })
            .unwrap();
        assert_eq!(f.id(), Id::Standard(StandardId::new(0x123).unwrap()));
        assert_eq!(f.data(), &[0xDE, 0xAD]);
        // Lower-case digits and a timestamp, as some adapters send them.
        let g: Line<PlainFrame> = parse(b"T18FF1002801020304050607080a1b").unwrap();
        let Line::Frame(g) = g else { panic!("a frame") };
        assert_eq!(g.id(), Id::Extended(ExtendedId::new(0x18FF_1002).unwrap()));
        assert_eq!(g.data(), &[1, 2, 3, 4, 5, 6, 7, 8]);
        // Lower-case data digits read as upper-case ones do.
        let l: Line<PlainFrame> = parse(b"t1233a0fFcb").unwrap();
        let Line::Frame(l) = l else { panic!("a frame") };
        assert_eq!(l.data(), &[0xA0, 0xFF, 0xCB]);
        let r: Line<PlainFrame> = parse(b"R18FF10024").unwrap();
        let Line::Frame(r) = r else { panic!("a frame") };
        assert!(r.is_remote_frame());
        assert_eq!(r.dlc(), 4);
    }

    #[test]
    fn the_encoder_writes_what_adapters_write() {
        let id = ExtendedId::new(0x18FF_1002).unwrap();
        let f = PlainFrame::new(id, &[0xAB, 0x01]).unwrap();
        let (out, n) = line(&f);
        assert_eq!(&out[..n], b"T18FF10022AB01\r");
        let s = PlainFrame::new(StandardId::new(0x7FF).unwrap(), &[]).unwrap();
        let (out, n) = line(&s);
        assert_eq!(&out[..n], b"t7FF0\r");
        let mut short = [0u8; 5];
        assert_eq!(encode(&f, &mut short), Err(SlcanError::Buffer));
    }

    #[test]
    fn commands_and_bad_lines_give_their_answers() {
        let p = |s: &[u8]| parse::<PlainFrame>(s);
        assert_eq!(p(b"O"), Ok(Line::Command(Command::Open)));
        assert_eq!(p(b"S6"), Ok(Line::Command(Command::Bitrate(6))));
        assert_eq!(p(b"Z1"), Ok(Line::Command(Command::Timestamps(true))));
        assert_eq!(p(b"Z0"), Ok(Line::Command(Command::Timestamps(false))));
        assert_eq!(p(b"S0"), Ok(Line::Command(Command::Bitrate(0))));
        assert_eq!(p(b"S8"), Ok(Line::Command(Command::Bitrate(8))));
        assert_eq!(p(b"Z2"), Err(SlcanError::Argument));
        for (line, c) in [
            (&b"O"[..], Command::Open),
            (b"L", Command::ListenOnly),
            (b"C", Command::Close),
            (b"V", Command::Version),
            (b"N", Command::SerialNumber),
            (b"F", Command::Status),
        ] {
            assert_eq!(p(line), Ok(Line::Command(c)));
        }
        assert_eq!(p(b""), Err(SlcanError::Empty));
        assert_eq!(p(b"S9"), Err(SlcanError::Argument));
        assert_eq!(p(b"Ox"), Err(SlcanError::Argument));
        assert_eq!(p(b"d1238"), Err(SlcanError::Unknown(b'd')));
        assert_eq!(p(b"t1239"), Err(SlcanError::Length));
        assert_eq!(p(b"t12320A"), Err(SlcanError::Length));
        assert_eq!(p(b"t8001"), Err(SlcanError::Id));
        assert_eq!(p(b"T200000000"), Err(SlcanError::Id));
        assert_eq!(p(b"t12G0"), Err(SlcanError::NotHex));
    }

    #[test]
    fn a_lost_end_of_line_costs_one_line() {
        let mut b = LineBuffer::new();
        let mut results: heapless::Vec<_, 4> = heapless::Vec::new();
        let stream = core::iter::repeat_n(b'7', 40).chain(*b"\rt1230\r\nO\r");
        for byte in stream {
            if let Some(r) = b.push::<PlainFrame>(byte) {
                results.push(r).unwrap();
            }
        }
        assert_eq!(results.len(), 3);
        assert_eq!(results[0], Err(SlcanError::TooLong));
        assert!(matches!(results[1], Ok(Line::Frame(_))));
        assert_eq!(results[2], Ok(Line::Command(Command::Open)));
    }

    #[test]
    fn the_longest_line_reads_and_one_more_character_does_not() {
        // T, 8 id digits, the length, 16 data digits, a 4-digit timestamp: 30.
        let longest = b"T18FF1002801020304050607081A2B";
        assert_eq!(longest.len(), MAX_LINE);
        assert!(matches!(parse::<PlainFrame>(longest), Ok(Line::Frame(_))));
        let mut b = LineBuffer::new();
        let mut last = None;
        for &byte in longest.iter().chain(b"0\r") {
            last = b.push::<PlainFrame>(byte).or(last);
        }
        assert_eq!(last, Some(Err(SlcanError::TooLong)));
        // The encoder's longest line (no timestamp) and its `\r` fit a buffer of
        // MAX_LINE + 1.
        let f = PlainFrame::new(ExtendedId::new(0x1FFF_FFFF).unwrap(), &[0xFF; 8]).unwrap();
        let (_, n) = line(&f);
        assert_eq!(n, MAX_LINE - 4 + 1);
    }

    #[test]
    fn every_error_says_what_it_is() {
        let all = [
            SlcanError::Empty,
            SlcanError::TooLong,
            SlcanError::Unknown(b'd'),
            SlcanError::NotHex,
            SlcanError::Length,
            SlcanError::Id,
            SlcanError::Argument,
            SlcanError::Buffer,
        ];
        let mut said: heapless::Vec<heapless::String<64>, 8> = heapless::Vec::new();
        for e in all {
            let mut text = heapless::String::<64>::new();
            core::fmt::write(&mut text, format_args!("{e}")).unwrap();
            assert!(text.contains("SLCAN"), "{e:?}: {text}");
            assert!(!said.contains(&text), "{e:?} says what another says");
            said.push(text).unwrap();
        }
        let mut text = heapless::String::<64>::new();
        core::fmt::write(&mut text, format_args!("{}", SlcanError::Unknown(0x64))).unwrap();
        assert!(text.contains("0x64"), "{text}");
    }

    proptest! {
        #[test]
        fn every_classic_frame_survives_the_line(
            extended in any::<bool>(),
            raw in any::<u32>(),
            data in proptest::collection::vec(any::<u8>(), 0..=8),
            remote in any::<bool>(),
        ) {
            let id = if extended {
                Id::Extended(ExtendedId::new(raw & 0x1FFF_FFFF).unwrap())
            } else {
                Id::Standard(StandardId::new((raw & 0x7FF) as u16).unwrap())
            };
            let f = if remote {
                PlainFrame::new_remote(id, data.len()).unwrap()
            } else {
                PlainFrame::new(id, &data).unwrap()
            };
            let (out, n) = line(&f);
            let mut b = LineBuffer::new();
            let mut got = None;
            for &byte in &out[..n] {
                if let Some(r) = b.push::<PlainFrame>(byte) {
                    got = Some(r);
                }
            }
            prop_assert_eq!(got, Some(Ok(Line::Frame(f))));
        }

        #[test]
        fn any_bytes_give_lines_or_errors(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            let mut b = LineBuffer::new();
            for byte in bytes {
                let _ = b.push::<PlainFrame>(byte);
            }
        }
    }
}
