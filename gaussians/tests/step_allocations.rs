//! Once warm, a training step reuses its per-Gaussian buffers: the bytes a step allocates
//! (counted by a global allocator in this test binary) grow by less than 128 B per
//! Gaussian (gemm's own packing buffers) and are otherwise a few images' worth (the
//! loss). Before the reuse of buffers, a step allocated ≈ 1.9 KB per Gaussian (the field's
//! activations, the deformed copy, the gradients, the rasterizer's lists).

mod raster_common;

use gaussians::field::FieldSettings;
use gaussians::raster::TileRasterizer;
use gaussians::train::{TrainSettings, Trainer, View};
use glam::DVec3;
use raster_common::*;
#[global_allocator]
static ALLOC: testkit::TrackingAlloc = testkit::TrackingAlloc;

const W: u32 = 64;
const H: u32 = 48;

/// Bytes allocated per step, averaged over 6 steps after 6 warm ones, with `n` Gaussians
/// and the field on.
fn bytes_per_step(n: usize) -> usize {
    let r = TileRasterizer;
    let truth = |k: usize| {
        let kind = SceneKind {
            n: 200,
            spread: 1.0,
            log_scale: (-2.5, -1.5),
            logit: (0.0, 3.0),
            sh_rest: 0.2,
        };
        random_splats(&mut Rng(100 + k as u64), kind)
    };
    let views: Vec<View> = (0..3)
        .map(|k| {
            let camera = camera(W, H, 50.0, DVec3::new(0.3 * k as f64 - 0.3, 0.1, 4.0));
            let rgb = TileRasterizer
                .render_full(&truth(k), &camera, 0, [0.0; 3])
                .0
                .rgb;
            View {
                camera,
                time: 0.4 * k as f32,
                rgb,
            }
        })
        .collect();
    let mut settings = TrainSettings {
        static_iterations: 0,
        field: FieldSettings {
            depth: 2,
            width: 32,
            ..Default::default()
        },
        ..Default::default()
    };
    // No densification inside the measurement.
    settings.densify.from_iter = 1000;
    let kind = SceneKind {
        n,
        spread: 1.0,
        log_scale: (-3.5, -2.5),
        logit: (-1.0, 2.0),
        sh_rest: 0.1,
    };
    let mut t = Trainer::new(settings, random_splats(&mut Rng(7), kind), 1.0);
    for _ in 0..6 {
        t.step(&r, &views);
    }
    let ((), bytes) = testkit::alloc::allocated_during(|| {
        for _ in 0..6 {
            t.step(&r, &views);
        }
    });
    bytes / 6
}

#[test]
fn a_warm_step_allocates_little_per_gaussian() {
    let _alone = testkit::alloc::exclusive();
    assert!(testkit::alloc::installed());
    let small = bytes_per_step(2_000);
    let large = bytes_per_step(8_000);
    let image = (W * H) as usize * 3 * 4;
    eprintln!("bytes per step: {small} (2 000 Gaussians), {large} (8 000); image {image}");
    // Per Gaussian what remains is gemm's packing buffers (≈ 80 B, allocated inside each
    // gemm call); before the reuse a step allocated 1.9 KB per Gaussian.
    let per_gaussian = large.saturating_sub(small) / 6_000;
    assert!(per_gaussian < 128, "{small} → {large} bytes per step");
    // Per pixel what remains is the loss's buffers (L1 and D-SSIM and their gradients).
    assert!(
        large < 32 * image + 128 * 8_000,
        "{large} bytes per step, image {image}"
    );
}
