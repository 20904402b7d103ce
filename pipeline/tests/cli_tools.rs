//! `degs events convert` and `degs synth`, driven through the binary.

use scene::events::EventStream;
use scene::formats::{ReadOptions, read_events, write_events, write_npz};
use scene::manifest::Scene;
use std::fs;
use std::path::Path;
use std::process::{Command, Output};

fn degs(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_degs"))
        .args(args)
        .output()
        .unwrap()
}

fn text(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

/// A small stream with awkward timestamps (not whole microseconds for `.txt`/`.evs`).
fn stream(micro: bool) -> EventStream {
    let mut ev = EventStream::new(40, 30);
    for i in 0..500u32 {
        let t = if micro {
            (1_000 + 37 * i as i64) as f64 / 1e6
        } else {
            0.001 + i as f64 * 3.7e-5 + 1e-13 * (i % 7) as f64
        };
        ev.t.push(t);
        ev.x.push((i * 7 % 40) as u16);
        ev.y.push((i * 11 % 30) as u16);
        ev.p.push(if i % 3 == 0 { -1 } else { 1 });
    }
    ev
}

fn same(a: &EventStream, b: &EventStream) {
    assert_eq!((a.width, a.height), (b.width, b.height));
    assert_eq!(a.x, b.x);
    assert_eq!(a.y, b.y);
    assert_eq!(a.p, b.p);
    let bits = |v: &[f64]| v.iter().map(|t| t.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&a.t), bits(&b.t));
}

#[test]
fn convert_round_trips_between_formats_bit_exactly() {
    let d = tempfile::tempdir().unwrap();
    let p = |n: &str| d.path().join(n).display().to_string();
    let ev = stream(false);
    write_events(p("a.txt"), &ev).unwrap();
    let o = degs(&["events", "convert", &p("a.txt"), &p("b.evs")]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("500 events"), "{}", text(&o));
    let o = degs(&["events", "convert", &p("b.evs"), &p("c.txt")]);
    assert!(o.status.success(), "{}", text(&o));
    let none = ReadOptions::default();
    same(&ev, &read_events(p("b.evs"), &none).unwrap());
    same(&ev, &read_events(p("c.txt"), &none).unwrap());

    // .npz holds whole microseconds and no sensor size
    let ev = stream(true);
    write_events(p("m.evs"), &ev).unwrap();
    let o = degs(&["events", "convert", &p("m.evs"), &p("m.npz")]);
    assert!(o.status.success(), "{}", text(&o));
    let o = degs(&[
        "events",
        "convert",
        &p("m.npz"),
        &p("n.evs"),
        "--sensor",
        "40x30",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    same(&ev, &read_events(p("n.evs"), &none).unwrap());
}

#[test]
fn hsergb_coordinates_are_divided_by_32() {
    let d = tempfile::tempdir().unwrap();
    let p = |n: &str| d.path().join(n).display().to_string();
    let ev = stream(true);
    // HS-ERGB layout: x, y stored ×32 (a sensor 32× larger holds them)
    let mut scaled = ev.clone();
    scaled.width *= 32;
    scaled.height *= 32;
    scaled.x.iter_mut().for_each(|x| *x *= 32);
    scaled.y.iter_mut().for_each(|y| *y *= 32);
    write_npz(p("hs.npz"), &scaled).unwrap();
    let o = degs(&[
        "events",
        "convert",
        &p("hs.npz"),
        &p("hs.evs"),
        "--sensor",
        "40x30",
        "--hsergb",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    same(
        &ev,
        &read_events(p("hs.evs"), &ReadOptions::default()).unwrap(),
    );
    // the explicit factor does the same
    let o = degs(&[
        "events",
        "convert",
        &p("hs.npz"),
        &p("hs2.evs"),
        "--sensor",
        "40x30",
        "--coord-scale",
        "32",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(
        fs::read(p("hs.evs")).unwrap(),
        fs::read(p("hs2.evs")).unwrap()
    );
    // without the option the coordinates fall outside the sensor: an error, no output
    let o = degs(&[
        "events",
        "convert",
        &p("hs.npz"),
        &p("bad.evs"),
        "--sensor",
        "40x30",
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("hs.npz"), "{}", text(&o));
    assert!(!Path::new(&p("bad.evs")).exists());
}

#[test]
fn convert_errors_name_the_file_and_write_nothing() {
    let d = tempfile::tempdir().unwrap();
    let p = |n: &str| d.path().join(n).display().to_string();
    write_events(p("ok.evs"), &stream(false)).unwrap();
    let mut bytes = fs::read(p("ok.evs")).unwrap();
    bytes.truncate(bytes.len() / 2);
    fs::write(p("cut.evs"), &bytes).unwrap();
    fs::write(p("junk.txt"), "0.1 1 2 1\nnot an event\n").unwrap();
    fs::write(p("empty.npz"), b"").unwrap();
    for (input, out) in [
        ("cut.evs", "o1.txt"),
        ("junk.txt", "o2.evs"),
        ("empty.npz", "o3.evs"),
        ("missing.evs", "o4.txt"),
        ("ok.evs", "o5.xyz"),
    ] {
        let o = degs(&["events", "convert", &p(input), &p(out), "--sensor", "40x30"]);
        assert!(!o.status.success(), "{input}");
        let err = text(&o);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains(input) || err.contains(out), "{err}");
        assert!(!Path::new(&p(out)).exists(), "{out} written");
    }
    let leftovers: Vec<_> = fs::read_dir(d.path())
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp"))
        .collect();
    assert!(leftovers.is_empty());
}

/// Tiny settings so every preset writes in well under a second.
const TINY: [&str; 12] = [
    "--set",
    "width=24",
    "--set",
    "height=16",
    "--set",
    "duration=0.25",
    "--set",
    "render_rate_hz=200",
    "--set",
    "test_frames=2",
    "--set",
    "supersample=1",
];

#[test]
fn synth_writes_every_preset_in_the_scene_layout() {
    let d = tempfile::tempdir().unwrap();
    for preset in synth::PRESETS {
        let out = d.path().join(preset);
        let mut args = vec!["synth", "--preset", preset, "--out", out.to_str().unwrap()];
        args.extend_from_slice(&TINY);
        let o = degs(&args);
        assert!(o.status.success(), "{preset}: {}", text(&o));
        let scene = Scene::open(&out).unwrap();
        // train frames at k / train_fps over 0.25 s: at 8 fps 0, 0.125, 0.25 (3); the
        // moderate preset's 20 fps gives 0, 0.05, …, 0.25 (6)
        let train = if *preset == "moderate" { 6 } else { 3 };
        assert_eq!(scene.train.frames.len(), train, "{preset}");
        assert_eq!(scene.test.frames.len(), 2, "{preset}");
        // the novel views: one per test time, 15° off the path
        assert_eq!(scene.novel.frames.len(), 2, "{preset}");
        assert!(
            text(&o).contains(&format!("{train} train + 2 test frames + 2 novel views")),
            "{preset}: {}",
            text(&o)
        );
        for (n, t) in scene.novel.frames.iter().zip(&scene.test.frames) {
            assert_eq!(n.timestamp, t.timestamp, "{preset}");
            let moved = (n.cam_to_world.translation - t.cam_to_world.translation).length();
            assert!(
                moved > 0.75,
                "{preset}: novel camera {moved} from the test one"
            );
        }
        let all = scene.train.frames.iter().chain(&scene.test.frames);
        for f in all.chain(&scene.novel.frames) {
            let img = scene::image_io::read_image(scene.image_path(f)).unwrap();
            assert_eq!((img.width, img.height), (24, 16), "{preset}");
        }
        let ev = scene.load_events().unwrap();
        assert_eq!((ev.width, ev.height), (24, 16));
        assert!(!ev.is_empty(), "{preset}: no events");
        assert!(out.join("events.evs").is_file());
        let gt = synth::gt::read_event_flow_gt(out.join("gt/event_flow.bin")).unwrap();
        assert_eq!(gt.len(), ev.len(), "{preset}: one gt flow per event");
        for split in ["train", "test", "novel"] {
            let n = if split == "train" { 3 } else { 2 };
            for i in 0..n {
                let depth = out.join(format!("gt/{split}/depth_{i:04}.exr"));
                let (w, h, z) = scene::image_io::read_exr_depth(&depth).unwrap();
                assert_eq!((w, h), (24, 16));
                assert!(z.iter().all(|z| z.is_finite() && *z >= 0.0));
                let flow = out.join(format!("gt/{split}/flow_{i:04}.exr"));
                assert!(flow.is_file(), "{}", flow.display());
            }
        }
        let settings: toml::Table =
            serde_json::from_slice::<serde_json::Value>(&fs::read(out.join("synth.json")).unwrap())
                .ok()
                .and_then(|v| toml::Value::try_from(v).ok())
                .and_then(|v| v.as_table().cloned())
                .unwrap();
        assert_eq!(settings["width"].as_integer(), Some(24), "{preset}");
    }
    // the novel-view angle is a setting (its default in --help); 0 writes no novel split
    let help = String::from_utf8_lossy(&degs(&["synth", "--help"]).stdout).to_string();
    assert!(
        help.contains("novel_angle_deg=0") && help.contains("[novel_angle_deg default: 15]"),
        "{help}"
    );
    let out = d.path().join("no-novel");
    let mut args = vec!["synth", "--out", out.to_str().unwrap()];
    args.extend_from_slice(&TINY);
    args.extend_from_slice(&["--set", "novel_angle_deg=0"]);
    let o = degs(&args);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("+ 0 novel views"), "{}", text(&o));
    assert!(Scene::open(&out).unwrap().novel.frames.is_empty());
    assert!(!out.join("transforms_novel.json").exists());
    // a typo in a setting names it; nothing is written
    let out = d.path().join("typo");
    let o = degs(&["synth", "--out", out.to_str().unwrap(), "--set", "widht=3"]);
    assert!(!o.status.success());
    assert!(text(&o).contains("widht"), "{}", text(&o));
    assert!(!out.exists());
    let o = degs(&["synth", "--preset", "nope", "--out", out.to_str().unwrap()]);
    assert!(text(&o).contains("nope") && text(&o).contains("rigid"));
}

#[test]
fn import_prints_what_it_found_and_refuses_an_aedat4_without_poses() {
    let dir = tempfile::tempdir().unwrap();
    let sample = testkit::testdata::shared_data("aedat4_sample/sample.aedat4");
    let sample = sample.to_str().unwrap();
    let out = dir.path().join("davis");
    let o = degs(&["import", "aedat4", sample, out.to_str().unwrap()]);
    assert!(!o.status.success());
    let e = text(&o);
    assert!(
        e.contains("sample.aedat4") && e.contains("--static-camera"),
        "{e}"
    );
    assert!(!out.exists());
    let o = degs(&[
        "import",
        "aedat4",
        sample,
        out.to_str().unwrap(),
        "--static-camera",
        "--test-every",
        "2",
        "--contrast-threshold",
        "0.2",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let printed = String::from_utf8_lossy(&o.stdout);
    for want in [
        "346x260",
        "4 over 0.120000 s",
        "2 train, 2 test",
        "6676",
        "Linear",
        "identity pose",
    ] {
        assert!(printed.contains(want), "{want:?} missing from:\n{printed}");
    }
    let s = Scene::open(&out).unwrap();
    assert_eq!((s.train.frames.len(), s.test.frames.len()), (2, 2));
    assert_eq!(s.contrast_threshold(), 0.2);
    let summary: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(out.join("import.json")).unwrap()).unwrap();
    assert_eq!(summary["events"], 6676);
    // A bad flag value is refused, naming the flag.
    let out2 = dir.path().join("davis2");
    let o = degs(&[
        "import",
        "aedat4",
        sample,
        out2.to_str().unwrap(),
        "--static-camera",
        "--test-every",
        "1",
    ]);
    assert!(
        !o.status.success() && text(&o).contains("--test-every 1"),
        "{}",
        text(&o)
    );
}

/// `degs … | head`: a closed stdout ends `degs` quietly (killed by SIGPIPE as any Unix
/// tool; no panic, nothing on stderr), not with exit 101. The pipe's read end is closed
/// before `degs` starts, so its first print meets a closed pipe.
#[test]
fn a_closed_stdout_ends_degs_quietly() {
    use std::os::unix::process::ExitStatusExt;
    let d = tempfile::tempdir().unwrap();
    let exp = d.path().join("e.toml");
    fs::write(&exp, "name = \"e\"\n[scene]\nsynth = \"rigid\"\n").unwrap();
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let o = Command::new(env!("CARGO_BIN_EXE_degs"))
        .args(["config", "show", exp.to_str().unwrap()])
        .stdout(writer)
        .output()
        .unwrap();
    let err = text(&o);
    assert!(err.is_empty(), "{err}");
    const SIGPIPE: i32 = 13; // Linux
    assert_eq!(o.status.signal(), Some(SIGPIPE), "{:?}", o.status);
}

/// Settings that cannot work are refused when the experiment is loaded (`degs plan`,
/// before any stage), by the stage's own validation, naming the file, table and key;
/// a wrong type names the key, a TOML syntax error the line.
#[test]
fn plan_refuses_settings_that_cannot_work() {
    let d = tempfile::tempdir().unwrap();
    let cases = [
        ("[assoc]\nk = 0\n", "[assoc]", "k = 0"),
        (
            "[gaussians]\nfeature_lr = -0.01\n",
            "[gaussians]",
            "feature_lr = -0.01",
        ),
        (
            "[gaussians.densify]\ninterval = 0\n",
            "[gaussians]",
            "densify.interval = 0",
        ),
        (
            "[gaussians]\nsh_degree = 7\n",
            "[gaussians]",
            "sh_degree = 7",
        ),
        (
            "[gaussians.densify]\ninterval = \"often\"\n",
            "[gaussians]",
            "key `densify.interval`",
        ),
        ("[deform]\nposenet_lr = -1.0\n", "[deform]", "posenet_lr"),
        ("[assoc]\nk = = 3\n", "line 6, column 5", ""),
    ];
    for (i, (table, place, key)) in cases.iter().enumerate() {
        let exp = d.path().join(format!("e{i}.toml"));
        fs::write(
            &exp,
            format!("name = \"e{i}\"\n\n[scene]\nsynth = \"rigid\"\n{table}"),
        )
        .unwrap();
        let cache = d.path().join("cache");
        let o = degs(&[
            "plan",
            exp.to_str().unwrap(),
            "--cache",
            cache.to_str().unwrap(),
        ]);
        let e = text(&o);
        assert!(!o.status.success(), "{table}: accepted");
        assert!(
            e.contains(exp.to_str().unwrap()) && e.contains(place) && e.contains(key),
            "{table}: {e}"
        );
        assert!(
            !cache.join("runs").exists(),
            "{table}: something was written"
        );
    }
}

/// A synthetic scene whose test times fall on its train times is refused at `degs synth`
/// (and so at `plan`), with a `test_frames` that avoids it.
#[test]
fn synth_refuses_test_frames_on_train_frames() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("s");
    let o = degs(&[
        "synth",
        "--preset",
        "static",
        "--set",
        "width=16",
        "--set",
        "height=12",
        "--set",
        "duration=3",
        "--set",
        "train_fps=20",
        "--set",
        "test_frames=30",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = text(&o);
    assert!(
        e.contains("test_frames = 30: 30 of the 30 test times") && e.contains("avoids it"),
        "{e}"
    );
    assert!(!out.exists());
}

/// `degs events convert A A` is refused and A is left as it was.
#[test]
fn convert_onto_its_input_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let a = d.path().join("a.txt");
    write_events(&a, &stream(true)).unwrap();
    let before = fs::read(&a).unwrap();
    let o = degs(&[
        "events",
        "convert",
        a.to_str().unwrap(),
        a.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("the output is the input"), "{}", text(&o));
    assert_eq!(fs::read(&a).unwrap(), before);
}
