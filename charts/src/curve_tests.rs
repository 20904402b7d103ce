use super::curve::{Curve, is_curve_file, parse_steps, read_curve, to_csv};
use super::curve_draw::stop_label;
use super::curve_draw::write_curve_charts;
use super::draw;
use serde_json::Value;
use std::path::Path;

/// Three steps, the rule stopping at step 2 (as `locm_budget` writes them).
const REAL: &str = r#"{"step":0,"locm_s":0.0,"loss":null,"epe_px":3.7000,"zero_px":12.5000,"ratio":0.2960,"stopped":false}
{"step":1,"locm_s":0.812,"loss":0.190000,"epe_px":3.0000,"zero_px":12.5000,"ratio":0.2400,"stopped":false}
{"step":2,"locm_s":1.630,"loss":0.180000,"epe_px":2.6500,"zero_px":12.5000,"ratio":0.2120,"stopped":true,"stop_reason":"converged"}
"#;

/// A second curve near the zero-flow level, stopping at `max_steps`.
const SYNTHETIC: &str = r#"{"step":0,"locm_s":0.0,"loss":null,"epe_px":1.5130,"zero_px":1.7590,"ratio":0.8602,"stopped":false}
{"step":1,"locm_s":0.900,"loss":1.013000,"epe_px":1.4830,"zero_px":1.7590,"ratio":0.8431,"stopped":false}
{"step":2,"locm_s":1.790,"loss":0.990000,"epe_px":1.4690,"zero_px":1.7590,"ratio":0.8351,"stopped":false}
{"step":3,"locm_s":2.700,"loss":0.935000,"epe_px":1.4860,"zero_px":1.7590,"ratio":0.8448,"stopped":true,"stop_reason":"max_steps"}
"#;

fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn err_of(dir: &Path, text: &[u8]) -> String {
    let p = dir.join("bad.jsonl");
    std::fs::write(&p, text).unwrap();
    let e = format!("{:#}", read_curve(&p).unwrap_err());
    assert!(e.contains(&p.display().to_string()), "{e}");
    e
}

#[test]
fn curve_files_read_with_their_stop() {
    let d = tempfile::tempdir().unwrap();
    let c = read_curve(&write(d.path(), "ecd_shapes_rotation.jsonl", REAL)).unwrap();
    assert_eq!(c.name, "ecd_shapes_rotation");
    assert_eq!(c.steps.len(), 3);
    assert_eq!(c.steps[0].loss, None);
    assert_eq!(c.steps[1].loss, Some(0.19));
    assert_eq!((c.steps[2].locm_s, c.steps[2].ratio), (1.63, 0.212));
    let stop = c.stop().unwrap();
    assert_eq!(
        (stop.step, stop.stop_reason.as_deref()),
        (2, Some("converged"))
    );
    assert_eq!(
        stop_label(&c).unwrap(),
        "step 2 (converged): 0.212 at 1.6 s"
    );
    // a file from before `stopped` existed: read, no stop marked
    let old: String = REAL
        .lines()
        .take(2)
        .map(|l| l.replace(",\"stopped\":false", "") + "\n")
        .collect();
    let steps = parse_steps(&old).unwrap();
    assert_eq!(steps.len(), 2);
    assert!(steps.iter().all(|s| !s.stopped));
    // steps after the stop (the example trains on to max_steps) are part of the curve
    let on = format!(
        "{REAL}{}\n",
        SYNTHETIC
            .lines()
            .nth(1)
            .unwrap()
            .replace("\"step\":1", "\"step\":3")
            .replace("\"locm_s\":0.900", "\"locm_s\":2.5")
    );
    let c = read_curve(&write(d.path(), "on.jsonl", &on)).unwrap();
    assert_eq!(c.steps.len(), 4);
    assert_eq!((c.stop().unwrap().step, c.steps[3].ratio), (2, 0.8431));
    assert!(is_curve_file("runs/a/ecd.jsonl") && is_curve_file("X.JSONL"));
    assert!(!is_curve_file("sweep_a") && !is_curve_file("runs/x/run.json"));
}

#[test]
fn damaged_curve_files_name_the_file_and_line() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    // cut inside the last line (no newline at the end)
    let cut = &REAL[..REAL.len() - 30];
    let e = err_of(dir, cut.as_bytes());
    assert!(e.contains("line 3: cut short"), "{e}");
    // a corrupt line in the middle
    let bad = REAL.replacen("\"epe_px\":3.0000", "\"epe_px\":3.0@00", 1);
    assert!(err_of(dir, bad.as_bytes()).contains("line 2: not a LoCM curve step"));
    // NaN (as Rust prints it) is not JSON
    let nan = REAL.replacen("\"epe_px\":3.0000", "\"epe_px\":NaN", 1);
    assert!(err_of(dir, nan.as_bytes()).contains("line 2:"));
    for (text, want) in [
        (
            REAL.replacen("\"ratio\":0.2400", "\"ratio\":0.4400", 1),
            "line 2: ratio 0.44 is not epe_px ÷ zero_px = 0.2400",
        ),
        (
            REAL.replacen(
                "\"zero_px\":12.5000,\"ratio\":0.2400",
                "\"zero_px\":0,\"ratio\":0.2400",
                1,
            ),
            "line 2: zero_px = 0 is not a positive number",
        ),
        (
            REAL.replacen("\"locm_s\":0.812", "\"locm_s\":-0.812", 1),
            "line 2: locm_s = -0.812 is not a non-negative number",
        ),
        (
            REAL.replacen("\"step\":2", "\"step\":1", 1),
            "line 3: step 1 after step 1",
        ),
        (
            REAL.replacen("\"locm_s\":1.630", "\"locm_s\":0.5", 1),
            "line 3: LoCM time 0.5 s is less than the previous step's 0.812 s",
        ),
        (
            format!(
                "{REAL}{}",
                SYNTHETIC
                    .lines()
                    .nth(3)
                    .unwrap()
                    .replace("\"step\":3", "\"step\":9")
            ),
            "line 4: a second stop (step 9); the rule stopped at step 2",
        ),
        (
            REAL.replacen(
                "\"stopped\":false}",
                "\"stopped\":false,\"stop_reason\":\"converged\"}",
                1,
            ),
            "line 1: stop_reason on a step where the rule did not stop",
        ),
        ("\n\n".to_string(), "no steps"),
        (
            "{\"step\":0}\n".to_string(),
            "line 1: not a LoCM curve step: missing field",
        ),
    ] {
        let e = err_of(dir, text.as_bytes());
        assert!(e.contains(want), "{e}\nwanted: {want}");
    }
    assert!(err_of(dir, b"\xff\xfe{}").contains("not UTF-8"));
    let missing = dir.join("missing.jsonl");
    let e = format!("{:#}", read_curve(&missing).unwrap_err());
    assert!(e.contains("missing.jsonl: cannot read"), "{e}");
}

#[test]
fn the_curve_chart_draws_every_curve_and_its_stop() {
    let d = tempfile::tempdir().unwrap();
    let paths = [
        write(d.path(), "real.jsonl", REAL),
        write(d.path(), "rigid64.jsonl", SYNTHETIC),
    ];
    let out = d.path().join("charts");
    let files = write_curve_charts(&paths, &out).unwrap();
    let names: Vec<String> = files
        .iter()
        .map(|f| f.file_name().unwrap().to_string_lossy().to_string())
        .collect();
    assert_eq!(
        names,
        [
            "locm-curves.png",
            "locm-curves.svg",
            "locm-curves.json",
            "locm-curves.csv"
        ]
    );
    let img = scene::image_io::read_image(out.join("locm-curves.png")).unwrap();
    assert_eq!((img.width, img.height, img.channels), draw::SIZE_RGB);
    let count = |rgb: [u8; 3]| {
        img.data
            .chunks(3)
            .filter(|p| {
                p.iter()
                    .zip(rgb)
                    .all(|(&v, c)| (v * 255.0).round() as u8 == c)
            })
            .count()
    };
    // each curve's colour (red, blue) and the grey zero-flow line are drawn
    assert!(count([214, 39, 40]) > 200, "{}", count([214, 39, 40]));
    assert!(count([31, 119, 180]) > 200, "{}", count([31, 119, 180]));
    assert!(count([120, 120, 120]) > 300, "{}", count([120, 120, 120]));
    let svg = std::fs::read_to_string(out.join("locm-curves.svg")).unwrap();
    for text in [
        "LoCM fine-tuning time, scoring not counted (s)",
        "mean flow EPE ÷ zero-flow EPE",
        "zero flow (ratio 1: predicting no motion)",
        "real: 2 steps, zero-flow EPE 12.50 px",
        "rigid64: 3 steps, zero-flow EPE 1.76 px",
        "step 2 (converged): 0.212 at 1.6 s",
        "step 3 (max_steps): 0.845 at 2.7 s",
        "where the stopping rule stopped",
    ] {
        assert!(svg.contains(text), "{text}");
    }
    let json: Value =
        serde_json::from_slice(&std::fs::read(out.join("locm-curves.json")).unwrap()).unwrap();
    assert_eq!(json[1]["steps"][3]["ratio"], 0.8448);
    assert_eq!(json[0]["steps"][2]["stop_reason"], "converged");
    let csv = std::fs::read_to_string(out.join("locm-curves.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 3 + 4);
    assert_eq!(
        csv.lines().nth(3).unwrap(),
        "real,2,1.63,0.18,2.65,12.5,0.212,true,converged"
    );
    // a damaged curve file stops the chart with its name, and writes nothing
    let bad = write(d.path(), "bad.jsonl", &REAL[..40]);
    let out2 = d.path().join("charts2");
    let e = format!("{:#}", write_curve_charts(&[bad], &out2).unwrap_err());
    assert!(e.contains("bad.jsonl: line 1: cut short"), "{e}");
    assert!(!out2.exists());
}

#[test]
fn curves_of_one_name_are_told_apart_by_path() {
    let d = tempfile::tempdir().unwrap();
    for sub in ["a", "b"] {
        std::fs::create_dir_all(d.path().join(sub)).unwrap();
    }
    let paths = [
        write(&d.path().join("a"), "c.jsonl", REAL),
        write(&d.path().join("b"), "c.jsonl", SYNTHETIC),
    ];
    let out = d.path().join("charts");
    write_curve_charts(&paths, &out).unwrap();
    let json: Vec<Value> =
        serde_json::from_slice(&std::fs::read(out.join("locm-curves.json")).unwrap()).unwrap();
    let names: Vec<&str> = json.iter().map(|c| c["name"].as_str().unwrap()).collect();
    assert!(names[0].ends_with("a/c.jsonl") && names[1].ends_with("b/c.jsonl"));
    let c: Vec<Curve> = vec![];
    assert_eq!(to_csv(&c).lines().count(), 1);
}
