//! A Python interpreter with `plyfile`, the independent PLY reader of the tests.

use std::path::Path;

/// A Python that can import plyfile: `$DEGS_PYTHON`, else `python3` if it has plyfile,
/// else a virtual environment this test makes once under the target directory
/// (`python3 -m venv` + `pip install plyfile` from PyPI). `Err` says what failed.
pub fn python_with_plyfile() -> Result<String, String> {
    let has_plyfile = |py: &str| {
        std::process::Command::new(py)
            .args(["-c", "import plyfile"])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if let Ok(py) = std::env::var("DEGS_PYTHON") {
        return if has_plyfile(&py) {
            Ok(py)
        } else {
            Err(format!("DEGS_PYTHON={py} cannot import plyfile"))
        };
    }
    if has_plyfile("python3") {
        return Ok("python3".into());
    }
    let venv = Path::new(env!("CARGO_TARGET_TMPDIR")).join("plyfile-venv");
    let py = venv.join("bin/python").display().to_string();
    if !has_plyfile(&py) {
        let run = |cmd: &str, args: &[&str]| {
            std::process::Command::new(cmd)
                .args(args)
                .output()
                .map_err(|e| format!("{cmd}: {e}"))
                .and_then(|o| {
                    o.status.success().then_some(()).ok_or_else(|| {
                        format!(
                            "{cmd} {}: {}",
                            args.join(" "),
                            String::from_utf8_lossy(&o.stderr)
                        )
                    })
                })
        };
        let venv_s = venv.display().to_string();
        run("python3", &["-m", "venv", &venv_s])?;
        run(&py, &["-m", "pip", "install", "-q", "plyfile"])?;
    }
    Ok(py)
}
