//! What the diagnostics that read a model of a scene share (`SCENE MODEL_DIR ...`).
// Each example compiles this module on its own and uses a part of it.
#![allow(dead_code)]

use gaussians::model::Model;
use std::path::PathBuf;

/// Print `what` and exit with status 1.
pub fn fail(what: String) -> ! {
    eprintln!("{what}");
    std::process::exit(1)
}

/// The command line's arguments, the scene (first) and the model (second) opened; with
/// fewer than two arguments `usage` is printed and the process exits with status 2.
pub fn open(usage: &str) -> (Vec<String>, PathBuf, scene::Scene, Model) {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        eprintln!("usage: {usage}");
        std::process::exit(2);
    }
    let root = PathBuf::from(&args[0]);
    let sc = scene::Scene::open(&root).unwrap_or_else(|e| fail(format!("{e}")));
    let model = Model::load(args[1].as_ref()).unwrap_or_else(|e| fail(format!("{}: {e}", args[1])));
    (args, root, sc, model)
}

/// The median (the upper one of an even count); NaN when `v` is empty.
pub fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let k = v.len() / 2;
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}

/// The quartiles (nearest rank below); NaN when `e` is empty.
pub fn quartiles(mut e: Vec<f64>) -> [f64; 3] {
    if e.is_empty() {
        return [f64::NAN; 3];
    }
    e.sort_by(f64::total_cmp);
    [0.25, 0.5, 0.75].map(|f| e[((e.len() - 1) as f64 * f) as usize])
}
