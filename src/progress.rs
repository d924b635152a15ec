//! A line on stderr for each step of a big job that takes over a second (loading a scene,
//! building its BVH, encoding a layout): "step…" once it has run for a second, then "step:
//! done in N s (peak memory M MB)" (the process's peak resident set so far, where the OS
//! reports it). Quick steps print nothing.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

static QUIET: AtomicBool = AtomicBool::new(false);

/// Silences the progress lines (`sweep --quiet`).
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

/// Runs `f`, announcing `label` if it takes over a second, and its time when it ends.
pub fn step<T>(label: &str, f: impl FnOnce() -> T) -> T {
    if QUIET.load(Ordering::Relaxed) {
        return f();
    }
    let (tx, rx) = mpsc::channel::<()>();
    let t0 = Instant::now();
    std::thread::scope(|s| {
        let watcher = s.spawn(move || {
            let slow = matches!(rx.recv_timeout(Duration::from_secs(1)), Err(mpsc::RecvTimeoutError::Timeout));
            if slow {
                eprintln!("{label}…");
            }
            slow
        });
        let r = f();
        let _ = tx.send(());
        if watcher.join().unwrap_or(false) {
            let peak = peak_rss_bytes().map(|b| format!(" (peak memory {} MB)", b >> 20)).unwrap_or_default();
            eprintln!("{label}: done in {:.1} s{peak}", t0.elapsed().as_secs_f64());
        }
        r
    })
}

/// The process's peak resident set size in bytes (Linux: `VmHWM` in /proc/self/status).
pub fn peak_rss_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let kb: u64 =
        s.lines().find_map(|l| l.strip_prefix("VmHWM:"))?.trim().trim_end_matches("kB").trim().parse().ok()?;
    Some(kb << 10)
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_step_returns_its_value_quick_or_slow() {
        assert_eq!(super::step("quick", || 7), 7);
        assert!(super::peak_rss_bytes().is_some_and(|b| b > 0));
        assert_eq!(
            super::step("slow (a test of the progress line)", || {
                std::thread::sleep(std::time::Duration::from_millis(1200));
                "done"
            }),
            "done"
        );
    }
}
