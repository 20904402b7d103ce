//! The tracks init's settings (`[tracks]` in the warm-up's `settings.toml`).

/// Settings of the tracks init (`[tracks]` in `settings.toml`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackSettings {
    /// Half-size of the Lucas–Kanade window, pixels (window `2r + 1`, at most 16).
    pub radius: u32,
    /// Pyramid levels (1 = no pyramid).
    pub levels: u32,
    /// Smallest eigenvalue of the window's structure tensor per pixel for a trackable
    /// window (grey levels² per pixel²).
    pub min_texture: f32,
    /// A link is kept when tracking it back lands within this many pixels.
    pub forward_backward: f32,
    /// A track is a still point when its rays meet within this RMS reprojection error.
    pub still_pixels: f64,
    /// A moving track is kept when its trajectory fits within this RMS error.
    pub moving_pixels: f64,
    /// Penalty on a trajectory's acceleration, relative to the angular residuals.
    pub ridge: f64,
    /// Weight of the track term `L_track` in the warm-up ([`super::loss`]): each moving track's
    /// Gaussian is pulled to where its track saw it in every train frame (0 = the tracks
    /// only start the trajectories).
    pub weight: f64,
    /// Residual (pixels) above which `L_track` grows linearly (Huber): a track that
    /// drifted pulls no harder than this.
    pub huber_px: f64,
    /// `L_track`'s gradient also trains the deformation field (else only the tracked
    /// Gaussians' own centres and trajectories).
    pub into_field: bool,
    /// With a depth prior (`scene::depth_prior`): the relative depth error that costs as
    /// much as one pixel of reprojection error when a moving track is lifted, and a third
    /// of the disagreement with the prior that makes a track whose rays meet moving
    /// after all (its 2D motion mimicked a still point's parallax). 0 ignores the prior.
    pub depth_sigma: f64,
    /// The acceleration penalty in place of `ridge` for a track with prior depths (with
    /// them its distance is known: the penalty only keeps the fit well conditioned).
    pub depth_ridge: f64,
    /// With a depth prior, drop the initial (stereo) Gaussians that lie off the prior's
    /// surface in most frames they project into ([`super::drop_where_prior_disagrees`]). Off:
    /// measured +0.3 dB on `rigid`'s co-visible novel pixels but −0.4 on its moving ones,
    /// and −1.3 dB co-visible on `fast` at 4 fps, where the alignment is poorer.
    pub prior_prunes: bool,
    /// With a depth prior, the weight of `L_depth` in the warm-up and the joint training
    /// ([`super::prior_loss`]): each train view's rendered depth pulled to its aligned prior
    /// (0 = off). 0.1 measured best of 0.01, 0.1, 0.3 and 1 (BENCHMARKS.md, "The prior in
    /// the loss").
    pub depth_weight: f64,
    /// Event images per frame interval that the tracks are chained through ([`super::events`]):
    /// the events carry a window across motion too large for Lucas–Kanade between two
    /// frames. 0 = the frames alone (also when the scene has no events).
    pub event_steps: u32,
    /// Frames per window of the moving tracks' trajectories ([`super::init`]): a moving track
    /// that one quadratic holds over most of the recording (seen in ¾ of the frames)
    /// keeps one Gaussian from the middle frame; the others come from each window's
    /// middle frame, fitted over the window (and a frame either side) and shown only
    /// within it. 0 = the frames that `window_s` spans. With both 0, one trajectory
    /// over the recording for every track, from the middle frame.
    pub window: u32,
    /// Seconds of recording a window spans when `window` = 0: `1 + round(window_s / Δt)`
    /// frames, at least 2, Δt the train frames' median interval
    /// ([`TrackSettings::window_frames`]). A quadratic holds a turn for a stretch of
    /// time, not of frames: on the path-traced `spin` windows of 5 frames win at 20 fps
    /// and lose at 10 fps, where 3 win (BENCHMARKS.md, "The windows' handover at
    /// the frames").
    pub window_s: f64,
    /// Every this many pixels (in x and in y) a track starts in a reference frame, and
    /// a moving track's Gaussian covers that footprint. 0 = automatic: 1 up to
    /// [`AUTO_STRIDE_PIXELS`] pixels a frame, else the smallest stride that starts at most
    /// that many ([`TrackSettings::stride_for`]): the init's cost grows with the tracks.
    pub stride: u32,
    /// Where one window's copies hand over to the next ([`Handover`]).
    pub handover: Handover,
    /// Weight of the shape term ([`super::rigid`]): neighbouring tracked Gaussians of
    /// one life keep their distances over time, so a moving object keeps its size and
    /// a depth prior's frame-to-frame error cannot make it breathe along the rays
    /// (0 = off).
    pub rigidity: f64,
    /// Neighbours per tracked Gaussian in the shape term.
    pub rigidity_neighbours: u32,
    /// Pairs per tracked Gaussian in the shape term with other members of its part, across
    /// the object ([`super::rigid`]; 0 = the neighbours only).
    pub rigidity_far: u32,
    /// Weight of the depth distortion on the train views in the warm-up and the joint
    /// training (`raster::Distortion`, [`super::prior_loss::distortion_weights`]): one
    /// depth per pixel, not layers in front and behind whose blend lands on it (which a
    /// new viewpoint parts into copies). 0 = off.
    pub distortion: f64,
    /// Weight of the prior's depth on every moving Gaussian blended into a pixel, not only
    /// on the blend (`raster::Anchor`, [`super::prior_loss::anchor_weights`], the movers
    /// [`super::prior_loss::movers`]): where `L_depth` lets a front and a back layer
    /// average to the prior's depth, this pulls each layer to it, in the warm-up and the
    /// joint training. 0 = off.
    pub depth_samples: f64,
    /// The relative depth difference that is one unit of `depth_samples`' Huber: within
    /// it a layer is pulled in proportion (so the prior's own error, a few %, pulls
    /// little), beyond it with a constant force.
    pub depth_samples_sigma: f64,
    /// Group the moving tracks' Gaussians into rigid parts that share one motion over the
    /// recording, a pose per train frame ([`crate::parts`], [`super::parts`]): a part's
    /// size is then one number the depth prior's frames average into. A group is made a
    /// part only when a third of its members were followed at every train frame, so
    /// extreme motion, whose tracks are windows of a few frames, keeps its own
    /// trajectories. On by default: +0.6 to +1.7 dB on the moving novel pixels of `rigid`,
    /// `nonrigid` and `moderate`, `fast` 8 fps unchanged (BENCHMARKS.md, "Parts only where
    /// their motion was seen").
    pub parts: bool,
    /// With `parts`, bundle adjust each part ([`super::bundle`]): its poses and its
    /// members' centres fitted to the tracks' pixels and to the prior's depths, in place
    /// of the poses chained from the members' trajectories, then scaled to the lifts'
    /// depth at the middle frame. On by default (it acts only with `parts`): +0.16 to
    /// +0.56 dB on the moving novel pixels of `rigid` and `nonrigid` at 4 and 8 fps, a
    /// tie on `fast` (BENCHMARKS.md, "The adjusted part at the lifts' distance").
    pub bundle: bool,
    /// Up to this many links of a track that fail (lost, or back further than
    /// `forward_backward`) are carried by the affine motion their neighbours' links agree
    /// on ([`super::fill`]) instead of ending it: the tracks of a reference frame advance
    /// together, frame by frame. 0 = off.
    pub fill: u32,
    /// With `parts`, a group whose members were followed at too few train frames (the
    /// gate above) is followed instead as one rigid body through the images
    /// ([`super::part_motion`]): the frames and this many event images per frame
    /// interval (the frames alone where the scene has no events). 0 = such groups keep
    /// their own trajectories.
    pub part_steps: u32,
}

/// Where the windows of trajectories hand over (`tracks.handover`; [`super::init::windows`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Handover {
    /// Runs of `window` frames; a run's copies live from midway to the previous run's
    /// last frame to midway to the next one's first. The time at a life's end lies half
    /// an interval beyond the frames its copies are drawn at.
    Midway,
    /// Runs of `window` frames that share their end frames (a run starts at the previous
    /// one's last frame); a run's copies live from its first frame to its last, and a
    /// train view at a shared frame draws either run's copies (half of its views each,
    /// [`crate::motion::life_clock_shared`]): every time lies between two frames its
    /// copies were fitted to.
    #[default]
    Frame,
}

/// Tracked pixels per reference frame the automatic stride keeps to (128²).
pub const AUTO_STRIDE_PIXELS: usize = 128 * 128;

impl Default for TrackSettings {
    fn default() -> Self {
        TrackSettings {
            radius: 3,
            levels: 3,
            min_texture: 1e-5,
            forward_backward: 1.0,
            still_pixels: 1.0,
            moving_pixels: 2.0,
            ridge: 10.0,
            weight: 0.0,
            huber_px: 1.0,
            into_field: true,
            depth_sigma: 0.05,
            depth_ridge: 1e-3,
            prior_prunes: false,
            depth_weight: 0.1,
            event_steps: 2,
            window: 0,
            window_s: 0.2,
            stride: 0,
            handover: Handover::Frame,
            rigidity: 0.0,
            rigidity_neighbours: 8,
            rigidity_far: 0,
            distortion: 0.0,
            depth_samples: 0.0,
            depth_samples_sigma: 0.3,
            parts: true,
            bundle: true,
            fill: 0,
            part_steps: 0,
        }
    }
}

impl TrackSettings {
    /// The stride for frames of `width × height` pixels: `stride`, or when 0 the
    /// smallest `s` with `⌈w/s⌉·⌈h/s⌉ ≤` [`AUTO_STRIDE_PIXELS`].
    pub fn stride_for(&self, width: usize, height: usize) -> usize {
        if self.stride > 0 {
            return self.stride as usize;
        }
        (1..)
            .find(|&s| width.div_ceil(s) * height.div_ceil(s) <= AUTO_STRIDE_PIXELS)
            .unwrap_or(1)
    }

    /// The frames per window ([`Self::window`]) for train frames at `seconds` (in time
    /// order): `window`, or when 0 the frames `window_s` spans; 0 = no windows.
    pub fn window_frames(&self, seconds: &[f64]) -> u32 {
        let n = seconds.len();
        if self.window > 0 || self.window_s <= 0.0 || n < 2 {
            return self.window;
        }
        let interval = scene::manifest::median_interval(seconds);
        match interval > 0.0 {
            true => (1.0 + (self.window_s / interval).round()).clamp(2.0, n as f64) as u32,
            false => 0,
        }
    }

    pub fn validate(&self) -> Result<(), String> {
        if self.stride > 64 {
            return Err(format!(
                "tracks: stride = {} must be at most 64",
                self.stride
            ));
        }
        if !(1..=16).contains(&self.radius) || !(1..=8).contains(&self.levels) {
            return Err("tracks: radius must be 1..=16 and levels 1..=8".into());
        }
        if self.event_steps > 32 {
            return Err("tracks: event_steps must be at most 32".into());
        }
        let positive = [
            self.forward_backward as f64,
            self.still_pixels,
            self.moving_pixels,
        ];
        if positive.iter().any(|v| !(v.is_finite() && *v > 0.0))
            || !(self.ridge >= 0.0 && self.min_texture >= 0.0)
            || !(self.weight.is_finite() && self.weight >= 0.0)
            || !(self.huber_px.is_finite() && self.huber_px > 0.0)
            || !(self.depth_sigma.is_finite() && self.depth_sigma >= 0.0)
            || !(self.depth_ridge.is_finite() && self.depth_ridge >= 0.0)
            || !(self.depth_weight.is_finite() && self.depth_weight >= 0.0)
            || !(self.window_s.is_finite() && self.window_s >= 0.0)
            || !(self.rigidity.is_finite() && self.rigidity >= 0.0)
            || !(self.distortion.is_finite() && self.distortion >= 0.0)
            || !(self.depth_samples.is_finite() && self.depth_samples >= 0.0)
            || !(self.depth_samples_sigma.is_finite() && self.depth_samples_sigma > 0.0)
            || !(1..=64).contains(&self.rigidity_neighbours)
            || self.rigidity_far > 64
        {
            return Err(
                "tracks: thresholds and huber_px must be positive, ridge, min_texture, \
                 weight, depth_sigma, depth_ridge, depth_weight, window_s, rigidity, distortion and depth_samples finite and ≥ 0, \
                 depth_samples_sigma positive, \
                 rigidity_neighbours 1..=64, rigidity_far 0..=64"
                    .into(),
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::TrackSettings;

    #[test]
    fn the_automatic_stride_keeps_to_128_squared_tracked_pixels() {
        let st = TrackSettings::default();
        // ⌈w/s⌉·⌈h/s⌉ ≤ 16 384, worked by hand
        assert_eq!(st.stride_for(96, 96), 1);
        assert_eq!(st.stride_for(128, 128), 1);
        assert_eq!(st.stride_for(129, 128), 2); // 129·128 > 16 384, 65·64 fits
        assert_eq!(st.stride_for(346, 260), 3); // 173·130 = 22 490; 116·87 = 10 092
        assert_eq!(st.stride_for(640, 480), 5); // 160·120 = 19 200; 128·96 = 12 288
        let fixed = TrackSettings {
            stride: 2,
            ..Default::default()
        };
        assert_eq!(fixed.stride_for(640, 480), 2);
    }

    #[test]
    fn the_windows_span_window_s_at_any_frame_rate() {
        let st = TrackSettings::default();
        let at =
            |fps: f64, n: usize| -> Vec<f64> { (0..n).map(|k| 2.0 + k as f64 / fps).collect() };
        // 1 + round(0.2 s · fps), at least 2, by hand
        assert_eq!(st.window_frames(&at(20.0, 21)), 5);
        assert_eq!(st.window_frames(&at(10.0, 11)), 3);
        assert_eq!(st.window_frames(&at(8.0, 9)), 3); // 1.6 intervals
        assert_eq!(st.window_frames(&at(4.0, 5)), 2); // 0.8 of one
        assert_eq!(st.window_frames(&at(40.0, 41)), 9);
        assert_eq!(st.window_frames(&at(40.0, 3)), 3); // not more than the frames
        assert_eq!(st.window_frames(&at(20.0, 1)), 0);
        let frames = TrackSettings { window: 4, ..st };
        assert_eq!(frames.window_frames(&at(20.0, 21)), 4);
        let none = TrackSettings {
            window_s: 0.0,
            ..st
        };
        assert_eq!(none.window_frames(&at(20.0, 21)), 0);
    }
}
