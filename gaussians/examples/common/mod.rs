//! What the diagnostics that read a model of a scene share (`SCENE MODEL_DIR ...`).

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
