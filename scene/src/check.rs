//! What a scene can be wrong about that no stage would notice, or would notice only after
//! minutes of work: the findings `degs import`, `degs synth`, `degs plan`/`run`,
//! `status` and `eval` report before (or beside) their results (DESIGN §3, "Scene
//! checks"). Errors make the result meaningless (a test frame that is a train frame, no
//! event within the frames' span); warnings leave it usable but weaker.

use crate::Result;
use crate::manifest::{Frame, Scene};
use std::fmt;

/// How bad a [`Finding`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    /// Every score or model made from the scene would mislead: refuse to run.
    Error,
    /// Usable, but the user should know.
    Warning,
}

/// One thing found wrong with a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Finding {
    pub level: Level,
    pub message: String,
}

impl fmt::Display for Finding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let tag = match self.level {
            Level::Error => "error",
            Level::Warning => "warning",
        };
        write!(f, "{tag}: {}", self.message)
    }
}

/// Two frames are one when their times agree to this (seconds) and their poses'
/// matrices to [`SAME_POSE`].
pub(crate) const SAME_TIME_S: f64 = 1e-9;
/// See [`SAME_TIME_S`].
pub(crate) const SAME_POSE: f64 = 1e-9;

/// The findings on a scene's splits and on its event times (`events_t`, sorted; None
/// when the scene has no events).
pub fn check_frames(train: &[Frame], test: &[Frame], events_t: Option<&[f64]>) -> Vec<Finding> {
    let mut out = Vec::new();
    let mut push = |level, message: String| out.push(Finding { level, message });
    if train.len() < 2 {
        push(
            Level::Warning,
            format!(
                "{} train frame{}: nothing ties the model between frames, and the flow \
                 stage has no interval between train frames to work on",
                train.len(),
                if train.len() == 1 { "" } else { "s" }
            ),
        );
    }
    if test.is_empty() {
        push(
            Level::Warning,
            "no test frames: no held-out score (PSNR, SSIM, LPIPS) can be made; hold \
             frames out (`degs import --test-every N`, synth `test_frames`)"
                .into(),
        );
    }
    let same = |a: &Frame, b: &Frame| {
        (a.timestamp - b.timestamp).abs() <= SAME_TIME_S
            && (a.cam_to_world.matrix() - b.cam_to_world.matrix())
                .to_cols_array()
                .iter()
                .all(|d| d.abs() <= SAME_POSE)
    };
    let dup: Vec<(usize, usize)> = test
        .iter()
        .enumerate()
        .filter_map(|(i, t)| train.iter().position(|r| same(r, t)).map(|j| (i, j)))
        .collect();
    if let Some(&(i, j)) = dup.first() {
        push(
            Level::Error,
            format!(
                "{} of {} test frames are train frames (same time and camera; test frame \
                 {i} at {} s is train frame {j}): their scores would be on frames the \
                 model trained on",
                dup.len(),
                test.len(),
                test[i].timestamp
            ),
        );
    }
    if let Some(t) = events_t {
        let frames = train.iter().chain(test).map(|f| f.timestamp);
        let (f0, f1) = frames.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), t| {
            (a.min(t), b.max(t))
        });
        match (t.first(), t.last()) {
            // One time only (a single frame): no span to compare with.
            (Some(&e0), Some(&e1)) if f0.is_finite() && f1 > f0 => {
                let inside = t.partition_point(|&x| x <= f1) - t.partition_point(|&x| x < f0);
                if inside == 0 {
                    push(
                        Level::Error,
                        format!(
                            "none of the {} events ({e0} … {e1} s) lies within the frames' \
                             span ({f0} … {f1} s): are frames and events on one clock?",
                            t.len()
                        ),
                    );
                } else {
                    let covered = (e1.min(f1) - e0.max(f0)) / (f1 - f0).max(f64::MIN_POSITIVE);
                    if covered < 0.9 {
                        push(
                            Level::Warning,
                            format!(
                                "the events ({e0} … {e1} s) cover {:.0} % of the frames' \
                                 span ({f0} … {f1} s): frames without events near them \
                                 get no event supervision",
                                100.0 * covered.max(0.0)
                            ),
                        );
                    }
                }
            }
            (None, _) => push(Level::Warning, "the event file holds no events".into()),
            _ => {}
        }
    }
    out
}

/// The findings on an opened scene (its events read when it has any).
pub fn check_scene(scene: &Scene) -> Result<Vec<Finding>> {
    let events = match scene.events_path() {
        Some(_) => Some(scene.load_events()?),
        None => None,
    };
    Ok(check_frames(
        &scene.train.frames,
        &scene.test.frames,
        events.as_ref().map(|e| e.t.as_slice()),
    ))
}

/// The first error among `findings`, as one line naming `what` (a scene folder).
pub fn first_error(what: &std::path::Path, findings: &[Finding]) -> Option<crate::Error> {
    findings
        .iter()
        .find(|f| f.level == Level::Error)
        .map(|f| crate::Error::invalid(what, f.message.clone()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Pose;

    fn frame(t: f64, x: f64) -> Frame {
        let mut p = Pose::default();
        p.translation.x = x;
        Frame {
            file_path: String::new(),
            timestamp: t,
            time: t,
            cam_to_world: p,
        }
    }

    fn levels(f: &[Finding]) -> Vec<Level> {
        f.iter().map(|f| f.level).collect()
    }

    #[test]
    fn a_clean_scene_has_no_findings() {
        let train = [frame(0.0, 0.0), frame(1.0, 0.0)];
        let test = [frame(0.5, 0.0)];
        let ev = [0.0, 0.2, 0.9, 1.0];
        assert!(check_frames(&train, &test, Some(&ev)).is_empty());
    }

    #[test]
    fn test_frames_on_train_frames_are_errors_unless_the_camera_differs() {
        let train = [frame(0.0, 0.0), frame(1.0, 0.0)];
        let f = check_frames(&train, &[frame(1.0, 0.0), frame(0.5, 0.0)], None);
        assert_eq!(levels(&f), [Level::Error]);
        assert!(f[0].message.starts_with("1 of 2 test frames"), "{}", f[0]);
        // D-NeRF: a test view at a train time from another camera is a fair test.
        assert!(check_frames(&train, &[frame(1.0, 0.3)], None).is_empty());
    }

    #[test]
    fn events_off_the_frames_clock_are_errors_and_partial_cover_a_warning() {
        let train = [frame(0.0, 0.0), frame(1.0, 0.0)];
        let test = [frame(0.5, 0.0)];
        let f = check_frames(&train, &test, Some(&[5.0, 5.5, 6.0]));
        assert_eq!(levels(&f), [Level::Error]);
        assert!(f[0].message.contains("none of the 3 events"), "{}", f[0]);
        let f = check_frames(&train, &test, Some(&[0.0, 0.3, 0.5]));
        assert_eq!(levels(&f), [Level::Warning]);
        assert!(f[0].message.contains("cover 50 %"), "{}", f[0]);
        let f = check_frames(&train, &test, Some(&[]));
        assert_eq!(levels(&f), [Level::Warning]);
    }

    #[test]
    fn one_train_frame_and_no_test_frames_are_warnings() {
        let f = check_frames(&[frame(0.0, 0.0)], &[], Some(&[0.1, 0.2]));
        assert_eq!(levels(&f), [Level::Warning, Level::Warning]);
        assert!(f[0].message.starts_with("1 train frame:"), "{}", f[0]);
        assert!(f[1].message.starts_with("no test frames"), "{}", f[1]);
    }
}
