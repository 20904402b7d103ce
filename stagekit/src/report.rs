//! Small helpers every stage uses for its `report.json`: phase timings and peak memory.

use serde::Serialize;
use std::time::Instant;

/// Peak resident set size of this process in MiB (`VmHWM` of `/proc/self/status`);
/// `None` where the kernel does not report it.
pub fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// Wall time per named phase, in the order the phases ran.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Phases {
    pub seconds: Vec<(String, f64)>,
    #[serde(skip)]
    started: Option<(String, Instant)>,
}

impl Phases {
    pub fn new() -> Self {
        Self::default()
    }

    /// Ends the running phase (if any) and starts `name`.
    pub fn start(&mut self, name: &str) {
        self.stop();
        self.started = Some((name.to_string(), Instant::now()));
    }

    /// Ends the running phase.
    pub fn stop(&mut self) {
        if let Some((name, t)) = self.started.take() {
            self.seconds.push((name, t.elapsed().as_secs_f64()));
        }
    }

    /// Sum of all finished phases.
    pub fn total(&self) -> f64 {
        self.seconds.iter().map(|p| p.1).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phases_record_in_order_and_peak_rss_is_positive() {
        let clock = std::time::Instant::now();
        let mut p = Phases::new();
        p.start("a");
        std::thread::sleep(std::time::Duration::from_millis(20));
        p.start("b");
        std::thread::sleep(std::time::Duration::from_millis(10));
        p.stop();
        p.stop();
        let outside = clock.elapsed().as_secs_f64();
        let names: Vec<_> = p.seconds.iter().map(|s| s.0.as_str()).collect();
        assert_eq!(names, ["a", "b"]);
        // Each phase at least as long as its sleep; together no longer than the wall
        // clock around them, and the total their sum.
        assert!(
            p.seconds[0].1 >= 0.020 && p.seconds[1].1 >= 0.010,
            "{:?}",
            p.seconds
        );
        assert!(p.total() <= outside, "{} > {outside}", p.total());
        assert_eq!(p.total(), p.seconds[0].1 + p.seconds[1].1);
        if cfg!(target_os = "linux") {
            // While a 64 MiB buffer is resident (touched page by page), the peak holds it.
            let mut big = vec![0u8; 64 << 20];
            for i in (0..big.len()).step_by(4096) {
                big[i] = 1;
            }
            std::hint::black_box(&big);
            let peak = peak_rss_mib().unwrap();
            assert!(peak >= 64.0, "{peak}");
        }
    }
}
