//! What a running stage says about its progress, as the runner reads it: the plain lines
//! every stage prints through `stagekit::Progress` when its stderr is not a terminal
//! (`[   12.3 s] LABEL POS/TOTAL: MSG`, every twentieth of the work), turned into the
//! phase, the position of the total and an estimate of the time the phase has left. The
//! stage is not slowed: it prints these lines anyway.

use serde::{Deserialize, Serialize};

/// A stage's last progress line, read.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageProgress {
    /// What is counted (`iteration`, `deform`, `frame`, a fine-tuning phase).
    pub label: String,
    pub done: u64,
    pub total: u64,
    /// Seconds since the stage began this piece of work (its own clock).
    pub elapsed_s: f64,
    /// Seconds left at the rate so far, or the stage's own estimate; None before the
    /// first step is done.
    pub eta_s: Option<f64>,
    /// `eta_s` is the stage's estimate from its schedule (`… | left N s`), kept as is.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub eta_from_stage: bool,
}

/// Read one output line; None for lines that are not progress lines.
pub fn parse(line: &str) -> Option<StageProgress> {
    let rest = line.strip_prefix('[')?;
    let (secs, rest) = rest.split_once(" s] ")?;
    // The stage's own estimate, when it ends the line: `… | left 412 s`.
    let (rest, stage_left) = match rest.rsplit_once(stagekit::progress::LEFT_MARK) {
        Some((head, tail)) => match tail.strip_suffix(" s").map(str::parse::<f64>) {
            Some(Ok(v)) if v.is_finite() && v >= 0.0 => (head.trim_end(), Some(v)),
            _ => (rest, None),
        },
        None => (rest, None),
    };
    let elapsed_s: f64 = secs.trim().parse().ok()?;
    // `LABEL POS/TOTAL` then optionally `: MSG`; the label may hold spaces.
    let head = rest.split_once(": ").map_or(rest, |(h, _)| h);
    let (label, count) = head.rsplit_once(' ')?;
    let (done, total) = count.split_once('/')?;
    let (done, total): (u64, u64) = (done.parse().ok()?, total.parse().ok()?);
    if label.is_empty() || total == 0 || done > total || !elapsed_s.is_finite() {
        return None;
    }
    let eta_s = (done > 0).then(|| elapsed_s * (total - done) as f64 / done as f64);
    Some(StageProgress {
        label: label.to_string(),
        done,
        total,
        elapsed_s,
        eta_s: stage_left.or(eta_s),
        eta_from_stage: stage_left.is_some(),
    })
}

/// Lines of a phase its rate is measured over: at a line every twentieth of the work,
/// the last fifth of it.
const RECENT_LINES: usize = 4;

/// One running stage's recent progress lines, so its time left follows the speed it
/// runs at now. A phase's speed changes: the warm-up's first thousand steps (no field,
/// half resolution) run 4–6 times faster than the field's steps after them, so the rate
/// since the start promised a third of the real time left there.
#[derive(Default)]
pub struct RecentRate {
    seen: std::collections::VecDeque<(u64, f64)>,
    label: String,
}

impl RecentRate {
    /// `p` with its time left at the rate of its phase's last [`RECENT_LINES`] lines (at
    /// the rate since the phase began until there are two lines).
    pub fn update(&mut self, mut p: StageProgress) -> StageProgress {
        if p.eta_from_stage {
            return p;
        }
        if p.label != self.label {
            self.label = p.label.clone();
            self.seen.clear();
        }
        self.seen.push_back((p.done, p.elapsed_s));
        if self.seen.len() > RECENT_LINES + 1 {
            self.seen.pop_front();
        }
        let (d0, e0) = self.seen[0];
        if p.done > d0 && p.elapsed_s >= e0 {
            let rate = (p.elapsed_s - e0) / (p.done - d0) as f64;
            p.eta_s = Some(rate * (p.total - p.done) as f64);
        }
        p
    }
}

pub use stagekit::progress::fmt_duration;

impl StageProgress {
    /// `iteration 1200/3000 (40 %), about 2 min 10 s left`.
    pub fn line(&self) -> String {
        let pct = 100 * self.done / self.total;
        let mut s = format!("{} {}/{} ({pct} %)", self.label, self.done, self.total);
        match self.eta_s {
            // Under a second left is not worth a word.
            Some(e) if self.done < self.total && e >= 1.0 => {
                s += &format!(", about {} left", fmt_duration(e))
            }
            _ => {}
        }
        s
    }

    /// The tenth of the work this line reached (0–10): a plain log gets a line per tenth.
    pub fn tenth(&self) -> u64 {
        10 * self.done / self.total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_stage_kit_lines_and_nothing_else() {
        let p = parse("[   12.5 s] iteration 250/1000: loss 0.0123, 8123 Gaussians").unwrap();
        assert_eq!(
            (p.label.as_str(), p.done, p.total),
            ("iteration", 250, 1000)
        );
        assert_eq!(p.elapsed_s, 12.5);
        // 12.5 s for a quarter: 37.5 s for the rest.
        assert!((p.eta_s.unwrap() - 37.5).abs() < 1e-12);
        assert_eq!(p.line(), "iteration 250/1000 (25 %), about 38 s left");
        assert_eq!(p.tenth(), 2);
        let q = parse("[    0.0 s] fine-tune pass 0/40").unwrap();
        assert_eq!(
            (q.label.as_str(), q.done, q.eta_s),
            ("fine-tune pass", 0, None)
        );
        assert_eq!(
            parse("[  3.0 s] frame 3/3").unwrap().line(),
            "frame 3/3 (100 %)"
        );
        for not in [
            "gaussians: reading settings.toml",
            "[   1.0 s] iteration 5/0",
            "[   1.0 s] iteration 6/5",
            "[x s] iteration 1/5",
            "[   1.0 s] 1/5",
            "error: [   1.0 s] iteration 1/5",
        ] {
            assert_eq!(parse(not), None, "{not}");
        }
    }

    /// A phase that slows down: 100 steps in 10 s, then 10 s per 100. The time left
    /// follows the recent rate, not the average since the start.
    #[test]
    fn time_left_follows_the_recent_rate() {
        let mut r = RecentRate::default();
        let line =
            |done: u64, t: f64| parse(&format!("[{t:7.1} s] iteration {done}/1000")).unwrap();
        // The first line: the rate since the start (10 s per 100).
        assert!((r.update(line(100, 10.0)).eta_s.unwrap() - 90.0).abs() < 1e-9);
        // Then 50 s per 100 steps: after four slow lines the window holds only them.
        let mut t = 10.0;
        let mut last = None;
        for k in 2..=6u64 {
            t += 50.0;
            last = r.update(line(100 * k, t)).eta_s;
        }
        // 400 steps left at 0.5 s each (the average since the start would say 173 s).
        assert!((last.unwrap() - 200.0).abs() < 1e-9, "{last:?}");
        // A new phase starts its own window.
        let p = r.update(StageProgress {
            label: "predict".into(),
            done: 1,
            total: 10,
            elapsed_s: 2.0,
            eta_s: Some(18.0),
            eta_from_stage: false,
        });
        assert_eq!(p.eta_s, Some(18.0));
    }

    /// A stage that knows its schedule ends its lines with its own estimate: the runner
    /// shows that, not the rate of the recent lines.
    #[test]
    fn the_stages_own_estimate_is_kept() {
        let line = stagekit::progress::plain_line(
            30.0,
            "iteration",
            350,
            3500,
            "loss 0.06  PSNR 18.90 dB",
        );
        let p = parse(&format!("{line} | left 1862 s")).unwrap();
        assert_eq!(
            (p.done, p.total, p.eta_s, p.eta_from_stage),
            (350, 3500, Some(1862.0), true)
        );
        let mut r = RecentRate::default();
        r.update(parse("[   10.0 s] iteration 175/3500 | left 1900 s").unwrap());
        assert_eq!(r.update(p).eta_s, Some(1862.0));
        assert_eq!(
            parse("[   30.0 s] iteration 350/3500 | left 1862 s")
                .unwrap()
                .line(),
            "iteration 350/3500 (10 %), about 31 min 02 s left"
        );
        // Not a number: an ordinary message.
        let q = parse("[   30.0 s] iteration 350/3500: a | left x s").unwrap();
        assert!(!q.eta_from_stage && (q.eta_s.unwrap() - 270.0).abs() < 1e-9);
    }

    #[test]
    fn durations_read_as_a_person_says_them() {
        assert_eq!(fmt_duration(44.6), "45 s");
        assert_eq!(fmt_duration(125.0), "2 min 05 s");
        assert_eq!(fmt_duration(3780.0), "1 h 03 min");
        assert_eq!(fmt_duration(-3.0), "0 s");
    }

    #[test]
    fn the_stage_kit_writes_what_the_runner_reads() {
        let line = stagekit::progress::plain_line(3.25, "deform", 40, 80, "loss 1");
        let p = parse(&line).unwrap();
        assert_eq!((p.label.as_str(), p.done, p.total), ("deform", 40, 80));
        let line = stagekit::progress::plain_line(0.5, "fine-tune pass", 0, 12, "");
        assert_eq!(parse(&line).unwrap().label, "fine-tune pass");
    }
}
