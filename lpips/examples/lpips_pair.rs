//! LPIPS of two images, and how long it took:
//! `cargo run -p degs-lpips --example lpips_pair -- A.png B.png [vgg|alex]`.
//! The weights are fetched at first use (see the crate docs).

use lpips::{Lpips, Rgb, Variant};
use std::time::Instant;

fn load(p: &str) -> anyhow::Result<(Vec<f32>, usize, usize)> {
    let img = image::open(p)
        .map_err(|e| anyhow::anyhow!("{p}: {e}"))?
        .to_rgb8();
    let (w, h) = img.dimensions();
    Ok((
        img.as_raw().iter().map(|&v| v as f32 / 255.0).collect(),
        w as usize,
        h as usize,
    ))
}

fn rgb(i: &(Vec<f32>, usize, usize)) -> Rgb<'_> {
    Rgb {
        data: &i.0,
        width: i.1,
        height: i.2,
    }
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (a, b) = match args.as_slice() {
        [a, b, ..] => (a, b),
        _ => anyhow::bail!("usage: lpips_pair A.png B.png [vgg|alex]"),
    };
    let v = match args.get(2).map(String::as_str) {
        None | Some("vgg") => Variant::Vgg,
        Some("alex") => Variant::Alex,
        Some(o) => anyhow::bail!("network '{o}' is not vgg or alex"),
    };
    let t = Instant::now();
    let m = Lpips::load(v)?;
    let load_s = t.elapsed().as_secs_f64();
    let (ia, ib) = (load(a)?, load(b)?);
    let t = Instant::now();
    let d = m.distance(rgb(&ia), rgb(&ib))?;
    let first = t.elapsed().as_secs_f64();
    let t = Instant::now();
    m.distance(rgb(&ia), rgb(&ib))?;
    let second = t.elapsed().as_secs_f64();
    println!(
        "LPIPS ({}) {d:.6}  [{}x{}; weights {load_s:.2} s, distance {first:.3} s, again {second:.3} s]",
        v.name(),
        ia.1,
        ia.2
    );
    Ok(())
}
