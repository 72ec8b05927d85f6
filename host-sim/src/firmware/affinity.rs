//! Each QEMU on one host core: the board's UART holds one byte, so QEMU's I/O thread and
//! its vCPU thread hand every received byte to each other (the I/O thread reads it and
//! raises the interrupt, the vCPU takes it and asks for the next). On two cores every
//! hand-off is a wake-up across cores; confined to one, it is a switch on that core.
//! Measured on the CI machine (2 cores), one computer in the loop on the multi-lane road
//! for 3 s: 13.2 s wall and 11.9 CPU-s spread, 5.3 s and 5.3 CPU-s confined; the dense
//! road's, 52 CPU-s and 26. Nothing the firmware computes depends on it (`-icount`
//! counts instructions, not host time), only how long the host takes.
//!
//! The QEMUs a process starts go round the cores it may run on (its own affinity, so
//! `taskset -c 1 host-sim run …` keeps them all on core 1), in the order they start.

use std::os::unix::process::CommandExt;
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};

/// QEMUs this process has started.
static STARTED: AtomicUsize = AtomicUsize::new(0);

/// The host cores this process may run on, in ascending order (empty if it cannot say).
pub fn allowed_cores() -> Vec<usize> {
    // SAFETY: a zeroed cpu_set_t is an empty set; sched_getaffinity writes at most
    // size_of::<cpu_set_t>() bytes into it.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    let size = std::mem::size_of::<libc::cpu_set_t>();
    if unsafe { libc::sched_getaffinity(0, size, &mut set) } != 0 {
        return Vec::new();
    }
    (0..8 * size)
        // SAFETY: `c` is below the set's capacity in bits.
        .filter(|&c| unsafe { libc::CPU_ISSET(c, &set) })
        .collect()
}

/// The core the `k`-th QEMU gets: round `cores`.
fn core_for(k: usize, cores: &[usize]) -> Option<usize> {
    cores.get(k.checked_rem(cores.len())?).copied()
}

/// Makes `qemu` start on one core of this process's, the next in turn. Best effort: if the
/// cores cannot be read or set, QEMU runs wherever the kernel puts it, only slower.
pub fn confine(qemu: &mut Command) {
    let k = STARTED.fetch_add(1, Ordering::Relaxed);
    let Some(core) = core_for(k, &allowed_cores()) else {
        return;
    };
    // SAFETY: as in `allowed_cores`; `core` came from the process's own set.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    unsafe { libc::CPU_SET(core, &mut set) };
    let size = std::mem::size_of::<libc::cpu_set_t>();
    // SAFETY: between fork and exec the closure only makes one system call (no
    // allocation, no lock), and every thread QEMU starts inherits the mask.
    unsafe {
        qemu.pre_exec(move || {
            libc::sched_setaffinity(0, size, &set);
            Ok(())
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn qemus_go_round_the_allowed_cores() {
        let cores = allowed_cores();
        assert!(!cores.is_empty(), "a running process has a core");
        assert!(cores.windows(2).all(|w| w[0] < w[1]));
        let picked: Vec<_> = (0..5).filter_map(|k| core_for(k, &[2, 3])).collect();
        assert_eq!(picked, [2, 3, 2, 3, 2]);
        assert_eq!(core_for(7, &[5]), Some(5));
        assert_eq!(core_for(0, &[]), None);
    }

    #[test]
    fn a_confined_child_runs_on_one_core() {
        let mut cmd = Command::new("grep");
        cmd.args(["^Cpus_allowed_list", "/proc/self/status"]);
        confine(&mut cmd);
        let out = cmd.output().expect("grep runs");
        let text = String::from_utf8_lossy(&out.stdout);
        let list = text.split(':').nth(1).expect("a list").trim();
        let core: usize = list
            .parse()
            .unwrap_or_else(|_| panic!("one core, not {list}"));
        assert!(allowed_cores().contains(&core));
    }
}
