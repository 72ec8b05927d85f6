//! What the tests that need more than Rust share: the Python that README's test command
//! (`scripts/test.sh`) set up, and how a test is skipped when it could not set up what
//! the test needs. can-gateway's DBC test and host-sim's viewer test (which includes this
//! file by path) use it.

/// The Python that runs the checks: the test script's environment, else `python3`.
pub fn python() -> String {
    std::env::var("TESTS_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// Skips the test when the test script could not set up `what` (it lists it in
/// `TESTS_SKIP`): says so on the terminal, past cargo's capture, and in the script's skip
/// log. Anywhere else a missing prerequisite fails the test with `why`.
pub fn skip_or_fail(what: &str, test: &str, why: &str) {
    use std::io::Write;
    let listed = std::env::var("TESTS_SKIP").is_ok_and(|s| s.split(',').any(|w| w == what));
    assert!(
        listed,
        "{why} (README's test command, scripts/test.sh, sets it up)"
    );
    let line = format!("SKIPPED {test}: {why}");
    let _ = writeln!(std::io::stderr(), "{line}");
    if let Ok(log) = std::env::var("TESTS_SKIP_LOG") {
        let mut f = std::fs::OpenOptions::new()
            .append(true)
            .create(true)
            .open(&log)
            .expect("the test script's skip log opens");
        writeln!(f, "{line}").expect("the skip log takes a line");
    }
}
