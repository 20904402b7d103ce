//! The `evflow` binary: help text, exit codes, one-line errors naming the file, and the
//! bare-event-file source (calibration, window tiling).

use evflow::source::{Source, WindowSpec, parse_sensor, parse_window, read_calib};
use stagekit::help::flag_help;
use std::process::Command;

fn evflow() -> Command {
    Command::new(env!("CARGO_BIN_EXE_evflow"))
}

#[test]
fn help_and_errors() {
    let out = evflow().arg("--help").output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for cmd in ["simulate", "finetune", "predict", "eval", "pretrain"] {
        assert!(text.contains(cmd), "{cmd} missing from --help");
    }
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("no_scene_here");
    let out = evflow()
        .args(["finetune", "--scene"])
        .arg(&missing)
        .arg("--out")
        .arg(tmp.path().join("out"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.lines().last().unwrap();
    assert!(last.contains("no_scene_here"), "{err}");
    assert!(!tmp.path().join("out").exists());
    // A corrupt event file.
    let ev = tmp.path().join("bad.txt");
    std::fs::write(&ev, "0.1 3 4 1\nnot an event\n").unwrap();
    let out = evflow()
        .args(["predict", "--events"])
        .arg(&ev)
        .args(["--sensor", "32x32", "--out"])
        .arg(tmp.path().join("out"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("bad.txt"));
}

/// `finetune --help` and `pretrain --help` show the defaults of the settings their flags
/// override, from the settings types' `Default`.
#[test]
fn help_shows_the_settings_defaults() {
    let help = |cmd: &str| {
        let out = evflow().args([cmd, "--help"]).output().unwrap();
        assert!(out.status.success());
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let f = evflow::settings::FlowSettings::default();
    let finetune = help("finetune");
    for (flag, default) in [
        ("--min-steps", f.stop.min_steps.to_string()),
        ("--max-steps", f.stop.max_steps.to_string()),
        ("--lr-start", f.lr_start.to_string()),
        ("--lr-end", f.lr_end.to_string()),
        ("--rank", f.rank.to_string()),
        ("--max-flow", evflow::net::io::DEFAULT_MAX_FLOW.to_string()),
    ] {
        let line = flag_help(&finetune, flag);
        assert!(line.contains(&format!("[default: {default}]")), "{line}");
    }
    let p = evflow::pretrain::PretrainSettings::default();
    let pretrain = help("pretrain");
    for (flag, default) in [("--base", p.base), ("--iterations", p.iterations)] {
        let line = flag_help(&pretrain, flag);
        assert!(line.contains(&format!("[default: {default}]")), "{line}");
    }
}

#[test]
fn bare_event_file_windows_and_calibration() {
    assert_eq!(parse_sensor("240x180"), Ok((240, 180)));
    assert!(parse_sensor("240").is_err() && parse_sensor("0x5").is_err());
    assert_eq!(parse_window("1.5,2"), Ok((1.5, 2.0)));
    assert!(parse_window("2,1").is_err() && parse_window("nan,1").is_err());
    let tmp = tempfile::tempdir().unwrap();
    let ev = tmp.path().join("ev.txt");
    let lines: String = (0..100)
        .map(|i| format!("{} {} {} {}\n", i as f64 * 0.01, i % 30, i % 20, i % 2))
        .collect();
    std::fs::write(&ev, lines).unwrap();
    let spec = WindowSpec {
        windows: vec![],
        window_length: Some(0.25),
    };
    let s = Source::from_events(&ev, Some((32, 24)), None, &spec).unwrap();
    assert_eq!(s.windows.len(), 4);
    assert_eq!(s.window_events(), 100, "every event in exactly one window");
    // The CM loss of a huge window uses an even-stride subsample.
    let sub = s.cm_events(&s.windows[0], 7);
    assert!(sub.len() <= 7 && !sub.is_empty());
    assert!(sub.t.iter().all(|t| (0.0..=1.0).contains(t)));
    let whole = Source::from_events(&ev, Some((32, 24)), None, &WindowSpec::default()).unwrap();
    assert_eq!(whole.windows.len(), 1);
    assert_eq!(whole.windows[0].range, 0..100);
    // A file that stores its sensor size needs no --sensor; one that does not says so.
    let evs = tmp.path().join("ev.evs");
    scene::formats::write_events(&evs, &whole.events).unwrap();
    let stored = Source::from_events(&evs, None, None, &WindowSpec::default()).unwrap();
    assert_eq!((stored.events.width, stored.events.height), (32, 24));
    let e = Source::from_events(&ev, None, None, &WindowSpec::default())
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(e.contains("ev.txt") && e.contains("--sensor WxH"), "{e}");
    // Calibration: undistortion inverts the distortion model.
    let calib = tmp.path().join("calib.txt");
    std::fs::write(&calib, "30 30 15.5 11.5 -0.3 0.1 0.001 -0.002 0\n").unwrap();
    let k = read_calib(&calib, (32, 24)).unwrap();
    let s = Source::from_events(&ev, Some((32, 24)), Some(&calib), &WindowSpec::default()).unwrap();
    for i in [0, 17, 99] {
        let d = k.distort_pixel(glam::DVec2::new(s.xu[i] as f64, s.yu[i] as f64));
        assert!(
            (d.x - s.events.x[i] as f64).abs() < 1e-3,
            "event {i}: {d:?}"
        );
        assert!(
            (d.y - s.events.y[i] as f64).abs() < 1e-3,
            "event {i}: {d:?}"
        );
    }
    std::fs::write(&calib, "30 30 15.5\n").unwrap();
    let e = read_calib(&calib, (32, 24)).unwrap_err().to_string();
    assert!(e.contains("calib.txt"), "{e}");
}

#[test]
fn predict_takes_the_finetune_output_directory_as_adapter() {
    let tmp = tempfile::tempdir().unwrap();
    // A bar of events moving right over a 32x24 sensor for 0.5 s (one window).
    let ev = tmp.path().join("ev.txt");
    let lines: String = (0..3000)
        .map(|i| {
            let t = i as f64 / 6000.0;
            let x = 4 + (40.0 * t) as u32 + i % 3;
            format!("{t} {x} {} {}\n", 2 + (i * 7) % 20, i % 2)
        })
        .collect();
    std::fs::write(&ev, lines).unwrap();
    let run = |args: &[&str], out: &std::path::Path, adapter: Option<&std::path::Path>| {
        let mut c = evflow();
        c.args(args)
            .arg("--events")
            .arg(&ev)
            .args(["--sensor", "32x24", "--no-previews", "--out"])
            .arg(out);
        if let Some(a) = adapter {
            c.arg("--adapter").arg(a);
        }
        let run = c.output().unwrap();
        let err = String::from_utf8_lossy(&run.stderr).into_owned();
        (
            run.status.code(),
            err.lines().last().unwrap_or_default().to_string(),
        )
    };
    let ft = tmp.path().join("ft");
    let (code, last) = run(&["finetune", "--epochs", "1"], &ft, None);
    assert_eq!(code, Some(0), "{last}");
    let flow = |dir: &std::path::Path| evflow::flowfile::read_evflow(&dir.join("flow/0000.evflow"));
    let tuned = flow(&ft).unwrap();
    // The finetune output directory and the adapter file in it both give the fine-tuned
    // flow (which differs from the base network's).
    for (name, adapter) in [
        ("dir", ft.clone()),
        ("file", ft.join("adapter.safetensors")),
    ] {
        let out = tmp.path().join(name);
        let (code, last) = run(&["predict"], &out, Some(&adapter));
        assert_eq!(code, Some(0), "--adapter {name}: {last}");
        assert_eq!(flow(&out).unwrap(), tuned, "--adapter {name}");
    }
    let base = tmp.path().join("base");
    assert_eq!(run(&["predict"], &base, None).0, Some(0));
    assert_ne!(flow(&base).unwrap(), tuned, "the adapter changes the flow");
    // A directory without an adapter (the base prediction's): the error names it and
    // says what --adapter takes.
    let (code, last) = run(&["predict"], &tmp.path().join("x"), Some(&base));
    assert_eq!(code, Some(1));
    assert!(
        last.contains("base") && last.contains("adapter.safetensors") && last.contains("finetune"),
        "{last}"
    );
    assert!(!last.contains("base.json"), "{last}");
}

/// Grey PNG frames `frame_KKKK.png` (8-bit codes, row-major) and `timestamps.txt`: the
/// layout `evflow simulate --frames DIR` reads.
fn write_frame_dir(dir: &std::path::Path, w: u32, h: u32, codes: &[Vec<u8>], times: &[f64]) {
    std::fs::create_dir_all(dir).unwrap();
    for (k, c) in codes.iter().enumerate() {
        let img = scene::image_io::Image {
            width: w,
            height: h,
            channels: 1,
            data: c.iter().map(|&v| v as f32 / 255.0).collect(),
        };
        scene::image_io::write_png(dir.join(format!("frame_{k:04}.png")), &img).unwrap();
    }
    let ts: String = times.iter().map(|t| format!("{t}\n")).collect();
    std::fs::write(dir.join("timestamps.txt"), format!("# seconds\n{ts}")).unwrap();
}

#[test]
fn simulate_a_brightening_ramp_through_the_binary() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = tmp.path().join("frames");
    let (w, h) = (8u32, 4u32);
    let times = [0.0, 0.01, 0.02, 0.035, 0.05];
    // Pixel (x, y) brightens by a constant code step per frame (rows 0–2, steps 4..=42);
    // row 3 stays constant.
    let code = |x: u32, y: u32, k: usize| -> u8 {
        let step = if y == 3 { 0 } else { 4 + 5 * x + y };
        (20 + 7 * x + 3 * y + k as u32 * step) as u8
    };
    let codes: Vec<Vec<u8>> = (0..times.len())
        .map(|k| {
            (0..h)
                .flat_map(|y| (0..w).map(move |x| code(x, y, k)))
                .collect()
        })
        .collect();
    write_frame_dir(&frames, w, h, &codes, &times);
    let c = 0.1;
    let cfg = tmp.path().join("sim.toml");
    std::fs::write(
        &cfg,
        format!("threshold_pos = {c}\nthreshold_neg = {c}\nthreshold_sigma = 0.0\n"),
    )
    .unwrap();
    let out = tmp.path().join("ev.evs");
    let simulate = |encoding: Option<&str>| {
        let mut cmd = evflow();
        cmd.args(["simulate", "--frames"])
            .arg(&frames)
            .arg("--out")
            .arg(&out)
            .arg("--config")
            .arg(&cfg);
        if let Some(e) = encoding {
            cmd.args(["--frame-encoding", e]);
        }
        let run = cmd.output().unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr).to_string();
        assert!(run.status.success(), "{stderr}");
        assert!(stderr.contains("5 frames"), "{stderr}");
    };
    // By default the codes are sRGB: each pixel's count is floor(ΔL / C) with the
    // codes decoded by the IEC 61966-2-1 curve (written out here).
    simulate(None);
    let srgb = |v: u8| {
        let c = v as f64 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    let mut want = 0;
    for y in 0..h {
        for x in 0..w {
            let l = |k: usize| (1e-3 + srgb(code(x, y, k))).ln();
            want += ((l(4) - l(0)) / c).floor() as usize;
        }
    }
    let decoded = scene::formats::read_events(&out, &Default::default()).unwrap();
    assert_eq!(decoded.len(), want);
    // The rest of the test reads the codes as linear intensity.
    simulate(Some("linear"));

    // Read back with scene's reader (the sensor size comes from the .evs header).
    let ev = scene::formats::read_events(&out, &Default::default()).unwrap();
    assert_eq!((ev.width, ev.height), (w, h));
    assert!(
        ev.p.iter().all(|&p| p == 1),
        "a brightening ramp gives ON events only"
    );
    assert!(ev.t.windows(2).all(|p| p[0] <= p[1]));
    assert!(ev.t.iter().all(|&t| t > times[0] && t <= times[4]));

    // Per pixel: count = floor(ΔL / C) with L = log(1e-3 + Y), Y the luminance of the
    // grey value as read from the PNG; the k-th event at the time the (piecewise linear
    // in t) L crosses L₀ + k·C.
    let log_y = |v: u8| {
        let y = synth::sim::luminance(&[v as f32 / 255.0; 3])[0];
        (1e-3 + y as f64).ln()
    };
    let mut total = 0;
    for y in 0..h {
        for x in 0..w {
            let l: Vec<f64> = (0..times.len()).map(|k| log_y(code(x, y, k))).collect();
            let ratio = (l[4] - l[0]) / c;
            let frac = ratio - ratio.floor();
            assert!(y == 3 || (0.01..0.99).contains(&frac), "({x},{y}): {ratio}");
            let expected = ratio.floor() as usize;
            let mine: Vec<f64> = (0..ev.len())
                .filter(|&i| (ev.x[i] as u32, ev.y[i] as u32) == (x, y))
                .map(|i| ev.t[i])
                .collect();
            assert_eq!(mine.len(), expected, "pixel ({x},{y}): ΔL/C = {ratio}");
            for (k, &t) in mine.iter().enumerate() {
                let level = l[0] + (k + 1) as f64 * c;
                let i = (0..4).find(|&i| l[i] < level && level <= l[i + 1]).unwrap();
                let s = (level - l[i]) / (l[i + 1] - l[i]);
                let t_cross = times[i] + s * (times[i + 1] - times[i]);
                assert!(
                    (t - t_cross).abs() < 1e-9,
                    "({x},{y}) #{k}: {t} vs {t_cross}"
                );
            }
            total += expected;
        }
    }
    assert_eq!(ev.len(), total);
    // Rows 0–2 brighten by ΔL = 0.58 (pixel (0,0)) to 1.18 (pixel (7,0)): 5 to 11 events
    // per pixel (ΔL/C at least 0.067 away from an integer), 227 in all; the constant row
    // gives none.
    assert_eq!(total, 227);
    assert!(ev.y.iter().all(|&y| y != 3));
}

#[test]
fn simulate_names_a_missing_or_empty_frames_dir() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("ev.evs");
    let simulate = |frames: &std::path::Path| {
        let run = evflow()
            .args(["simulate", "--frames"])
            .arg(frames)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr).into_owned();
        assert_eq!(run.status.code(), Some(1), "{err}");
        err.lines().last().unwrap_or_default().to_string()
    };
    let last = simulate(&tmp.path().join("no_such_frames"));
    assert!(
        last.contains("error") && last.contains("no_such_frames"),
        "{last}"
    );
    // An empty directory: no timestamps.txt.
    let empty = tmp.path().join("empty_frames");
    std::fs::create_dir(&empty).unwrap();
    let last = simulate(&empty);
    assert!(
        last.contains("empty_frames") && last.contains("timestamps.txt"),
        "{last}"
    );
    // Timestamps but no images.
    std::fs::write(empty.join("timestamps.txt"), "0\n0.1\n").unwrap();
    let last = simulate(&empty);
    assert!(
        last.contains("empty_frames") && last.contains("no .png"),
        "{last}"
    );
    assert!(!out.exists(), "no event file on failure");
}
