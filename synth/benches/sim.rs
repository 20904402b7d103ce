//! Throughput of the synthetic renderer and the event simulator at 128² and 256².
//! Prints a table and writes `target/bench-results/sim.json`.
//! `SIM_BENCH_FRAMES` sets the number of internal frames simulated (default 200).

use scene::EventStream;
use std::time::Instant;
use synth::scene_dir::write_synthetic_scene;
use synth::sim::{SimConfig, Simulator, luminance};
use synth::{SynthConfig, SynthWorld};

#[derive(serde::Serialize)]
struct Row {
    size: u32,
    preset: String,
    supersample: u32,
    render_ms_per_frame: f64,
    render_frames_per_s: f64,
    sim_frames: usize,
    sim_events: usize,
    sim_ms_per_frame: f64,
    sim_frames_per_s: f64,
    sim_mevents_per_s: f64,
    scene_duration_s: f64,
    scene_total_s: f64,
}

fn main() {
    let frames: usize = std::env::var("SIM_BENCH_FRAMES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(200);
    let mut rows = Vec::new();
    for size in [128u32, 256] {
        for (preset, ss) in [("rigid", 1u32), ("fast", 2)] {
            let cfg = SynthConfig {
                width: size,
                height: size,
                supersample: ss,
                ..SynthConfig::preset(preset).unwrap()
            };
            let world = SynthWorld::new(&cfg).unwrap();
            let rate = cfg.render_rate_hz;

            // Render: all frames, kept for the simulator.
            let start = Instant::now();
            let lums: Vec<Vec<f32>> = (0..frames)
                .map(|k| luminance(&world.render(k as f64 / rate).rgb))
                .collect();
            let render_s = start.elapsed().as_secs_f64();

            // Simulate (no noise, threshold mismatch as the default config).
            let sim_cfg = SimConfig {
                threshold_pos: cfg.events.threshold_pos,
                threshold_neg: cfg.events.threshold_neg,
                ..SimConfig::default()
            };
            let mut sim = Simulator::new(size, size, &sim_cfg, 1);
            let mut out = EventStream::new(size, size);
            let start = Instant::now();
            for (k, l) in lums.iter().enumerate() {
                sim.push_frame(k as f64 / rate, l, &mut out).unwrap();
            }
            let sim_s = start.elapsed().as_secs_f64();

            // A whole scene directory (0.25 s of recording).
            let tmp = tempfile::tempdir().unwrap();
            let scene_cfg = SynthConfig {
                duration: 0.25,
                ..cfg.clone()
            };
            let summary = write_synthetic_scene(&scene_cfg, &tmp.path().join("s")).unwrap();

            rows.push(Row {
                size,
                preset: preset.into(),
                supersample: ss,
                render_ms_per_frame: 1e3 * render_s / frames as f64,
                render_frames_per_s: frames as f64 / render_s,
                sim_frames: frames,
                sim_events: out.len(),
                sim_ms_per_frame: 1e3 * sim_s / frames as f64,
                sim_frames_per_s: frames as f64 / sim_s,
                sim_mevents_per_s: out.len() as f64 / sim_s / 1e6,
                scene_duration_s: 0.25,
                scene_total_s: summary.total_s,
            });
        }
    }
    println!(
        "| size | preset | ss | render ms/frame | render frames/s | events ({frames} frames) | sim ms/frame | sim frames/s | sim M events/s | 0.25 s scene dir, s |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in &rows {
        println!(
            "| {}² | {} | {} | {:.2} | {:.0} | {} | {:.2} | {:.0} | {:.1} | {:.2} |",
            r.size,
            r.preset,
            r.supersample,
            r.render_ms_per_frame,
            r.render_frames_per_s,
            r.sim_events,
            r.sim_ms_per_frame,
            r.sim_frames_per_s,
            r.sim_mevents_per_s,
            r.scene_total_s
        );
    }
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/bench-results");
    std::fs::create_dir_all(&dir).expect("bench-results dir");
    let path = dir.join("sim.json");
    scene::atomic::write_json_atomic(&path, &rows).expect("write sim.json");
    eprintln!("wrote {}", path.display());
}
