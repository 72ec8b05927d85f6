//! # can-gateway
//!
//! The planners' V2V and V2I messages on classic CAN and CAN FD frames: a `no_std`, allocation-free
//! codec generic over [`embedded_can::Frame`], with AUTOSAR-E2E-style protection (an
//! alive counter and a CRC-8 per message) and a reassembler that turns any byte
//! sequence into either a message or a typed error, never a panic.
//!
//! - [`wire`]: the frame layout (29-bit J1939-style identifiers), units and resolutions;
//! - [`layout`]: where each field sits in each kind's payload (written once);
//! - [`crc`]: CRC-8 SAE J1850;
//! - [`codec`]: encoding messages into frames and reassembling frames into messages;
//! - [`frame`]: classic and CAN FD frame values for in-process buses, logs and tests;
//! - [`log`]: `candump -l` lines;
//! - [`secoc`]: SecOC-style authentication (AES-128-CMAC, time-based freshness);
//! - [`slcan`]: frames as serial-line CAN (Lawicel) text, the link of USB-CAN adapters.
//!
//! `can-gateway.dbc` (in this crate) describes every frame for standard tools.
//!
//! Feature `defmt`: [`Message`], the wire's values and every error implement
//! `defmt::Format` (and planner-core's types, through its own `defmt` feature), so
//! firmware logs a refused frame's [`DecodeError`] as it is.
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing,
        clippy::unreachable,
        clippy::todo,
        clippy::unimplemented
    )
)]
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod codec;
pub mod crc;
pub mod frame;
pub mod layout;
pub mod log;
pub mod secoc;
pub mod slcan;
pub mod wire;

pub use codec::{encode, encode_fd, DecodeError, EncodeError, Frames, Reassembler};
pub use frame::{FdFrame, PlainFrame};
/// The time type of every message ([`planner_core::time`]): integer microseconds on the
/// fleet's clock.
pub use planner_core::{Duration, Instant};
pub use wire::{Message, MessageKind};

/// The README's examples, compiled and run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
