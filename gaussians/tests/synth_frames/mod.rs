//! A synthetic world's renders as the tracks init's frames (the tracks tests).

use gaussians::tracks::Frame;
use gaussians::tracks::lk::{Grey, Pyramid};
use scene::Camera;

/// One frame per camera and render, its time normalised over `[first, last]`, its
/// image the render's luma in a pyramid of three levels.
pub fn frames<'a>(
    cams: &'a [Camera],
    times: &[f64],
    renders: &[synth::Render],
    (first, last): (f64, f64),
) -> Vec<Frame<'a>> {
    (cams.iter().zip(times).zip(renders))
        .map(|((camera, &t), r)| Frame {
            camera,
            time: (t - first) / (last - first),
            pyramid: Pyramid::new(
                Grey {
                    width: r.width as usize,
                    height: r.height as usize,
                    data: (r.rgb.chunks_exact(3))
                        .map(|c| 0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2])
                        .collect(),
                },
                3,
            ),
            between: Vec::new(),
        })
        .collect()
}
