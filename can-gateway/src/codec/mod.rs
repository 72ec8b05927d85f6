//! Encoding messages into frames, and reassembling frames into messages.
//!
//! The decoder is total: every input frame yields `Ok(None)` (part of a message stored),
//! `Ok(Some(message))` (a whole, verified message) or a typed [`DecodeError`], and a
//! frame that yields an error leaves the reassembler exactly as it was.
//!
//! One file per stage: `quantize` (values to and from the wire's resolutions),
//! `encode` (payload, CRC, frames, authenticator), `reassemble` (frames into a whole
//! payload), `verify` (the checks before a message is accepted) and `decode` (a verified
//! payload into a message). Where each field sits is [`crate::layout`]'s alone.

use crate::crc;
use crate::secoc::AuthError;
use crate::wire::{MessageKind, CHUNK, MAX_FRAMES};
use heapless::Vec;

mod decode;
mod encode;
mod quantize;
mod reassemble;
mod verify;

pub use encode::{encode, encode_fd, encode_fd_secured, encode_secured, SecuredFrames};
pub use quantize::restore_millis;
pub use reassemble::Reassembler;
pub use verify::Verifier;

/// The frames of one message.
pub type Frames<Fr> = Vec<Fr, MAX_FRAMES>;

/// Which field could not be encoded or was implausible on decoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Field {
    /// x.
    X,
    /// y.
    Y,
    /// Heading.
    Heading,
    /// Speed.
    Speed,
    /// Yaw rate.
    YawRate,
    /// A lane.
    Lane,
    /// A position along a path.
    PathPosition,
    /// A track's heading.
    TrackHeading,
    /// A flag byte other than 0 or 1, or an undefined flag bit set.
    Flag,
}

/// State message, byte 13, high nibble: the sender does not cooperate (a scripted or
/// legacy vehicle: it neither hears intentions nor yields).
const NOT_COOPERATIVE: u8 = 0x10;

/// Why a message could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum EncodeError {
    /// A value is NaN, infinite or outside what its field can carry.
    OutOfRange(Field),
    /// The frame type refused the identifier or data (never for a conforming type).
    Frame,
}

/// The first sentence of each variant's documentation (and its data).
impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::OutOfRange(..) => write!(
                f,
                "a value is NaN, infinite or outside what its field can carry ({self:?})"
            ),
            Self::Frame => f.write_str(
                "the frame type refused the identifier or data (never for a conforming type)",
            ),
        }
    }
}

impl core::error::Error for EncodeError {}

/// Why a frame was rejected (the reassembler is unchanged).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum DecodeError {
    /// A standard (11-bit) identifier or a remote frame: not ours.
    NotOurs,
    /// Extended identifier outside this protocol (priority, data page, PDU format).
    ForeignId,
    /// Unknown message kind code.
    UnknownKind(u8),
    /// The frame index is not below the kind's frame count.
    BadFrameIndex,
    /// Not 8 data bytes (a classic frame), not the length of its kind's CAN FD frame, or
    /// padding that is not zero.
    BadLength,
    /// The header's frame index differs from the identifier's.
    HeaderMismatch,
    /// A continuation frame without its message's first frame, or with another alive
    /// counter, or out of order.
    OutOfSequence,
    /// The message CRC does not match.
    Crc,
    /// A field is outside its plausible range.
    OutOfRange(Field),
    /// The sender's address differs from the id in the message.
    SenderMismatch,
    /// Same alive counter as the last accepted message of this sender and kind.
    Duplicate,
    /// Time stamp not newer than the last accepted state of this sender.
    Stale,
    /// The reassembler tracks as many senders as it can hold.
    Full,
    /// A secured message's authenticator was refused ([`crate::secoc`]).
    Auth(AuthError),
}

/// The first sentence of each variant's documentation (and its data).
impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NotOurs => f.write_str("a standard (11-bit) identifier or a remote frame: not ours"),
            Self::ForeignId => f.write_str("extended identifier outside this protocol (priority, data page, PDU format)"),
            Self::UnknownKind(..) => write!(f, "unknown message kind code ({self:?})"),
            Self::BadFrameIndex => f.write_str("the frame index is not below the kind's frame count"),
            Self::BadLength => f.write_str("not 8 data bytes (a classic frame), not the length of its kind's CAN FD frame, or padding that is not zero"),
            Self::HeaderMismatch => f.write_str("the header's frame index differs from the identifier's"),
            Self::OutOfSequence => f.write_str("a continuation frame without its message's first frame, or with another alive counter, or out of order"),
            Self::Crc => f.write_str("the message CRC does not match"),
            Self::OutOfRange(..) => write!(f, "a field is outside its plausible range ({self:?})"),
            Self::SenderMismatch => f.write_str("the sender's address differs from the id in the message"),
            Self::Duplicate => f.write_str("same alive counter as the last accepted message of this sender and kind"),
            Self::Stale => f.write_str("time stamp not newer than the last accepted state of this sender"),
            Self::Full => f.write_str("the reassembler tracks as many senders as it can hold"),
            Self::Auth(e) => write!(f, "a secured message's authenticator was refused: {e}"),
        }
    }
}

impl core::error::Error for DecodeError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            Self::Auth(e) => Some(e),
            _ => None,
        }
    }
}

/// The E2E CRC of a message: Data ID (kind code, source address), counter, payload.
pub(crate) fn message_crc(kind: MessageKind, sa: u8, counter: u8, payload: &[u8]) -> u8 {
    let c = crc::update(crc::INIT, &[kind as u8, sa, counter & 0x0F]);
    crc::finish(crc::update(c, payload))
}

/// Reassembly and acceptance state for one sender and kind.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Slot {
    pub(crate) sa: u8,
    pub(crate) kind: MessageKind,
    /// Counter of the message being reassembled and frames seen (bit i = frame i).
    pub(crate) partial: Option<(u8, u8)>,
    pub(crate) bytes: [u8; MAX_FRAMES * CHUNK],
    /// Counter of the last accepted message.
    pub(crate) last_counter: Option<u8>,
    /// Stamp of the last accepted state (the wire's ms), or period of the last tick.
    pub(crate) last_stamp: Option<u32>,
}

#[cfg(test)]
mod tests;
