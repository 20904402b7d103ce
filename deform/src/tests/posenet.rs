use super::{Rng, assert_close, fd_grad};
use crate::camera_path::{
    CameraPath, CameraVelocity, Interp, velocity_between, velocity_between_backward,
};
use crate::lie::perturb_camera_right;
use crate::posenet::{PoseNet, PoseNetSettings, apply_correction, correction_backward};
use glam::DVec3;
use scene::Pose;

fn small() -> PoseNetSettings {
    PoseNetSettings {
        frequencies: 3,
        hidden: 8,
        seed: 42,
    }
}

/// A network whose output layer is no longer zero (as after some training).
fn trained(s: PoseNetSettings) -> PoseNet<f64> {
    let mut net = PoseNet::<f64>::new(s);
    let mut rng = Rng::new(99);
    let n = net.params().len();
    let out = s.hidden * (s.input_dim() + 1);
    for p in &mut net.params_mut()[out..n] {
        *p = rng.uniform(-0.3, 0.3);
    }
    net
}

fn path() -> CameraPath {
    let mut rng = Rng::new(17);
    let times = [0.0, 0.2, 0.5, 0.7];
    let poses: Vec<Pose> = (0..4).map(|_| rng.pose(0.5, 1.0)).collect();
    CameraPath::new(&times, &poses, Interp::Linear).unwrap()
}

#[test]
fn zero_correction_at_initialisation() {
    let s = PoseNetSettings::default();
    assert_eq!(s.input_dim(), 13);
    assert_eq!(s.num_params(), 64 * 14 + 6 * 65);
    let net = PoseNet::<f32>::new(s);
    assert_eq!(net.params().len(), s.num_params());
    assert!(net.params()[..64 * 14].iter().any(|&p| p != 0.0));
    let p = path();
    for &t in &[0.0, 0.13, 0.5, 0.7] {
        let xi = net.forward(p.normalised_time(t) as f32);
        assert_eq!(xi, [0.0; 6]);
        let q = p.pose_at(t);
        assert_eq!(apply_correction(&q, xi.map(|x| x as f64)), q);
    }
    // Deterministic from the seed, different for another seed.
    assert_eq!(PoseNet::<f32>::new(s), net);
    let other = PoseNet::<f32>::new(PoseNetSettings { seed: 1, ..s });
    assert_ne!(other.params(), net.params());
    assert!(PoseNet::from_params(s, vec![0.0f32; 3]).is_err());
    assert!(PoseNet::from_params(s, net.params().to_vec()).is_ok());
}

#[test]
fn backward_matches_finite_differences() {
    let s = small();
    let net = trained(s);
    let g: [f64; 6] = [0.3, -0.7, 0.2, 0.9, -0.4, 0.5];
    for &t in &[0.0, 0.31, 0.77, 1.0] {
        let loss = |p: &[f64]| {
            let n = PoseNet::from_params(s, p.to_vec()).unwrap();
            n.forward(t).iter().zip(&g).map(|(a, b)| a * b).sum::<f64>()
        };
        let num = fd_grad(net.params(), 1e-6, loss);
        let mut an = vec![0.0; net.params().len()];
        net.backward(t, g, &mut an);
        assert_close(&format!("PoseNet gradient at t={t}"), &an, &num, 1e-6, 1e-9);
    }
    // At initialisation only the output layer has a gradient (W₂ = 0 blocks the rest).
    let fresh = PoseNet::<f64>::new(s);
    let mut an = vec![0.0; fresh.params().len()];
    fresh.backward(0.4, g, &mut an);
    let out = s.hidden * (s.input_dim() + 1);
    assert!(an[..out].iter().all(|&x| x == 0.0));
    assert!(an[out..].iter().any(|&x| x != 0.0));
}

#[test]
fn anchored_correction_is_zero_at_the_frames_and_its_gradient_matches() {
    let s = small();
    let net = trained(s);
    let (ta, tb) = (0.25, 0.5);
    // A trained net has a correction at the frames; the anchored one is exactly zero there.
    assert!(net.forward(ta).iter().any(|v| v.abs() > 1e-3));
    for t in [ta, tb] {
        assert!(
            net.forward_anchored(t, ta, tb)
                .iter()
                .all(|v| v.abs() < 1e-12)
        );
    }
    let mid = net.forward_anchored(0.4, ta, tb);
    let want: Vec<f64> = (0..6)
        .map(|o| net.forward(0.4)[o] - 0.4 * net.forward(ta)[o] - 0.6 * net.forward(tb)[o])
        .collect();
    assert_close("anchored ξ", &mid, &want, 1e-12, 1e-12);
    let g: [f64; 6] = [0.3, -0.7, 0.2, 0.9, -0.4, 0.5];
    for &t in &[0.3, 0.41, 0.49] {
        let loss = |p: &[f64]| {
            let n = PoseNet::from_params(s, p.to_vec()).unwrap();
            let x = n.forward_anchored(t, ta, tb);
            x.iter().zip(&g).map(|(a, b)| a * b).sum::<f64>()
        };
        let num = fd_grad(net.params(), 1e-6, loss);
        let mut an = vec![0.0; net.params().len()];
        net.backward_anchored(t, ta, tb, g, &mut an);
        assert_close(
            &format!("anchored gradient at t={t}"),
            &an,
            &num,
            1e-6,
            1e-9,
        );
    }
}

#[test]
fn f32_forward_agrees_with_f64() {
    let s = PoseNetSettings::default();
    let n64 = trained(s);
    let n32 = PoseNet::from_params(s, n64.params().iter().map(|&p| p as f32).collect()).unwrap();
    for &t in &[0.0, 0.25, 0.6, 1.0] {
        let a = n64.forward(t);
        let b = n32.forward(t as f32).map(|x| x as f64);
        assert_close("f32 vs f64", &b, &a, 1e-5, 1e-5);
    }
}

#[test]
fn correction_backward_matches_finite_differences() {
    let mut rng = Rng::new(5);
    let pose = rng.pose(1.0, 2.0);
    let pts: Vec<DVec3> = (0..3).map(|_| rng.vec3(2.0)).collect();
    let f = |p: &Pose| -> f64 {
        pts.iter()
            .map(|x| {
                let c = p.to_camera(*x);
                c.x * 0.3 - c.y * c.z + 0.1 * c.length_squared()
            })
            .sum()
    };
    for scale in [0.0, 1e-3, 0.3, 1.5] {
        let xi: [f64; 6] = std::array::from_fn(|_| rng.uniform(-1.0, 1.0) * scale);
        let corrected = apply_correction(&pose, xi);
        let g_eps: [f64; 6] = fd_grad(&[0.0; 6], 1e-6, |e| {
            f(&perturb_camera_right(&corrected, e.try_into().unwrap()))
        })
        .try_into()
        .unwrap();
        let num = fd_grad(&xi, 1e-6, |x| {
            f(&apply_correction(&pose, x.try_into().unwrap()))
        });
        assert_close(
            &format!("ξ gradient, |ξ|~{scale}"),
            &correction_backward(xi, g_eps),
            &num,
            1e-6,
            1e-8,
        );
    }
}

/// The whole chain the training loop will use: camera velocity of the corrected path
/// (symmetric difference) and a rasterizer-style (camera-right) pose gradient, back to the
/// PoseNet's weights.
#[test]
fn end_to_end_gradient_to_the_weights() {
    let s = small();
    let net = trained(s);
    let p = path();
    let (t, h) = (0.33, 0.01);
    let gvel = CameraVelocity {
        v: DVec3::new(0.4, -0.2, 0.7),
        w: DVec3::new(-0.3, 0.5, 0.1),
    };
    let target = DVec3::new(0.2, 0.3, -1.0);
    let loss = |n: &PoseNet<f64>| -> f64 {
        let corr = |tt: f64| apply_correction(&p.pose_at(tt), n.forward(p.normalised_time(tt)));
        let vel = velocity_between(&corr(t - 0.5 * h), &corr(t + 0.5 * h), h);
        // A render-like term on the pose at t.
        let q = corr(t);
        vel.v.dot(gvel.v) + vel.w.dot(gvel.w) + q.to_camera(target).length_squared()
    };
    let num = fd_grad(net.params(), 1e-6, |x| {
        loss(&PoseNet::from_params(s, x.to_vec()).unwrap())
    });

    let mut grad = vec![0.0; net.params().len()];
    let corr_at = |tt: f64| {
        let xi = net.forward(p.normalised_time(tt));
        (xi, apply_correction(&p.pose_at(tt), xi))
    };
    let ((xa, pa), (xb, pb), (xt, pt)) = (corr_at(t - 0.5 * h), corr_at(t + 0.5 * h), corr_at(t));
    let (ga, gb) = velocity_between_backward(&pa, &pb, h, &gvel);
    net.backward(
        p.normalised_time(t - 0.5 * h),
        correction_backward(xa, ga),
        &mut grad,
    );
    net.backward(
        p.normalised_time(t + 0.5 * h),
        correction_backward(xb, gb),
        &mut grad,
    );
    // The pose term's gradient as the rasterizer returns it (camera-right twist).
    let g_cam: [f64; 6] = fd_grad(&[0.0; 6], 1e-6, |e| {
        perturb_camera_right(&pt, e.try_into().unwrap())
            .to_camera(target)
            .length_squared()
    })
    .try_into()
    .unwrap();
    net.backward(
        p.normalised_time(t),
        correction_backward(xt, g_cam),
        &mut grad,
    );
    assert_close("end-to-end PoseNet gradient", &grad, &num, 1e-5, 1e-7);
}
