//! Runs independent jobs on all cores.

use std::sync::atomic::{AtomicUsize, Ordering};

/// Calls `f(i)` for every i in 0..count on `threads` worker threads (0 = all cores),
/// each taking the next index when free; returns the results in index order.
pub fn map_indexed<T: Send>(count: usize, threads: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let threads = self::threads(threads);
    let next = AtomicUsize::new(0);
    let mut out: Vec<(usize, T)> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads.min(count.max(1)))
            .map(|_| {
                s.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= count {
                            break mine;
                        }
                        mine.push((i, f(i)));
                    }
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    });
    out.sort_by_key(|(i, _)| *i);
    out.into_iter().map(|(_, t)| t).collect()
}

/// Number of worker threads `map_indexed` uses for `threads` (0 = all cores).
pub fn threads(threads: usize) -> usize {
    if threads == 0 {
        std::thread::available_parallelism().map_or(2, |n| n.get())
    } else {
        threads
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn results_in_index_order() {
        let v = super::map_indexed(100, 3, |i| i * i);
        assert_eq!(v, (0..100).map(|i| i * i).collect::<Vec<_>>());
        assert!(super::map_indexed(0, 0, |i| i).is_empty());
    }
}
