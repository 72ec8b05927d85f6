//! The paper's experiments and the theorems' sweeps, each a function from settings to a
//! result struct that serialises to its JSON (printing is the CLI's).

pub mod attacks;
pub mod crossings;
pub mod deadends;
pub mod demand;
pub mod experiment;
pub mod fault_grid;
pub mod faults;
pub mod flags;
pub mod lane_capacity;
pub mod layouts;
pub mod multilane;
pub mod network;
pub mod par;
pub mod platoon;
pub mod redteam;
pub mod refusal;
pub mod registry;
pub mod scale;
pub mod shard;
pub mod sweep;
pub mod throughput;
pub mod traffic;
pub mod worlds;
