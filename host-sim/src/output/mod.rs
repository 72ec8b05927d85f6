//! What a run leaves behind: the CSV trace, plots, and the viewer page, each written
//! whole or not at all ([`staged`]).

pub mod plot;
pub mod staged;
pub mod sumo;
pub mod trace;
pub mod viewer;
