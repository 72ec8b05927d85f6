//! # can-gateway
//!
//! Will map the planners' V2V/V2I messages onto CAN frames (a `no_std` codec over the
//! `embedded-can` traits, SocketCAN on Linux, a DBC file). Nothing is implemented yet:
//! this crate is an empty placeholder so that the workspace layout is in place, and it
//! provides no API.
#![no_std]
#![deny(missing_docs)]
