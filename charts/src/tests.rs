use super::*;

#[test]
fn pareto_front_keeps_the_points_nothing_beats() {
    // (cost, value): higher value and lower cost are better
    let pts = [
        (10.0, 20.0),    // 0: cheapest
        (20.0, 19.0),    // 1: dominated by 0
        (30.0, 25.0),    // 2: front
        (30.0, 24.0),    // 3: same cost as 2, worse
        (40.0, 25.0),    // 4: as good as 2 but dearer
        (50.0, 27.5),    // 5: front
        (5.0, f64::NAN), // 6: not a number, never on it
    ];
    assert_eq!(pareto_front(&pts), [0, 2, 5]);
    assert!(pareto_front(&[]).is_empty());
    // minimising an error: negate it
    let epe = [(1.0, -3.0), (2.0, -1.5), (3.0, -2.0), (4.0, -0.5)];
    assert_eq!(pareto_front(&epe), [0, 1, 3]);
}

#[test]
fn every_stage_a_model_needs_is_counted() {
    let mut d = needed("deform");
    d.sort();
    assert_eq!(d, ["assoc", "deform", "evflow", "gaussians"]);
    assert_eq!(needed("gaussians"), ["gaussians"]);
}

#[test]
fn model_bytes_leave_out_renders_depth_and_reports() {
    let d = tempfile::tempdir().unwrap();
    let w = |p: &str, n: usize| {
        let p = d.path().join(p);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, vec![0u8; n]).unwrap();
    };
    w("point_cloud.ply", 1000);
    w("field/mlp.safetensors", 200);
    w("model.json", 30);
    w("renders/0000.png", 5000);
    w("depth/0000.exr", 7000);
    w("report.json", 400);
    w("settings.toml", 50);
    assert_eq!(model_bytes(d.path()), 1230);
}

#[test]
fn locm_time_is_the_finetune_phase() {
    let r: Value = serde_json::from_str(
        r#"{"phases": [["load", 0.5], ["finetune", 3.25], ["predict", 1.0]]}"#,
    )
    .unwrap();
    assert_eq!(locm_seconds(&r), Some(3.25));
    let none: Value = serde_json::from_str(r#"{"phases": [["load", 0.5]]}"#).unwrap();
    assert_eq!(locm_seconds(&none), Some(0.0));
    assert_eq!(locm_seconds(&serde_json::json!({})), None);
}

/// A run record over entries in `root` whose reports are given; `built` is each
/// stage's build time, `cached` whether this run found it cached.
fn record(root: &Path, name: &str, stages: &[(&str, &str, f64, &str)]) -> RunRecord {
    use runner::record::{Action, StageRecord};
    let mut recs = vec![StageRecord {
        stage: "synth".into(),
        action: Action::Cached,
        key: Some("scenekey01".into()),
        binary: None,
        binary_hash: None,
        settings: serde_json::json!({"preset": "rigid"}),
        inputs: Default::default(),
        entry: Some(root.join("synth")),
        wall_s: 0.0,
        built_wall_s: Some(100.0),
        peak_rss_kib: None,
        exit_status: None,
        error: None,
        log: None,
        progress: None,
        warnings: Vec::new(),
    }];
    for (stage, key, built, report) in stages {
        let entry = root.join(stage).join(key);
        std::fs::create_dir_all(entry.join("renders")).unwrap();
        std::fs::write(entry.join("report.json"), report).unwrap();
        std::fs::write(entry.join("renders/0000.png"), [0u8; 64]).unwrap();
        std::fs::write(entry.join("model.bin"), vec![0u8; 2048]).unwrap();
        let mut r = recs[0].clone();
        r.stage = stage.to_string();
        r.key = Some(key.to_string());
        r.entry = Some(entry);
        r.built_wall_s = Some(*built);
        r.settings = serde_json::json!({});
        recs.push(r);
    }
    RunRecord {
        experiment: name.into(),
        experiment_file: None,
        cache_root: root.into(),
        status: "ok".into(),
        started_unix: 0,
        wall_s: 0.0,
        jobs: 1,
        stages: recs,
    }
}

#[test]
fn points_come_from_the_reports_and_shared_entries_count_once() {
    let d = tempfile::tempdir().unwrap();
    let g = r#"{"test": {"psnr_mean": 25.0, "ssim_mean": 0.8}, "gaussians": 3000}"#;
    let e = r#"{"flow_epe_px_s": 12.5, "phases": [["load", 1.0], ["finetune", 4.0]],
                "finetune": {"mode": "lora"}}"#;
    let degs = r#"{"test": {"psnr_mean": 27.0, "lpips_mean": 0.125}, "gaussians": 3500,
        "settings": {"schedule": {"gamma1": 1.0, "gamma2_max": 1.0}},
        "baselines": {"nearest": {"psnr_mean": 20.0, "lpips_mean": 0.25},
                      "blend": {"psnr_mean": 22.5, "lpips_mean": 0.1875},
                      "events": null}}"#;
    // RGB-only: no event term, and the motion term off (by its weight or by `motion`)
    let rgb = r#"{"test": {"psnr_mean": 26.0}, "gaussians": 3400,
        "settings": {"schedule": {"gamma1": 0.0, "gamma2_max": 1.0, "motion": "off"}}}"#;
    let a = record(
        d.path(),
        "sw_a",
        &[
            ("evflow", "e1", 10.0, e),
            ("gaussians", "g1", 20.0, g),
            ("assoc", "a1", 1.0, "{}"),
            ("deform", "d1", 30.0, degs),
        ],
    );
    let b = record(
        d.path(),
        "sw_b",
        &[
            ("evflow", "e1", 10.0, e),
            ("gaussians", "g1", 20.0, g),
            ("assoc", "a1", 1.0, "{}"),
            ("deform", "d2", 50.0, rgb),
        ],
    );
    let runs = [a, b];
    let data = collect(&runs);
    assert_eq!(data.models.len(), 3, "the shared warm-up is one point");
    let warm = &data.models[0];
    assert_eq!(
        (warm.stage.as_str(), warm.method),
        ("gaussians", Method::RgbWarmup)
    );
    assert_eq!(warm.experiments, ["sw_a", "sw_b"]);
    assert_eq!(
        warm.total_s, 20.0,
        "only its own stage (the scene is not counted)"
    );
    assert_eq!(warm.gaussians, Some(3000));
    assert_eq!(warm.model_bytes, 2048);
    let d1 = &data.models[1];
    assert_eq!(d1.method, Method::Degs);
    assert_eq!(d1.total_s, 10.0 + 20.0 + 1.0 + 30.0);
    assert_eq!(d1.lpips, Some(0.125));
    assert_eq!(data.models[2].method, Method::RgbJoint);
    assert_eq!(data.models[2].total_s, 81.0);
    assert_eq!(data.models[2].lpips, None);
    assert_eq!(data.flows.len(), 1);
    assert_eq!(
        (
            data.flows[0].epe_px_s,
            data.flows[0].locm_s,
            data.flows[0].mode.as_deref()
        ),
        (12.5, 4.0, Some("lora"))
    );
    let lines: Vec<(&str, f64, Option<f64>)> = data
        .baselines
        .iter()
        .map(|b| (b.name.as_str(), b.psnr, b.lpips))
        .collect();
    assert_eq!(
        lines,
        [
            ("nearest frame", 20.0, Some(0.25)),
            ("linear blend", 22.5, Some(0.1875))
        ]
    );
    assert!(data.models.iter().all(|p| p.scene == "rigid"));
    let csv = to_csv(&data);
    assert_eq!(csv.lines().count(), 1 + 3 + 1 + 2);
    let row: Vec<&str> = csv.lines().nth(2).unwrap().split(',').collect();
    assert_eq!(row.len(), 15);
    assert_eq!(row[..4], ["model", "rigid", "deform", "d1"]);
    assert_eq!(row[6], "27");
    assert_eq!(row[8], "0.125");
    assert_eq!(row[10], "61");

    // the charts: one per question, PNG and SVG, and the numbers beside them
    let out = d.path().join("charts");
    let files = write_charts(&runs, &out).unwrap();
    let names: Vec<String> = files
        .iter()
        .map(|f| f.file_name().unwrap().to_string_lossy().to_string())
        .collect();
    assert_eq!(
        names,
        [
            "rigid-psnr-vs-time.png",
            "rigid-psnr-vs-time.svg",
            "rigid-psnr-vs-size.png",
            "rigid-psnr-vs-size.svg",
            "rigid-psnr-vs-gaussians.png",
            "rigid-psnr-vs-gaussians.svg",
            "rigid-lpips-vs-time.png",
            "rigid-lpips-vs-time.svg",
            "rigid-epe-vs-locm.png",
            "rigid-epe-vs-locm.svg",
            "chart.json",
            "chart.csv"
        ]
    );
    let img = scene::image_io::read_image(out.join("rigid-psnr-vs-time.png")).unwrap();
    assert_eq!((img.width, img.height, img.channels), draw::SIZE_RGB);
    let px = |x: usize, y: usize| -> [u8; 3] {
        let o = (y * img.width as usize + x) * 3;
        [0, 1, 2].map(|c| (img.data[o + c] * 255.0).round() as u8)
    };
    let count = |rows: std::ops::Range<usize>, f: &dyn Fn([u8; 3]) -> bool| {
        rows.flat_map(|y| (0..img.width as usize).map(move |x| (x, y)))
            .filter(|&(x, y)| f(px(x, y)))
            .count()
    };
    let all = 0..img.height as usize;
    // each method's marker colour is there (DEGS red, RGB warm-up blue, RGB joint orange)
    assert!(count(all.clone(), &|p| p == [214, 39, 40]) > 50);
    assert!(count(all.clone(), &|p| p == [31, 119, 180]) > 50);
    assert!(count(all.clone(), &|p| p == [255, 127, 14]) > 20);
    // the title's text is drawn: dark pixels in the top rows
    assert!(count(0..40, &|p| p.iter().all(|&c| c < 100)) > 100);
    let svg = std::fs::read_to_string(out.join("rigid-psnr-vs-time.svg")).unwrap();
    for text in [
        "test PSNR (dB)",
        "Pareto front",
        "linear blend (22.50 dB)",
        "DEGS",
    ] {
        assert!(svg.contains(text), "{text}");
    }
    // the LPIPS chart: only the point whose report has LPIPS, the lines at theirs
    let svg = std::fs::read_to_string(out.join("rigid-lpips-vs-time.svg")).unwrap();
    for text in [
        "test LPIPS (VGG; lower is better)",
        "linear blend (0.1875)",
        "nearest frame (0.2500)",
    ] {
        assert!(svg.contains(text), "{text}");
    }
    assert!(!svg.contains("dB"), "no PSNR on the LPIPS chart");
    let baseline_row = csv.lines().last().unwrap();
    assert_eq!(
        baseline_row,
        "baseline,rigid,,,linear blend,,22.5,,0.1875,,,,,,"
    );
    let json: Value =
        serde_json::from_slice(&std::fs::read(out.join("chart.json")).unwrap()).unwrap();
    assert_eq!(json["models"][1]["total_s"], 61.0);
    assert_eq!(json["flows"][0]["locm_s"], 4.0);
}

#[test]
fn the_legend_takes_the_emptiest_place() {
    use super::legend::{legend_place, legend_size, polyline_anchors};
    super::draw::register_font().unwrap();
    let area = (0, 0, 100, 90);
    let size = (40, 30);
    let place = |pts: &[(i32, i32)]| legend_place(pts, area, size).name;
    // No points: the preferred corner. The lower right box is x 55..95, y 55..85.
    assert_eq!(place(&[]), "lower right");
    // A point in the lower right box moves it up.
    assert_eq!(place(&[(90, 80)]), "upper right");
    // Points in both right boxes (the upper one is y 5..35): lower left.
    assert_eq!(place(&[(90, 80), (70, 10)]), "lower left");
    // Every corner taken: the upper middle (x 30..70, y 5..35) if it is free…
    let corners = [(90, 80), (80, 10), (10, 70), (20, 20)];
    assert_eq!(place(&corners), "upper middle");
    // …and the middle left (y 30..60) when every other middle holds a point too.
    let mut busy = corners.to_vec();
    busy.extend([(50, 20), (50, 70), (80, 45)]);
    assert_eq!(place(&busy), "middle left");
    // With every named place covered, a free box elsewhere: three lines across a wide
    // area leave a band between the lower two.
    let wide = (0, 0, 200, 100);
    let mut lines = polyline_anchors(&[(0, 20), (200, 20)]);
    lines.extend(polyline_anchors(&[(0, 45), (200, 45)]));
    lines.extend(polyline_anchors(&[(0, 95), (200, 95)]));
    let p = legend_place(&lines, wide, (40, 30));
    assert_eq!(p.name, "inside");
    assert!(p.origin.1 > 45 && p.origin.1 + 30 < 95, "{p:?}");
    // A line crossing the lower right box without a vertex inside still moves the legend.
    let line = polyline_anchors(&[(50, 90), (100, 60)]);
    assert!(line.len() >= 14, "{}", line.len());
    assert_eq!(place(&line), "upper right");
    // Consecutive anchors lie about 4 pixels apart (5 with rounding), both ends kept.
    assert!(line.windows(2).all(|w| {
        let (dx, dy) = (w[1].0 - w[0].0, w[1].1 - w[0].1);
        dx * dx + dy * dy <= 5 * 5
    }));
    assert_eq!((line[0], *line.last().unwrap()), ((50, 90), (100, 60)));
    // The box grows with the labels: a longer label makes a wider box.
    let short = legend_size(&["a".to_string()]);
    let long = legend_size(&["a much longer label".to_string()]);
    assert!(
        long.0 > short.0 + 50 && long.1 == short.1,
        "{short:?} {long:?}"
    );
    let two = legend_size(&["a".to_string(), "b".to_string()]);
    assert!(two.1 > short.1 + 10, "{short:?} {two:?}");
}
