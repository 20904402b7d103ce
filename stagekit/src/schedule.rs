//! The time a piece of work has left when its steps do not all cost the same: a
//! [`Schedule`] of the expected relative cost of each phase's steps, and the measured
//! seconds per unit of that cost over the recent steps ([`TimeLeft`]).
//!
//! The warm-up is the case: its first thousand steps (half resolution, no field) run five
//! times faster than the field's, and the rate of the recent steps promised a fifth of
//! the real time left during them (BENCHMARKS.md, "640×480 end to end"). The stage knows
//! its phases; what it does not know (the machine's speed, the scene's size) the recent
//! steps measure.

use std::collections::VecDeque;
use std::sync::Mutex;

/// Expected relative cost per step, phase by phase: `(end, cost)` pairs, each phase
/// running from the previous end (0 for the first) up to `end` (exclusive).
#[derive(Clone, Debug, PartialEq)]
pub struct Schedule {
    phases: Vec<(u64, f64)>,
}

impl Schedule {
    /// Phases in any order; empty ones (an end not after the previous) are dropped, and
    /// costs that are not finite and positive count as 1.
    pub fn new(mut phases: Vec<(u64, f64)>) -> Schedule {
        phases.sort_by_key(|p| p.0);
        phases.dedup_by_key(|p| p.0);
        for p in &mut phases {
            if !(p.1.is_finite() && p.1 > 0.0) {
                p.1 = 1.0;
            }
        }
        Schedule { phases }
    }

    /// The work of steps `0..pos` (steps past the last phase cost as much as its steps).
    pub fn work(&self, pos: u64) -> f64 {
        let (mut start, mut sum, mut last) = (0u64, 0.0, 1.0);
        for &(end, cost) in &self.phases {
            if pos <= start {
                return sum;
            }
            sum += (pos.min(end) - start) as f64 * cost;
            (start, last) = (end, cost);
        }
        sum + pos.saturating_sub(start) as f64 * last
    }
}

/// Seconds left of a scheduled piece of work of `total` steps, at the rate (seconds per
/// unit of work) of the steps within the last twentieth of the work.
pub struct TimeLeft {
    schedule: Schedule,
    total: u64,
    seen: Mutex<VecDeque<(f64, f64)>>,
}

impl TimeLeft {
    pub fn new(schedule: Schedule, total: u64) -> TimeLeft {
        TimeLeft {
            schedule,
            total,
            seen: Mutex::new(VecDeque::new()),
        }
    }

    /// Step `pos` was done at `secs`; the estimate of the seconds left (`None` until two
    /// steps were seen).
    pub fn update(&self, pos: u64, secs: f64) -> Option<f64> {
        let (work, total) = (self.schedule.work(pos), self.schedule.work(self.total));
        let window = total / 20.0;
        let mut seen = self.seen.lock().unwrap_or_else(|e| e.into_inner());
        seen.push_back((work, secs));
        while seen.len() > 2 && seen[1].0 <= work - window {
            seen.pop_front();
        }
        let &(w0, s0) = seen.front()?;
        (work > w0 && secs >= s0).then(|| (secs - s0) / (work - w0) * (total - work).max(0.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn work_adds_each_phase_at_its_cost() {
        let s = Schedule::new(vec![(2000, 4.0), (1000, 1.0), (3500, 2.0)]);
        assert_eq!(s.work(0), 0.0);
        assert_eq!(s.work(500), 500.0);
        assert_eq!(s.work(1000), 1000.0);
        assert_eq!(s.work(1500), 1000.0 + 2000.0);
        assert_eq!(s.work(3500), 1000.0 + 4000.0 + 3000.0);
        // Past the last phase, at its cost.
        assert_eq!(s.work(3600), 8000.0 + 200.0);
        assert_eq!(Schedule::new(vec![]).work(7), 7.0);
    }

    /// A run whose steps cost what the schedule says (1 s, then 5 s, then 2 s each): the
    /// estimate is exact from the second step on, in every phase, where the recent rate
    /// of plain steps would have promised a fifth of the time during the first phase.
    #[test]
    fn time_left_is_exact_when_the_schedule_is_right() {
        let s = Schedule::new(vec![(100, 1.0), (300, 5.0), (400, 2.0)]);
        let truth = |pos: u64| s.work(400) - s.work(pos);
        let t = TimeLeft::new(s.clone(), 400);
        assert_eq!(t.update(0, 0.0), None);
        for pos in 1..=400u64 {
            let left = t.update(pos, s.work(pos)).unwrap();
            assert!((left - truth(pos)).abs() < 1e-9 * truth(0), "{pos}: {left}");
        }
        assert!((truth(50) - 1250.0).abs() < 1e-9);
    }

    /// A machine twice as slow as the schedule's units: the estimate doubles with it.
    #[test]
    fn the_rate_comes_from_the_recent_steps() {
        let s = Schedule::new(vec![(100, 1.0), (200, 3.0)]);
        let t = TimeLeft::new(s.clone(), 200);
        let mut left = None;
        for pos in 0..=150u64 {
            // The first 100 steps at 1 s per unit, then 2 s per unit.
            let secs = s.work(pos.min(100)) + 2.0 * (s.work(pos) - s.work(pos.min(100)));
            left = t.update(pos, secs);
        }
        assert!((left.unwrap() - 2.0 * 150.0).abs() < 1e-9, "{left:?}");
    }
}
