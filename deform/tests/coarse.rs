//! The event term at lower resolution (`deform::coarse`): the coarse camera renders
//! what the whole camera's image averages to over each block (the rasterizer at full
//! resolution, averaged over the blocks, is the reference).

use gaussians::TileRasterizer;
use gaussians::train::{TrainSettings, Trainer, init::random_splats};
use glam::DVec3;
use scene::{Camera, Intrinsics, Pose};

#[test]
fn the_coarse_camera_renders_the_block_means() {
    let (w, h) = (192usize, 144usize);
    let pose = Pose::look_at(DVec3::new(0.3, 0.2, 3.0), DVec3::ZERO, DVec3::Y);
    let camera = Camera {
        intrinsics: Intrinsics::from_fov_x(w as u32, h as u32, 0.9),
        cam_to_world: pose,
    };
    // Few, wide Gaussians (about 8 px across): a smooth image, so a block mean is near
    // the value at its centre.
    let splats = random_splats(200, DVec3::ZERO, 0.8, 7);
    let settings = TrainSettings {
        deform: false,
        ..Default::default()
    };
    let tr = Trainer::new(settings, splats, 1.0);
    let r = TileRasterizer;
    let full = tr.render_view(&r, &camera, 0.5).image.rgb;
    for k in [2usize, 3] {
        let c = deform::coarse::camera(&camera, k);
        let (w2, h2) = (w / k, h / k);
        let coarse = tr.render_view(&r, &c, 0.5).image.rgb;
        assert_eq!(coarse.len(), 3 * w2 * h2);
        // The blocks' centres put at `c/k` instead of `(c − (k−1)/2)/k`: a shift of
        // (k−1)/(2k) block, the mistake this guards against.
        let mut naive_cam = c;
        naive_cam.intrinsics.cx = camera.intrinsics.cx / k as f64;
        naive_cam.intrinsics.cy = camera.intrinsics.cy / k as f64;
        let naive = tr.render_view(&r, &naive_cam, 0.5).image.rgb;
        let (mut sum, mut base, mut n) = (0.0f64, 0.0f64, 0usize);
        for ch in 0..3 {
            for y in 0..h2 {
                for x in 0..w2 {
                    let mut mean = 0.0f64;
                    for dy in 0..k {
                        for dx in 0..k {
                            mean += f64::from(full[ch * w * h + (k * y + dy) * w + k * x + dx]);
                        }
                    }
                    mean /= (k * k) as f64;
                    let a = f64::from(coarse[ch * w2 * h2 + y * w2 + x]);
                    sum += (a - mean).abs();
                    base += (f64::from(naive[ch * w2 * h2 + y * w2 + x]) - mean).abs();
                    n += 1;
                }
            }
        }
        let (mean, shifted) = (sum / n as f64, base / n as f64);
        eprintln!(
            "k = {k}: mean difference to the block means {mean:.4}, centres at c/k {shifted:.4}"
        );
        assert!(
            mean < 0.6 * shifted,
            "k = {k}: {mean} against {shifted} at c/k"
        );
    }
}
