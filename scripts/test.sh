#!/usr/bin/env bash
# README's test command: sets up what the tests need beyond Rust, then runs every test of
# the workspace (`cargo test --workspace --release --no-fail-fast`, so one failing test
# binary does not hide the others). Extra arguments go to cargo test.
#
# Two tests need more than Rust: can-gateway's DBC test decodes the gateway's frames with
# Python `cantools`, and host-sim's viewer test drives the page in headless `chromium`
# through Python `playwright`. The Python packages go into a virtual environment under
# cargo's target directory (Debian's Python refuses `pip install` outside one, PEP 668);
# as root on Debian, missing system packages (a C linker, python3-venv, chromium) are
# installed with apt-get. What cannot be set up is skipped: the test says so in the
# normal output, and the end of this script lists every skip and counts them. Set
# TESTS_OFFLINE=1 to install nothing (then only what is already there is used).
set -uo pipefail
cd "$(dirname "$0")/.."

say() { echo "test.sh: $*"; }

# Everything this script creates lives under cargo's target directory (which
# CARGO_TARGET_DIR may move), never in the source tree.
target_dir() {
  cargo metadata --format-version 1 --no-deps 2>/dev/null |
    sed -n 's/.*"target_directory":"\([^"]*\)".*/\1/p'
}

can_apt() {
  [ "${TESTS_OFFLINE:-0}" != 1 ] && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null
}

apt_updated=0
apt_install() {
  can_apt || return 1
  if [ $apt_updated = 0 ]; then
    apt-get update -qq >/dev/null && apt_updated=1
  fi
  say "installing $* (apt-get)"
  # apt's chatter goes to a log, shown only if the install fails.
  local log
  log=$(mktemp)
  if ! DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "$@" \
    >"$log" 2>&1; then
    cat "$log"
    rm -f "$log"
    return 1
  fi
  rm -f "$log"
}

# Rust links with the system's C compiler; a bare Debian has none.
if ! command -v cc >/dev/null; then
  apt_install gcc libc6-dev || {
    say "no C linker (cc) and no way to install one: apt-get install gcc"
    exit 2
  }
fi

target=$(target_dir)
if [ -z "$target" ]; then
  say "cargo metadata failed: is this the repository, with cargo on the PATH?"
  exit 2
fi
mkdir -p "$target"
venv="$target/test-python"
skip_log="$target/test-skips.log"
: >"$skip_log"
skip=()

# The Python environment: the system's python3 if it has cantools and playwright, else a
# virtual environment with them.
python_ready() {
  "$1" -c 'import cantools, playwright.sync_api' 2>/dev/null
}
make_venv() {
  command -v python3 >/dev/null || apt_install python3 || return 1
  # Without python3-venv, venv fails and says so at length: install it instead.
  python3 -m venv "$venv" >/dev/null 2>&1 || {
    rm -rf "$venv"
    apt_install python3-venv && python3 -m venv "$venv"
  } || return 1
  [ "${TESTS_OFFLINE:-0}" != 1 ] || return 1
  say "installing cantools and playwright into $venv (pip)"
  "$venv/bin/python3" -m pip install --quiet --disable-pip-version-check cantools playwright
}
if python_ready python3; then
  export TESTS_PYTHON=python3
elif python_ready "$venv/bin/python3" || { make_venv && python_ready "$venv/bin/python3"; }; then
  export TESTS_PYTHON="$venv/bin/python3"
else
  # A system-wide cantools (e.g. Debian's python3-cantools) still serves the DBC test.
  if python3 -c 'import cantools' 2>/dev/null; then
    export TESTS_PYTHON=python3
  else
    skip+=(cantools)
  fi
fi

# The browser: Debian's chromium, driven by the environment's playwright.
if ! command -v chromium >/dev/null && ! command -v chromium-browser >/dev/null; then
  apt_install chromium || true
fi
if ! { command -v chromium || command -v chromium-browser; } >/dev/null ||
  ! "${TESTS_PYTHON:-python3}" -c 'import playwright.sync_api' 2>/dev/null; then
  skip+=(browser)
fi

if [ ${#skip[@]} -gt 0 ]; then
  TESTS_SKIP=$(IFS=,; echo "${skip[*]}")
  export TESTS_SKIP
  say "cannot set up: ${skip[*]} (those tests will be skipped and listed at the end)"
fi
export TESTS_SKIP_LOG="$skip_log"

cargo test --workspace --release --no-fail-fast "$@"
status=$?

skipped=$(grep -c '^SKIPPED' "$skip_log" || true)
if [ "$skipped" -gt 0 ]; then
  echo
  say "SKIPPED $skipped test(s), not run for want of what they need:"
  grep '^SKIPPED' "$skip_log" | sed 's/^/  /'
fi
# Checks against a benchmark dependency (SUMO) run where it is installed; without it
# they say so here and count as neither a skip nor a failure.
if grep -q '^NOT RUN' "$skip_log"; then
  echo
  say "not run, for want of a benchmark dependency (not required by the tests):"
  grep '^NOT RUN' "$skip_log" | sed 's/^/  /'
fi
if [ $status = 0 ]; then
  say "every test passed ($skipped skipped)"
else
  say "FAILED: cargo test exited $status (scroll up for the failing tests)"
fi
exit $status
