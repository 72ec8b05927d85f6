//! planner-core's integration tests, one binary: each file beside this one is a module
//! (`cargo test -p planner-core --test integration reuse::` runs one file's tests). One
//! binary, not one per file: each file's binary linked the crate and instantiated its
//! generic planners again; the 21 took 40 CPU-seconds of a release build, this one takes
//! 18 (cargo's `--timings`, at 47a8dbd).

mod active_set;
mod answer_at_cap;
mod crossing;
mod errors;
mod free_space_oracle;
mod leader_aware;
mod lemmas;
mod manager_audit;
mod mpc_audit;
mod multilane;
mod mutation_audit;
mod planner_step;
mod reuse;
mod scaled_cold_start;
mod settings;
mod slot;
mod verifier_edge;
mod warm_from_fallback;
mod warm_retry;
mod widen;
