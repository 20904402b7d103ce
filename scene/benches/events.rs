//! Event file throughput: `.evs` vs text (and `.npz`) for 10 M events.
//! `cargo bench -p scene --bench events` — prints a table and writes
//! `target/bench-results/events.json`. Set `DEGS_BENCH_EVENTS` to change the count.

use scene::events::EventStream;
use scene::formats::{EvsMap, ReadOptions, read_events, write_events};
use std::path::{Path, PathBuf};
use std::time::Instant;

fn stream(n: usize) -> EventStream {
    let (w, h) = (346u32, 260u32);
    let mut ev = EventStream::with_capacity(w, h, n);
    let mut s = 7u64;
    let mut t = 1589163147.368868f64;
    for _ in 0..n {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        t += ((s >> 54) as f64) * 1e-8;
        ev.push(
            t,
            ((s >> 20) % w as u64) as u16,
            ((s >> 30) % h as u64) as u16,
            if (s >> 40) & 1 == 1 { 1 } else { -1 },
        );
    }
    ev
}

/// Best of `reps` wall times in seconds.
fn best(reps: usize, mut f: impl FnMut()) -> f64 {
    (0..reps)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

struct Row {
    format: &'static str,
    op: &'static str,
    seconds: f64,
    bytes: u64,
}

fn results_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../target"));
    target.join("bench-results")
}

fn main() {
    let n: usize = std::env::var("DEGS_BENCH_EVENTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10_000_000);
    let ev = stream(n);
    let dir = tempfile::tempdir().expect("temp dir");
    let opts = ReadOptions {
        sensor: Some((ev.width, ev.height)),
        coord_scale: None,
    };
    let mut rows = Vec::new();
    for (format, name, reps) in [
        ("evs", "ev.evs", 3),
        ("text", "ev.txt", 2),
        ("npz", "ev.npz", 2),
    ] {
        let path = dir.path().join(name);
        let w = best(reps, || write_events(&path, &ev).expect("write"));
        let bytes = std::fs::metadata(&path).expect("size").len();
        let mut count = 0;
        let r = best(reps, || {
            count = read_events(&path, &opts).expect("read").len()
        });
        assert_eq!(count, n);
        rows.push(Row {
            format,
            op: "write",
            seconds: w,
            bytes,
        });
        rows.push(Row {
            format,
            op: "read",
            seconds: r,
            bytes,
        });
        if format == "evs" {
            let m = best(reps, || {
                let map = EvsMap::open(&path).expect("map");
                count = map.t().len();
            });
            rows.push(Row {
                format,
                op: "map (hash check, no copy)",
                seconds: m,
                bytes,
            });
        }
    }

    println!("events: {n}, threads: {}", rayon::current_num_threads());
    println!("| format | operation | time (s) | M events/s | MB/s | file MB |");
    println!("|---|---|---:|---:|---:|---:|");
    for r in &rows {
        println!(
            "| {} | {} | {:.3} | {:.1} | {:.0} | {:.0} |",
            r.format,
            r.op,
            r.seconds,
            n as f64 / r.seconds / 1e6,
            r.bytes as f64 / r.seconds / 1e6,
            r.bytes as f64 / 1e6
        );
    }
    let json = serde_json::json!({
        "bench": "events",
        "events": n,
        "threads": rayon::current_num_threads(),
        "results": rows.iter().map(|r| serde_json::json!({
            "format": r.format,
            "op": r.op,
            "seconds": r.seconds,
            "events_per_s": n as f64 / r.seconds,
            "bytes": r.bytes,
        })).collect::<Vec<_>>(),
    });
    let out = results_dir().join("events.json");
    scene::atomic::write_json_atomic(&out, &json).expect("write results");
    println!("wrote {}", out.display());
}
