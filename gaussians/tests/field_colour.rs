//! A colour field (`FieldSettings::color`): the trainer's gradient of every field
//! parameter, taken through the renderer and the colour deltas, against central
//! differences in f64 of a loss rendered by the f64 reference rasterizer with the
//! f64 network's colour added to each Gaussian's DC coefficients.

mod raster_common;

use gaussians::Planes;
use gaussians::field::{FieldSettings, Mlp};
use gaussians::raster::TileRasterizer;
use gaussians::raster::reference::{self, Gaussians64};
use gaussians::train::{TrainSettings, Trainer};
use raster_common::Rng;

#[test]
fn the_colour_fields_gradient_matches_finite_differences() {
    let mut rng = Rng(91);
    let splats = raster_common::random_splats(&mut rng, raster_common::SMOOTH);
    let field = FieldSettings {
        depth: 2,
        width: 8,
        pos_freqs: 2,
        time_freqs: 2,
        seed: 3,
        zero_head_init: false,
        color: true,
    };
    let s = TrainSettings {
        deform: true,
        static_iterations: 0,
        dynamic_only: false,
        field,
        ..TrainSettings::default()
    };
    let mut tr = Trainer::new(s, splats, 1.0);
    // The geometric outputs held at zero (their head columns and biases), so the field
    // changes colour only and the reference needs no deformation; the colour columns
    // scaled up so that δc is a sizeable part of each colour.
    let head = *tr.field.layers.last().unwrap();
    for j in 0..head.fan_in {
        for k in 0..head.fan_out {
            let w = &mut tr.field.params[head.weight + j * head.fan_out + k];
            *w = if k < 10 { 0.0 } else { 3.0 * *w };
        }
    }
    for k in 0..10 {
        tr.field.params[head.bias + k] = 0.0;
    }
    assert!(tr.field_on());
    let cam = raster_common::smooth_camera();
    let (w, h) = (cam.intrinsics.width, cam.intrinsics.height);
    let t = 0.35f32;
    let weights: Vec<f64> = (0..3 * w * h).map(|_| rng.uni(-1.0, 1.0)).collect();
    let w32: Vec<f32> = weights.iter().map(|&x| x as f32).collect();
    let r = TileRasterizer;
    let v = tr.render_view(&r, &cam, t);
    let g = tr.view_backward(&r, &v, &w32, Planes::NONE, None);
    assert_eq!(g.field.len(), tr.field.params.len());

    let bg = tr.settings.background.map(f64::from);
    let x64: Vec<[f64; 3]> = tr.splats.means.iter().map(|m| m.map(f64::from)).collect();
    let mut net = Mlp::<f64>::new(field, 0);
    net.params = tr.field.params.iter().map(|&p| p as f64).collect();
    let base = Gaussians64::from(&tr.splats);
    let mut loss = |params: &[f64]| -> f64 {
        net.params.copy_from_slice(params);
        let (rows, _) = net.forward(&x64, &[t as f64]);
        let mut g64 = base.clone();
        for (i, c) in g64.sh_dc.iter_mut().enumerate() {
            (0..3).for_each(|k| c[k] += rows[i * 13 + 10 + k]);
        }
        let f = reference::render(&g64, &cam, 0, bg);
        f.rgb.iter().zip(&weights).map(|(a, b)| a * b).sum()
    };
    let p0: Vec<f64> = tr.field.params.iter().map(|&p| p as f64).collect();
    let (mut num, mut den, mut checked) = (0.0f64, 0.0f64, 0);
    const EPS: f64 = 1e-6;
    for p in 0..p0.len() {
        // Parameters that reach only the geometric outputs have no colour path (and
        // a zero gradient here, checked below).
        let geometric_head = (p >= head.weight && p < head.bias && (p - head.weight) % 13 < 10)
            || (p >= head.bias && p < head.bias + 10);
        if geometric_head {
            continue;
        }
        let mut q = p0.clone();
        q[p] += EPS;
        let lp = loss(&q);
        q[p] -= 2.0 * EPS;
        let fd = (lp - loss(&q)) / (2.0 * EPS);
        num += (g.field[p] as f64 - fd).powi(2);
        den += fd * fd;
        checked += 1;
    }
    assert!(checked > 100, "{checked} parameters checked");
    assert!(
        den.sqrt() > 1e-2,
        "the colour must reach the image: {}",
        den.sqrt()
    );
    let rel = num.sqrt() / den.sqrt();
    assert!(
        rel < 1e-3,
        "relative error {rel:.2e} against f64 central differences"
    );
    // The canonical DC coefficients' gradient is the deformed ones' (c' = c + δc): the
    // colour bias gradient is its sum over the Gaussians.
    for k in 0..3 {
        let sum: f64 = g.splats.sh_dc.iter().map(|c| c[k] as f64).sum();
        let bias = g.field[head.bias + 10 + k] as f64;
        assert!(
            (sum - bias).abs() < 1e-4 * sum.abs().max(1.0),
            "{sum} against {bias}"
        );
    }
}
