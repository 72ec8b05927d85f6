//! What a run leaves behind: the CSV trace, plots, and the viewer page.

pub mod plot;
pub mod trace;
pub mod viewer;
