//! The event term's tiles (`deform::crop`): they cover every pixel once, a cropped
//! camera renders what the whole camera renders in that window (the rasterizer of the
//! whole image is the reference), and the pseudo image's window holds the same values.
//! And at lower resolution (`deform::coarse`): the coarse camera renders what the whole
//! camera's image averages to over each block.

use deform::crop::Crop;
use deform::event_image::PseudoImage;
use gaussians::TileRasterizer;
use gaussians::train::{TrainSettings, Trainer, init::random_splats};
use glam::DVec3;
use scene::{Camera, Intrinsics, Pose};

#[test]
fn the_tiles_cover_every_pixel_once() {
    for (w, h, k) in [
        (346, 260, 2),
        (346, 260, 3),
        (17, 5, 4),
        (8, 8, 1),
        (640, 480, 5),
    ] {
        let mut hits = vec![0u32; w * h];
        let mut areas = Vec::new();
        for t in 0..k * k {
            let c = Crop::tile(w, h, k, t);
            assert!(c.x0 + c.width <= w && c.y0 + c.height <= h, "{c:?} outside");
            for y in c.y0..c.y0 + c.height {
                for x in c.x0..c.x0 + c.width {
                    hits[y * w + x] += 1;
                }
            }
            areas.push(c.width * c.height);
        }
        assert!(
            hits.iter().all(|&n| n == 1),
            "{w}×{h}, k = {k}: not a partition"
        );
        // Equal tiles within a pixel of each side.
        let (lo, hi) = (areas.iter().min().unwrap(), areas.iter().max().unwrap());
        assert!(hi - lo <= w / k + h / k + 1, "{w}×{h}, k = {k}: {areas:?}");
    }
}

/// A `w × h` camera looking at `n` random Gaussians in a cube of half-size 0.8, and a
/// trainer holding them (no field).
fn cube_of_gaussians(w: usize, h: usize, n: usize) -> (Camera, Trainer) {
    let pose = Pose::look_at(DVec3::new(0.3, 0.2, 3.0), DVec3::ZERO, DVec3::Y);
    let camera = Camera {
        intrinsics: Intrinsics::from_fov_x(w as u32, h as u32, 0.9),
        cam_to_world: pose,
    };
    let settings = TrainSettings {
        deform: false,
        ..Default::default()
    };
    let splats = random_splats(n, DVec3::ZERO, 0.8, 7);
    (camera, Trainer::new(settings, splats, 1.0))
}

#[test]
fn a_cropped_camera_renders_the_window_of_the_whole_image() {
    let (w, h) = (96usize, 72usize);
    let (camera, tr) = cube_of_gaussians(w, h, 3000);
    let r = TileRasterizer;
    let full = tr.render_view(&r, &camera, 0.5);
    let reference = full.image.rgb.clone();
    // The whole image's buffers are reused by the crops (the trainer's spare pool).
    tr.recycle_view(full);
    let (mut worst, mut sum, mut n) = (0.0f32, 0.0f64, 0usize);
    for t in 0..9 {
        let c = Crop::tile(w, h, 3, t);
        let v = tr.render_view(&r, &c.camera(&camera), 0.5);
        assert_eq!(v.image.rgb.len(), 3 * c.width * c.height);
        for ch in 0..3 {
            for y in 0..c.height {
                for x in 0..c.width {
                    let a = v.image.rgb[ch * c.width * c.height + y * c.width + x];
                    let b = reference[ch * w * h + (c.y0 + y) * w + c.x0 + x];
                    worst = worst.max((a - b).abs());
                    sum += f64::from((a - b).abs());
                    n += 1;
                }
            }
        }
        tr.recycle_view(v);
    }
    let mean = sum / n as f64;
    eprintln!("crop vs whole image: largest difference {worst:.2e}, mean {mean:.2e}");
    // Tiles of the rasterizer fall elsewhere in a crop; a Gaussian's reach is cut at
    // its tile list, so values may differ by a faint Gaussian's tail, never more.
    assert!(reference.iter().any(|&x| x > 0.05), "nothing rendered");
    assert!(mean < 1e-4 && worst < 0.02, "largest {worst}, mean {mean}");
}

#[test]
fn the_pseudo_image_window_holds_the_same_values() {
    let (w, h, ch) = (11usize, 7usize, 3usize);
    let value = |c: usize, y: usize, x: usize| (c * 1000 + y * 100 + x) as f32;
    let mut full = PseudoImage::<f32>::default();
    (full.width, full.height, full.channels) = (w, h, ch);
    (full.log_eps, full.band_per_c, full.band) = (0.01, 0.25, 0.05);
    for c in 0..ch {
        for y in 0..h {
            for x in 0..w {
                full.data.push(value(c, y, x));
                full.valid.push((x + y + c) % 3 != 0);
                full.n_eff.push(-value(c, y, x));
            }
        }
    }
    let crop = Crop {
        x0: 3,
        y0: 2,
        width: 5,
        height: 4,
    };
    let mut out = PseudoImage::default();
    crop.pseudo(&full, &mut out);
    assert_eq!((out.width, out.height, out.channels), (5, 4, 3));
    assert_eq!((out.log_eps, out.band_per_c, out.band), (0.01, 0.25, 0.05));
    let mut i = 0;
    for c in 0..ch {
        for y in 2..6 {
            for x in 3..8 {
                assert_eq!(out.data[i], value(c, y, x));
                assert_eq!(out.valid[i], (x + y + c) % 3 != 0);
                assert_eq!(out.n_eff[i], -value(c, y, x));
                i += 1;
            }
        }
    }
    assert_eq!(i, out.data.len());
}

#[test]
fn the_coarse_camera_renders_the_block_means() {
    let (w, h) = (192usize, 144usize);
    // Few, wide Gaussians (about 8 px across): a smooth image, so a block mean is near
    // the value at its centre.
    let (camera, tr) = cube_of_gaussians(w, h, 200);
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
