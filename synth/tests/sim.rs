//! Event simulator: exact crossings on ramps, determinism, noise, refractory period.

use scene::EventStream;
use scene::manifest::FrameEncoding;
use stagekit::Settings;
use synth::frames::{read_timestamps, simulate_frames};
use synth::sim::{SimConfig, Simulator, luminance};

const EPS: f64 = 1e-3;

fn clean(c: f64) -> SimConfig {
    SimConfig {
        threshold_pos: c,
        threshold_neg: c,
        threshold_sigma: 0.0,
        ..SimConfig::default()
    }
}

/// Luminance whose log(ε + Y) is `l`.
fn lum_of_log(l: f64) -> f32 {
    (l.exp() - EPS) as f32
}

/// Feed a 1×1 ramp `L(t) = l0 + slope·t` at `times`; return the stream.
fn ramp(cfg: &SimConfig, l0: f64, slope: f64, times: &[f64]) -> EventStream {
    let mut sim = Simulator::new(1, 1, cfg, 7);
    let mut out = EventStream::new(1, 1);
    for &t in times {
        sim.push_frame(t, &[lum_of_log(l0 + slope * t)], &mut out)
            .unwrap();
    }
    out
}

#[test]
fn ramp_count_polarity_and_crossing_times_are_exact() {
    let c = 0.1;
    let cfg = clean(c);
    let times = [0.0, 0.2, 0.45, 0.7, 1.0];
    for (l0, slope) in [
        (0.5f64.ln(), 0.37),
        (0.8f64.ln(), -0.83),
        (0.05f64.ln(), 1.234),
    ] {
        let out = ramp(&cfg, l0, slope, &times);
        let start = (EPS + lum_of_log(l0) as f64).ln();
        let end = (EPS + lum_of_log(l0 + slope) as f64).ln();
        let expected = ((end - start).abs() / c).floor() as usize;
        assert_eq!(out.len(), expected, "slope {slope}");
        assert_eq!(expected, (slope.abs() / c).floor() as usize);
        for (k, (&t, &p)) in out.t.iter().zip(&out.p).enumerate() {
            assert_eq!(p as f64, slope.signum());
            // Level crossing k+1 of the (linear in t) log ramp.
            let t_cross = (k + 1) as f64 * c / slope.abs();
            assert!((t - t_cross).abs() < 1e-6, "event {k}: {t} vs {t_cross}");
        }
        out.validate().unwrap();
    }
}

#[test]
fn ramp_up_then_down_changes_polarity_at_the_right_levels() {
    let cfg = clean(0.2);
    let mut sim = Simulator::new(1, 1, &cfg, 0);
    let mut out = EventStream::new(1, 1);
    // L: 0 → 0.5 → 0.05 (log units, relative to ln(0.3)).
    let base = 0.3f64.ln();
    for (t, l) in [(0.0, 0.0), (1.0, 0.5), (2.0, 0.05)] {
        sim.push_frame(t, &[lum_of_log(base + l)], &mut out)
            .unwrap();
    }
    // Up: crossings at 0.2, 0.4 (t = 0.4, 0.8); reference 0.4. Down: 0.4 → 0.2 at
    // L = 0.2 (t = 1 + 0.3/0.45); 0.2 → 0.0 would need L ≤ 0.0 — not reached.
    assert_eq!(out.p, vec![1, 1, -1]);
    let expected = [0.4, 0.8, 1.0 + 0.3 / 0.45];
    for (t, e) in out.t.iter().zip(expected) {
        assert!((t - e).abs() < 1e-6, "{:?}", out.t);
    }
}

#[test]
fn static_image_gives_no_events_without_noise() {
    let cfg = SimConfig::default(); // with threshold mismatch, no noise
    let (w, h) = (16u32, 9u32);
    let frame: Vec<f32> = (0..w * h).map(|i| (i % 7) as f32 / 7.0).collect();
    let mut sim = Simulator::new(w, h, &cfg, 3);
    let mut out = EventStream::new(w, h);
    for k in 0..10 {
        assert_eq!(
            sim.push_frame(k as f64 * 0.01, &frame, &mut out).unwrap(),
            0
        );
    }
    assert!(out.is_empty());
}

fn random_frames(w: u32, h: u32, n: usize) -> Vec<Vec<f32>> {
    // Deterministic smooth-ish moving pattern.
    (0..n)
        .map(|k| {
            (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f32, (i / w) as f32);
                    0.5 + 0.45 * (0.3 * x + 0.2 * y - 0.7 * k as f32).sin()
                })
                .collect()
        })
        .collect()
}

fn run(cfg: &SimConfig, seed: u64, frames: &[Vec<f32>], w: u32, h: u32) -> EventStream {
    let mut sim = Simulator::new(w, h, cfg, seed);
    let mut out = EventStream::new(w, h);
    for (k, f) in frames.iter().enumerate() {
        sim.push_frame(k as f64 * 0.002, f, &mut out).unwrap();
    }
    out
}

#[test]
fn deterministic_by_seed_and_sorted() {
    let (w, h) = (24, 17);
    let frames = random_frames(w, h, 12);
    let cfg = SimConfig {
        threshold_sigma: 0.03,
        shot_noise_hz: 50.0,
        hot_pixel_fraction: 0.05,
        hot_pixel_hz: 500.0,
        refractory_s: 1e-4,
        ..SimConfig::default()
    };
    let a = run(&cfg, 42, &frames, w, h);
    let b = run(&cfg, 42, &frames, w, h);
    let c = run(&cfg, 43, &frames, w, h);
    assert!(a.len() > 100);
    assert_eq!(a, b);
    assert_ne!(a, c);
    a.validate().unwrap();
    // Same result on a single thread (row parallelism does not change the output).
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let d = pool.install(|| run(&cfg, 42, &frames, w, h));
    assert_eq!(a, d);
}

#[test]
fn refractory_period_drops_close_crossings() {
    // One interval of 10 ms, ΔL = 0.55, C = 0.1: crossings at k·(10 ms/5.5), k = 1…5.
    let cfg = SimConfig {
        refractory_s: 0.005,
        ..clean(0.1)
    };
    let base = 0.4f64.ln();
    let mut sim = Simulator::new(1, 1, &cfg, 0);
    let mut out = EventStream::new(1, 1);
    sim.push_frame(0.0, &[lum_of_log(base)], &mut out).unwrap();
    sim.push_frame(0.01, &[lum_of_log(base + 0.55)], &mut out)
        .unwrap();
    let step = 0.01 / 5.5;
    // Kept: k = 1 (1.82 ms) and k = 4 (7.27 ms, first ≥ 1.82 + 5 ms); k = 5 is 1.8 ms later.
    assert_eq!(out.len(), 2, "{:?}", out.t);
    assert!((out.t[0] - step).abs() < 1e-7);
    assert!((out.t[1] - 4.0 * step).abs() < 1e-7);

    // On a busy random scene every pixel's events are at least the period apart.
    let (w, h) = (20, 12);
    let frames = random_frames(w, h, 30);
    let cfg = SimConfig {
        refractory_s: 0.003,
        ..clean(0.05)
    };
    let out = run(&cfg, 1, &frames, w, h);
    let mut last = vec![f64::NEG_INFINITY; (w * h) as usize];
    for i in 0..out.len() {
        let pix = out.y[i] as usize * w as usize + out.x[i] as usize;
        assert!(out.t[i] - last[pix] >= 0.003 - 1e-12);
        last[pix] = out.t[i];
    }
    assert!(out.len() > 50);
}

#[test]
fn shot_noise_rate_and_hot_pixels() {
    let (w, h) = (64, 64);
    let frame = vec![0.5f32; (w * h) as usize];
    let cfg = SimConfig {
        shot_noise_hz: 10.0,
        ..clean(0.1)
    };
    let mut sim = Simulator::new(w, h, &cfg, 9);
    let mut out = EventStream::new(w, h);
    let mut flags = Vec::new();
    for k in 0..=100 {
        sim.push_frame_flagged(k as f64 * 0.01, &frame, &mut out, Some(&mut flags))
            .unwrap();
    }
    // 4096 px × 10 Hz × 1 s = 40 960 expected; Poisson std ≈ 202.
    let n = out.len() as f64;
    assert!((n - 40960.0).abs() < 1000.0, "{n}");
    assert_eq!(flags.len(), out.len());
    assert!(flags.iter().all(|&f| f));
    let positive = out.p.iter().filter(|&&p| p == 1).count() as f64;
    assert!((positive / n - 0.5).abs() < 0.02);
    out.validate().unwrap();

    let cfg = SimConfig {
        hot_pixel_fraction: 0.01,
        hot_pixel_hz: 200.0,
        ..clean(0.1)
    };
    let mut sim = Simulator::new(w, h, &cfg, 9);
    let hot: Vec<u32> = sim.hot_pixels().to_vec();
    assert!(!hot.is_empty() && hot.len() < 100, "{}", hot.len());
    let mut out = EventStream::new(w, h);
    for k in 0..=10 {
        sim.push_frame(k as f64 * 0.01, &frame, &mut out).unwrap();
    }
    // 0.1 s × 200 Hz = 20 events per hot pixel on average, all positive, all hot.
    let per_pixel = out.len() as f64 / hot.len() as f64;
    assert!((per_pixel - 20.0).abs() < 5.0, "{per_pixel}");
    for i in 0..out.len() {
        let pix = out.y[i] as u32 * w + out.x[i] as u32;
        assert!(hot.contains(&pix));
        assert_eq!(out.p[i], 1);
    }
}

#[test]
fn threshold_mismatch_statistics_and_clamp() {
    let cfg = SimConfig {
        threshold_pos: 0.2,
        threshold_neg: 0.15,
        threshold_sigma: 0.03,
        ..SimConfig::default()
    };
    let sim = Simulator::new(100, 100, &cfg, 5);
    let stats = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        let s = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
        (m, s)
    };
    let (m, s) = stats(sim.thresholds_pos());
    assert!(
        (m - 0.2).abs() < 0.002 && (s - 0.03).abs() < 0.002,
        "{m} {s}"
    );
    let (m, _) = stats(sim.thresholds_neg());
    assert!((m - 0.15).abs() < 0.002);
    let wide = SimConfig {
        threshold_sigma: 0.2,
        ..cfg
    };
    let sim = Simulator::new(50, 50, &wide, 5);
    let min = sim
        .thresholds_pos()
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min);
    assert_eq!(min, 0.01);
}

#[test]
fn bad_frames_are_errors() {
    let mut sim = Simulator::new(2, 2, &SimConfig::default(), 0);
    let mut out = EventStream::new(2, 2);
    assert!(sim.push_frame(0.0, &[0.5; 3], &mut out).is_err());
    sim.push_frame(0.0, &[0.5; 4], &mut out).unwrap();
    let e = sim.push_frame(0.0, &[0.5; 4], &mut out).unwrap_err();
    assert!(e.to_string().contains("increase"), "{e}");
    assert!(
        sim.push_frame(1.0, &[0.5, f32::NAN, 0.5, 0.5], &mut out)
            .is_err()
    );
    assert!(
        sim.push_frame(1.0, &[0.5, -1.0, 0.5, 0.5], &mut out)
            .is_err()
    );
    assert!(sim.push_frame(f64::NAN, &[0.5; 4], &mut out).is_err());
    assert!(out.is_empty());
    let bad = SimConfig {
        threshold_pos: -0.1,
        ..SimConfig::default()
    };
    assert!(bad.validate().is_err());
}

#[test]
fn luminance_uses_rec709_weights() {
    let y = luminance(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]);
    assert_eq!(y[..3], [0.2126, 0.7152, 0.0722]);
    assert!((y[3] - 1.0).abs() < 1e-6);
}

fn write_frames(dir: &std::path::Path, frames: &[Vec<f32>], w: u32, h: u32) {
    for (k, f) in frames.iter().enumerate() {
        let rgb: Vec<f32> = f.iter().flat_map(|&v| [v, v, v]).collect();
        let img = scene::image_io::Image {
            width: w,
            height: h,
            channels: 3,
            data: rgb,
        };
        scene::image_io::write_png(dir.join(format!("frame_{k:04}.png")), &img).unwrap();
    }
}

#[test]
fn simulate_frames_matches_the_library_on_png_input() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (20, 10);
    let frames = random_frames(w, h, 6);
    write_frames(dir.path(), &frames, w, h);
    let times = "# t in seconds\n0.0\n0.01\n0.02\n\n0.03\n0.04\n0.05\n";
    std::fs::write(dir.path().join("timestamps.txt"), times).unwrap();
    let out_path = dir.path().join("out.evs");
    let cfg = clean(0.1);
    let summary = simulate_frames(dir.path(), &out_path, &cfg, 3, FrameEncoding::Linear).unwrap();
    let read = scene::formats::read_events(&out_path, &Default::default()).unwrap();
    assert_eq!(summary.frames, 6);
    assert_eq!(summary.events, read.len());
    assert!(read.len() > 20);
    // The same frames as read back from PNG, through the library directly.
    let mut sim = Simulator::new(w, h, &cfg, 3);
    let mut direct = EventStream::new(w, h);
    for k in 0..6 {
        let img =
            scene::image_io::read_image(dir.path().join(format!("frame_{k:04}.png"))).unwrap();
        sim.push_frame(k as f64 * 0.01, &luminance(&img.data), &mut direct)
            .unwrap();
    }
    assert_eq!(read, direct);
}

#[test]
fn simulate_frames_rejects_bad_directories() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.evs");
    let cfg = clean(0.1);
    // No timestamps file.
    let e = simulate_frames(dir.path(), &out, &cfg, 0, FrameEncoding::Linear).unwrap_err();
    assert!(e.to_string().contains("timestamps.txt"), "{e}");
    let frames = random_frames(4, 4, 3);
    write_frames(dir.path(), &frames, 4, 4);
    let ts = dir.path().join("timestamps.txt");
    std::fs::write(&ts, "0\n0.1\n").unwrap();
    let e = simulate_frames(dir.path(), &out, &cfg, 0, FrameEncoding::Linear).unwrap_err();
    assert!(e.to_string().contains("2 timestamps for 3 images"), "{e}");
    std::fs::write(&ts, "0\n0.1\nabc\n").unwrap();
    let e = simulate_frames(dir.path(), &out, &cfg, 0, FrameEncoding::Linear).unwrap_err();
    assert!(e.to_string().contains("line 3"), "{e}");
    std::fs::write(&ts, "0\n0.1\n0.1\n").unwrap();
    assert!(read_timestamps(&ts).is_err());
    std::fs::write(&ts, "0\n0.1\ninf\n").unwrap();
    assert!(read_timestamps(&ts).is_err());
    assert!(!out.exists(), "nothing half-written");
    // Frames of different sizes.
    write_frames(dir.path(), &random_frames(5, 4, 1), 5, 4);
    std::fs::rename(
        dir.path().join("frame_0000.png"),
        dir.path().join("frame_0002.png"),
    )
    .unwrap();
    write_frames(dir.path(), &random_frames(4, 4, 2), 4, 4);
    std::fs::write(&ts, "0\n0.1\n0.2\n").unwrap();
    let e = simulate_frames(dir.path(), &out, &cfg, 0, FrameEncoding::Linear).unwrap_err();
    assert!(
        e.to_string().contains("frame_0002.png") && e.to_string().contains("5x4"),
        "{e}"
    );
    // A corrupt image names the file.
    std::fs::write(&ts, "0\n0.1\n0.2\n").unwrap();
    std::fs::write(dir.path().join("frame_0001.png"), b"not a png").unwrap();
    let e = simulate_frames(dir.path(), &out, &cfg, 0, FrameEncoding::Linear).unwrap_err();
    assert!(e.to_string().contains("frame_0001.png"), "{e}");
    assert!(!out.exists());
    // A directory without images.
    let empty = tempfile::tempdir().unwrap();
    std::fs::write(empty.path().join("timestamps.txt"), "").unwrap();
    let e = simulate_frames(empty.path(), &out, &cfg, 0, FrameEncoding::Linear).unwrap_err();
    assert!(e.to_string().contains("no .png"), "{e}");
    assert!(!out.exists());
}

#[test]
fn simulate_frames_decodes_srgb_codes_before_the_log() {
    // One pixel from code 128 to code 255. sRGB 128/255 is linear 0.2158605 (IEC
    // 61966-2-1 table value), so log(ε + Y) rises by ln(1.001 / 0.2168605) = 1.5295:
    // 15 events at C = 0.1. Read as linear codes it would rise by ln(1.001 / 0.50296)
    // = 0.6879: 6 events.
    let dir = tempfile::tempdir().unwrap();
    for (k, v) in [128.0f32 / 255.0, 1.0].into_iter().enumerate() {
        let img = scene::image_io::Image {
            width: 1,
            height: 1,
            channels: 3,
            data: vec![v; 3],
        };
        scene::image_io::write_png(dir.path().join(format!("f_{k}.png")), &img).unwrap();
    }
    std::fs::write(dir.path().join("timestamps.txt"), "0.0\n0.01\n").unwrap();
    let out = dir.path().join("out.evs");
    for (encoding, want) in [(FrameEncoding::Srgb, 15), (FrameEncoding::Linear, 6)] {
        simulate_frames(dir.path(), &out, &clean(0.1), 0, encoding).unwrap();
        let ev = scene::formats::read_events(&out, &Default::default()).unwrap();
        assert_eq!(ev.len(), want, "{encoding:?}");
        assert!(ev.p.iter().all(|&p| p > 0), "{encoding:?}: all positive");
    }
}

#[test]
fn a_pixel_that_returns_to_its_value_gives_as_many_off_as_on_events() {
    // log L: l0 → l0 + 1.1 → l0 at C = 0.2: five ON events up, and on the way back the
    // reference falls by five thresholds to exactly l0, so the fifth OFF crossing is an
    // exact tie that must fire (v2e does; a reference accumulated in floating point
    // would miss it for most l0).
    let mut lost = Vec::new();
    for k in 0..40 {
        let l0 = -4.0 + 0.1 * k as f64;
        let mut sim = Simulator::new(1, 1, &clean(0.2), 0);
        let mut out = EventStream::new(1, 1);
        for (t, l) in [(0.0, l0), (0.01, l0 + 1.1), (0.02, l0)] {
            sim.push_frame(t, &[lum_of_log(l)], &mut out).unwrap();
        }
        let on = out.p.iter().filter(|&&p| p > 0).count();
        let off = out.p.iter().filter(|&&p| p < 0).count();
        assert_eq!(on, 5, "l0 = {l0}");
        if off != on {
            lost.push(l0);
        }
    }
    assert!(lost.is_empty(), "OFF events lost at l0 = {lost:?}");
}
