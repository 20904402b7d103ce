//! The 2D baselines beside a model's figures: what the nearest train frame, the linear
//! blend of the two neighbouring train frames and the two-sided event pseudo image
//! score on the test frames. Computed from the scene with `deform::baselines` (with the
//! scene's frame encoding and contrast threshold, where the deform stage may have
//! overridden them by its settings), their images written beside the metrics so that
//! they can be scored like the model (LPIPS, moving pixels) and looked at.
//!
//! They predict the recorded camera's image at a time; none can render a new
//! viewpoint, so the novel views have no baseline figures.

use anyhow::{Context, Result};
use deform::baselines::{BaselineScore, Recording};
use gaussians::stage::load_views;
use scene::evaluation::{BaselineFigures, COMPUTED, Score};
use scene::image_io::{Image, write_png};
use scene::manifest::Scene;
use std::path::{Path, PathBuf};

/// The images of the baselines on the test frames, written by [`compute`]: per baseline
/// its name (`nearest`, `blend`, `events`) and its PNG per test frame, in order.
pub(crate) type BaselineImages = Vec<(&'static str, Vec<PathBuf>)>;

/// Score the baselines on the scene's test frames and write their images under
/// `dir/baselines/NAME/NNNN.png` (8-bit, the frames' encoding); None when the scene has
/// no test frames. Errors name the file that could not be read (an image, the event
/// stream).
pub fn compute(scene: &Scene, dir: &Path) -> Result<Option<(BaselineFigures, BaselineImages)>> {
    if scene.test.frames.is_empty() {
        return Ok(None);
    }
    let train = load_views(scene, &scene.train)?;
    let test = load_views(scene, &scene.test)?;
    let times: Vec<f64> = scene.train.frames.iter().map(|f| f.timestamp).collect();
    let test_times: Vec<f64> = scene.test.frames.iter().map(|f| f.timestamp).collect();
    let events = match scene.events_path() {
        Some(_) => Some(scene.load_events()?),
        None => None,
    };
    let rec = Recording {
        train: &train,
        times: &times,
        events: events.as_ref(),
        contrast: scene.contrast_threshold(),
        srgb: scene.train.frames_srgb(),
    };
    let b = deform::baselines::evaluate(&rec, &test, &test_times, None);
    let score = |s: &BaselineScore| Score {
        psnr_mean: s.psnr_mean,
        ssim_mean: s.ssim_mean,
        ..Score::default()
    };
    let mut images = Vec::new();
    for (name, s) in [
        ("nearest", Some(&b.nearest)),
        ("blend", Some(&b.blend)),
        ("events", b.events.as_ref()),
    ] {
        let Some(s) = s else { continue };
        let out = dir.join("baselines").join(name);
        std::fs::create_dir_all(&out).with_context(|| format!("{}", out.display()))?;
        let mut paths = Vec::with_capacity(s.images.len());
        for (k, (planar, view)) in s.images.iter().zip(&test).enumerate() {
            let (w, h) = (view.camera.intrinsics.width, view.camera.intrinsics.height);
            let n = (w * h) as usize;
            let data = (0..n)
                .flat_map(|i| [planar[i], planar[n + i], planar[2 * n + i]])
                .map(|v| v.clamp(0.0, 1.0))
                .collect();
            let path = out.join(format!("{k:04}.png"));
            write_png(
                &path,
                &Image {
                    width: w,
                    height: h,
                    channels: 3,
                    data,
                },
            )?;
            paths.push(path);
        }
        images.push((name, paths));
    }
    let figures = BaselineFigures {
        nearest: score(&b.nearest),
        blend: score(&b.blend),
        events: b.events.as_ref().map(score),
        source: COMPUTED.to_string(),
    };
    Ok(Some((figures, images)))
}
