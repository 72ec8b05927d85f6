//! Lines of the `candump -l` log format, `(seconds.micros) iface ID#DATA`, so that a
//! gateway's traffic can be read by can-utils, python-can and cantools.

use core::fmt::Write;
use embedded_can::{Frame, Id};
use heapless::String;

/// One `candump -l` line (without newline) for `frame` seen at `micros` µs on `iface`;
/// a frame with more than 8 data bytes is a CAN FD frame, written `ID##0DATA` (flags 0:
/// no bit-rate switch) as candump writes it. `None` if the interface name does not fit
/// (the line holds 192 bytes).
pub fn candump_line<Fr: Frame>(micros: u64, iface: &str, frame: &Fr) -> Option<String<192>> {
    let mut s = String::new();
    write!(
        s,
        "({}.{:06}) {} ",
        micros / 1_000_000,
        micros % 1_000_000,
        iface
    )
    .ok()?;
    match frame.id() {
        Id::Extended(e) => write!(s, "{:08X}#", e.as_raw()).ok()?,
        Id::Standard(st) => write!(s, "{:03X}#", st.as_raw()).ok()?,
    }
    if frame.data().len() > 8 {
        s.push_str("#0").ok()?;
    }
    for b in frame.data() {
        write!(s, "{b:02X}").ok()?;
    }
    Some(s)
}
