use super::{Rng, assert_close, fd_grad};
use crate::camera_path::{CameraPath, Interp};
use crate::flow::{
    EgoGrad, EgoPoints, Flow2, GsCameras, GsGrad, Pinhole, ProjCam, ego_flow, ego_flow_at,
    ego_flow_backward, ego_flow_image, gaussian_flow, gaussian_flow_backward, inverse_depth,
};
use crate::lie::perturb_camera_right;
use glam::{DVec2, DVec3};
use scene::{Camera, Intrinsics, Pose};

fn intrinsics() -> Intrinsics {
    Intrinsics {
        width: 64,
        height: 48,
        fx: 70.0,
        fy: 64.0,
        cx: 30.2,
        cy: 25.7,
        distortion: None,
    }
}

fn moving_path(interp: Interp) -> CameraPath {
    let mut rng = Rng::new(21);
    let times = [0.0, 0.1, 0.25, 0.4];
    let poses: Vec<Pose> = (0..4)
        .map(|i| {
            let eye = DVec3::new(0.3 * i as f64, 0.1 * (i as f64).sin(), 4.0) + rng.vec3(0.2);
            let look = Pose::look_at(eye, rng.vec3(0.3), DVec3::Y);
            crate::lie::perturb_camera_right(
                &look,
                [0.0, 0.0, 0.0, 0.0, 0.0, rng.uniform(-0.3, 0.3)],
            )
        })
        .collect();
    CameraPath::new(&times, &poses, interp).unwrap()
}

/// Eq. 9 against the real thing: a static world point, the camera moving along the
/// path, the pixel differentiated in time by central differences.
#[test]
fn ego_flow_is_the_image_velocity_of_static_points() {
    let k = intrinsics();
    let pin = Pinhole::<f64>::from_intrinsics(&k);
    let mut rng = Rng::new(4);
    for interp in [Interp::Linear, Interp::CatmullRom] {
        let path = moving_path(interp);
        for &t in &[0.03, 0.17, 0.3] {
            let cam = Camera {
                intrinsics: k,
                cam_to_world: path.pose_at(t),
            };
            let vel = path.velocity_at(t).to_array();
            for _ in 0..10 {
                let px = DVec2::new(rng.uniform(0.0, 63.0), rng.uniform(0.0, 47.0));
                let depth = rng.uniform(1.0, 6.0);
                let x = cam.unproject_world(px, depth);
                let h = 1e-6;
                let at = |s: f64| {
                    Camera {
                        intrinsics: k,
                        cam_to_world: path.pose_at(s),
                    }
                    .project_world(x)
                    .unwrap()
                    .0
                };
                let truth = (at(t + h) - at(t - h)) / (2.0 * h);
                let f = ego_flow_at(&pin, px.x, px.y, 1.0 / depth, &vel);
                assert_close(
                    &format!("{interp:?} F_ego at t={t}"),
                    &f,
                    &truth.to_array(),
                    1e-6,
                    1e-5,
                );
            }
        }
    }
}

#[test]
fn ego_flow_backward_matches_finite_differences() {
    let k = intrinsics();
    let pin = Pinhole::<f64>::from_intrinsics(&k);
    let mut rng = Rng::new(8);
    let n = 7;
    let u: Vec<f64> = (0..n).map(|_| rng.uniform(-5.0, 70.0)).collect();
    let v: Vec<f64> = (0..n).map(|_| rng.uniform(-5.0, 50.0)).collect();
    let mut rho: Vec<f64> = (0..n).map(|_| rng.uniform(0.0, 2.0)).collect();
    rho[2] = -1.0; // invalid (from `inverse_depth` of a depth at the near plane)
    rho[4] = 500.0; // nearer than the limit
    let vel: [f64; 6] = std::array::from_fn(|_| rng.uniform(-1.0, 1.0));
    let wu: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let wv: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let loss = |x: &[f64]| {
        let (uu, vv, rr) = (&x[0..n], &x[n..2 * n], &x[2 * n..3 * n]);
        let vel: [f64; 6] = x[3 * n..].try_into().unwrap();
        let mut out = Flow2::default();
        let pts = EgoPoints {
            u: uu,
            v: vv,
            inv_depth: rr,
        };
        ego_flow(&pin, &vel, pts, 100.0, &mut out);
        (0..n)
            .map(|i| wu[i] * out.u[i] + wv[i] * out.v[i])
            .sum::<f64>()
    };
    let x: Vec<f64> = u
        .iter()
        .chain(&v)
        .chain(&rho)
        .chain(&vel)
        .copied()
        .collect();
    let num = fd_grad(&x, 1e-6, loss);
    let mut out = Flow2::default();
    let pts = EgoPoints {
        u: &u,
        v: &v,
        inv_depth: &rho,
    };
    ego_flow(&pin, &vel, pts, 100.0, &mut out);
    assert_eq!(
        out.valid,
        [true, true, false, true, false, true, true],
        "validity"
    );
    assert_eq!(
        (out.u[2], out.v[2], out.u[4], out.v[4]),
        (0.0, 0.0, 0.0, 0.0)
    );
    let mut g = EgoGrad::default();
    ego_flow_backward(&pin, &vel, pts, &out, &wu, &wv, &mut g);
    let an: Vec<f64> =
        g.u.iter()
            .chain(&g.v)
            .chain(&g.inv_depth)
            .chain(&g.velocity)
            .copied()
            .collect();
    assert_close("F_ego gradient", &an, &num, 1e-7, 1e-6);
}

#[test]
fn ego_flow_f32_agrees_with_f64_and_image_form_with_points() {
    let k = intrinsics();
    let mut rng = Rng::new(9);
    let (w, h) = (64usize, 48usize);
    let depth: Vec<f64> = (0..w * h).map(|_| rng.uniform(0.5, 5.0)).collect();
    let mut inv: Vec<f64> = depth.iter().map(|&d| inverse_depth(d, 0.01)).collect();
    inv[5] = inverse_depth(0.0, 0.01);
    inv[6] = inverse_depth(f64::NAN, 0.01);
    inv[7] = inverse_depth(-2.0, 0.01);
    inv[8] = 1.0 / 1e-6; // Z → 0
    let vel: [f64; 6] = std::array::from_fn(|_| rng.uniform(-1.0, 1.0));
    let mut f64out = Flow2::default();
    ego_flow_image(
        &Pinhole::from_intrinsics(&k),
        &vel,
        w,
        &inv,
        100.0,
        &mut f64out,
    );
    let inv32: Vec<f32> = inv.iter().map(|&x| x as f32).collect();
    let vel32 = vel.map(|x| x as f32);
    let mut f32out = Flow2::<f32>::default();
    ego_flow_image(
        &Pinhole::from_intrinsics(&k),
        &vel32,
        w,
        &inv32,
        100.0,
        &mut f32out,
    );
    for i in 0..w * h {
        assert_eq!(f64out.valid[i], f32out.valid[i]);
        assert!(f32out.u[i].is_finite() && f32out.v[i].is_finite());
        let tol = 1e-5 * (1.0 + f64out.u[i].abs().max(f64out.v[i].abs()));
        assert!((f64out.u[i] - f32out.u[i] as f64).abs() < tol, "pixel {i}");
        assert!((f64out.v[i] - f32out.v[i] as f64).abs() < tol, "pixel {i}");
    }
    assert!(!f64out.valid[5] && !f64out.valid[6] && !f64out.valid[7] && !f64out.valid[8]);
    // Same numbers through the point form at the pixel centres.
    let us: Vec<f64> = (0..w * h).map(|i| (i % w) as f64).collect();
    let vs: Vec<f64> = (0..w * h).map(|i| (i / w) as f64).collect();
    let mut pts = Flow2::default();
    let p = EgoPoints {
        u: &us,
        v: &vs,
        inv_depth: &inv,
    };
    ego_flow(&Pinhole::from_intrinsics(&k), &vel, p, 100.0, &mut pts);
    assert_eq!(pts, f64out);
}

fn gs_case(rng: &mut Rng, n: usize) -> (Pose, Pose, Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let p0 = Pose::look_at(DVec3::new(0.2, 0.1, 4.0), DVec3::ZERO, DVec3::Y);
    let p1 = perturb_camera_right(&p0, [0.05, -0.02, 0.03, 0.01, 0.02, -0.015]);
    let x0: Vec<[f64; 3]> = (0..n).map(|_| rng.vec3(1.0).to_array()).collect();
    let x1: Vec<[f64; 3]> = x0
        .iter()
        .map(|x| (DVec3::from_array(*x) + rng.vec3(0.1)).to_array())
        .collect();
    (p0, p1, x0, x1)
}

#[test]
fn gaussian_flow_backward_matches_finite_differences() {
    let k = intrinsics();
    let mut rng = Rng::new(12);
    let n = 6;
    let (p0, p1, mut x0, x1) = gs_case(&mut rng, n);
    x0[3] = [0.2, 0.1, 4.5]; // behind the camera at t0: invalid
    let wu: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let wv: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect();
    for exact in [false, true] {
        let loss = |x: &[f64]| {
            let a: Vec<[f64; 3]> = (0..n)
                .map(|i| [x[3 * i], x[3 * i + 1], x[3 * i + 2]])
                .collect();
            let o = 3 * n;
            let b: Vec<[f64; 3]> = (0..n)
                .map(|i| [x[o + 3 * i], x[o + 3 * i + 1], x[o + 3 * i + 2]])
                .collect();
            let e0: [f64; 6] = x[6 * n..6 * n + 6].try_into().unwrap();
            let e1: [f64; 6] = x[6 * n + 6..].try_into().unwrap();
            let c0 = ProjCam::new(&perturb_camera_right(&p0, e0), &k, 0.01);
            let c1 = ProjCam::new(&perturb_camera_right(&p1, e1), &k, 0.01);
            let cams = if exact {
                GsCameras::Exact(&c0, &c1)
            } else {
                GsCameras::Same(&c0)
            };
            let mut out = Flow2::default();
            gaussian_flow(cams, &a, &b, &mut out);
            (0..n)
                .map(|i| wu[i] * out.u[i] + wv[i] * out.v[i])
                .sum::<f64>()
        };
        let x: Vec<f64> = x0
            .iter()
            .chain(&x1)
            .flatten()
            .copied()
            .chain([0.0; 12])
            .collect();
        let num = fd_grad(&x, 1e-6, loss);
        let c0 = ProjCam::new(&p0, &k, 0.01);
        let c1 = ProjCam::new(&p1, &k, 0.01);
        let cams = if exact {
            GsCameras::Exact(&c0, &c1)
        } else {
            GsCameras::Same(&c0)
        };
        let mut out = Flow2::default();
        gaussian_flow(cams, &x0, &x1, &mut out);
        assert!(!out.valid[3] && out.valid.iter().filter(|&&v| v).count() == n - 1);
        let mut g = GsGrad::default();
        gaussian_flow_backward(cams, &x0, &x1, &out, &wu, &wv, &mut g);
        let an: Vec<f64> =
            g.x0.iter()
                .chain(&g.x1)
                .flatten()
                .chain(&g.cam0)
                .chain(&g.cam1)
                .copied()
                .collect();
        assert_close(
            &format!("F_gs gradient (exact {exact})"),
            &an,
            &num,
            1e-6,
            1e-6,
        );
        assert_eq!(g.x0[3], [0.0; 3]);
    }
}

#[test]
fn gaussian_flow_forms_agree_with_projection_and_ego_motion() {
    let k = intrinsics();
    let pin = Pinhole::<f64>::from_intrinsics(&k);
    let path = moving_path(Interp::CatmullRom);
    let mut rng = Rng::new(2);
    let n = 20;
    let t0 = 0.12;
    let x0: Vec<[f64; 3]> = (0..n).map(|_| rng.vec3(0.8).to_array()).collect();
    let vel3: Vec<DVec3> = (0..n).map(|_| rng.vec3(2.0)).collect();
    let q0 = path.pose_at(t0);
    let c0 = ProjCam::new(&q0, &k, 0.01);
    let vel = path.velocity_at(t0).to_array();
    let cam = Camera {
        intrinsics: k,
        cam_to_world: q0,
    };
    // Largest |exact − (same + ego·Δt)| / |exact| over the Gaussians, for a span Δt.
    let worst = |dt: f64| -> f64 {
        let c1 = ProjCam::new(&path.pose_at(t0 + dt), &k, 0.01);
        let x1: Vec<[f64; 3]> = (0..n)
            .map(|i| (DVec3::from_array(x0[i]) + vel3[i] * dt).to_array())
            .collect();
        let (mut same, mut exact) = (Flow2::default(), Flow2::default());
        gaussian_flow(GsCameras::Same(&c0), &x0, &x1, &mut same);
        gaussian_flow(GsCameras::Exact(&c0, &c1), &x0, &x1, &mut exact);
        let mut worst = 0.0f64;
        for i in 0..n {
            let (px0, d0) = cam.project_world(DVec3::from_array(x0[i])).unwrap();
            let (px1, _) = cam.project_world(DVec3::from_array(x1[i])).unwrap();
            // Same camera: exactly the difference of the two projections.
            assert_close(
                "same",
                &[same.u[i], same.v[i]],
                &(px1 - px0).to_array(),
                1e-10,
                1e-12,
            );
            let ego = ego_flow_at(&pin, px0.x, px0.y, 1.0 / d0, &vel);
            let e = DVec2::new(exact.u[i], exact.v[i]);
            let sum = DVec2::new(same.u[i] + ego[0] * dt, same.v[i] + ego[1] * dt);
            worst = worst.max((e - sum).length() / e.length());
        }
        worst
    };
    // The decomposition F_gs + F_ego·Δt is first-order exact: its relative error
    // shrinks in proportion to Δt.
    let (a, b) = (worst(1e-3), worst(1e-4));
    assert!(
        a < 5e-2 && b < 5e-3,
        "relative errors {a:.2e} (1 ms), {b:.2e} (0.1 ms)"
    );
    assert!(
        (a / b - 10.0).abs() < 1.0,
        "error ratio {:.2} (first order: 10)",
        a / b
    );
}
