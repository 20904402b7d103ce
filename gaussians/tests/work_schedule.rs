//! The warm-up's time left (`train::work_schedule` through `stagekit::schedule`) against
//! the timelines of two real runs of the default warm-up: the stage's progress lines
//! (iteration, seconds) of the DAVIS346-size and the 640×480 runs of BENCHMARKS.md
//! ("Sensor-size recordings", "640×480 end to end"), the second sharing the machine with
//! other work. The truth is each run's own end time.

use gaussians::train::{TrainSettings, work_schedule};
use stagekit::schedule::TimeLeft;

/// Seconds at iterations 175, 350, …, 3500 (a line every twentieth).
const DAVIS346: [f64; 20] = [
    39.2, 48.7, 58.9, 69.0, 80.1, 100.4, 134.2, 168.5, 201.1, 237.7, 279.0, 326.8, 384.2, 448.2,
    522.0, 547.2, 572.6, 600.0, 624.3, 648.6,
];
const VGA: [f64; 20] = [
    232.8, 255.0, 282.1, 311.2, 342.2, 388.2, 472.1, 576.4, 706.4, 859.7, 967.6, 1096.2, 1255.7,
    1547.4, 1738.7, 1816.3, 1892.5, 1972.8, 2047.9, 2123.9,
];

/// Worst ratio (estimate / truth, or its inverse when under 1) over the lines from the
/// second to the second-to-last, for the schedule's estimate and for the plain rate of
/// the last two lines (what the runner showed before).
fn worst_ratios(times: &[f64; 20], pixels: usize) -> (f64, f64) {
    let s = TrainSettings::default();
    assert_eq!(
        s.iterations, 3500,
        "the timelines are of the default 3 500 iterations"
    );
    let t = TimeLeft::new(work_schedule(&s, pixels), 3500);
    let off = |est: f64, truth: f64| (est / truth).max(truth / est);
    let (mut sched, mut plain) = (1.0f64, 1.0f64);
    for (k, &secs) in times.iter().enumerate() {
        let pos = 175 * (k as u64 + 1);
        let est = t.update(pos, secs);
        if k == 0 || k == 19 {
            continue;
        }
        let truth = times[19] - secs;
        sched = sched.max(off(est.unwrap(), truth));
        let rate = (secs - times[k - 1]) / 175.0;
        plain = plain.max(off(rate * (3500 - pos) as f64, truth));
    }
    (sched, plain)
}

#[test]
fn the_warm_ups_time_left_follows_its_schedule_on_real_runs() {
    for (name, times, pixels) in [
        ("346×260", &DAVIS346, 346 * 260),
        ("640×480", &VGA, 640 * 480),
    ] {
        let (sched, plain) = worst_ratios(times, pixels);
        eprintln!(
            "{name}: worst ratio of the time left, schedule {sched:.2}, plain rate {plain:.2}"
        );
        // The plain rate was off by up to 5× (a fifth of the time left during the fast
        // half-resolution steps); the schedule stays within about 2× at every line,
        // the worst right after the sizing, whose own work falls in one interval.
        assert!(
            plain > 3.5,
            "{name}: the plain rate's worst ratio {plain:.2}"
        );
        assert!(
            sched < 2.2,
            "{name}: the schedule's worst ratio {sched:.2} (plain {plain:.2})"
        );
    }
}
