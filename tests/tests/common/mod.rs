//! Helpers shared by the workspace tests.

/// The number in environment variable `key` (a test's case count or seed), else `default`.
pub fn env(key: &str, default: u64) -> u64 {
    std::env::var(key)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}
