use super::{Rng, assert_close, fd_grad};
use crate::motion_loss::{
    CsrBindings, MotionGrad, MotionInputs, MotionSettings, Norm, PerGaussian, motion_loss, robust,
};
use crate::schedule::LossSchedule;

#[test]
fn schedule_follows_eq_13() {
    let s = LossSchedule::default();
    assert_eq!(s.gamma1(0), 2.0);
    assert_eq!(s.gamma2(0), 0.0);
    assert!((s.gamma2(4000) - (1.0 - (-1.0f64).exp())).abs() < 1e-15);
    let want = 1.0 - (-1.0f64 / 4000.0).exp();
    assert!((s.gamma2(1) - want).abs() < 1e-12 * want);
    assert!((s.gamma2(200_000) - 1.0).abs() < 1e-15);
    assert!(
        (s.total(4000, 0.5, 0.25, 2.0) - (0.5 + 2.0 * 0.25 + 2.0 * s.gamma2(4000))).abs() < 1e-15
    );
    let flat = LossSchedule {
        gamma2_iters: 0.0,
        gamma2_max: 0.3,
        ..s
    };
    assert_eq!(flat.gamma2(0), 0.3);
    let off = LossSchedule {
        gamma1: 0.0,
        gamma2_max: 0.0,
        ..s
    };
    assert_eq!(off.total(10, 1.0, 5.0, 7.0), 1.0);
}

const ALL: [Norm; 4] = [Norm::L1, Norm::Charbonnier, Norm::Huber, Norm::L2];

fn settings(norm: Norm) -> MotionSettings {
    MotionSettings {
        norm,
        epsilon: 0.01,
        huber_delta: 0.5,
        ..MotionSettings::default()
    }
}

#[test]
fn value_on_a_hand_made_case() {
    // One Gaussian, two events with weights ¼ and ¾, over Δt = 0.1 s.
    let offsets = [0u32, 2];
    let events = [10u64, 12];
    let weights = [0.25f32, 0.75];
    let flow_u = [40.0, 0.0, 20.0];
    let flow_v = [-8.0, 0.0, 0.0];
    let (ego_u, ego_v) = ([5.0], [1.0]);
    let (gs_u, gs_v) = ([1.0], [-0.5]);
    let inp = MotionInputs {
        dt: 0.1,
        bindings: CsrBindings {
            offsets: &offsets,
            events: &events,
            weights: &weights,
        },
        flow_u: &flow_u,
        flow_v: &flow_v,
        flow_base: 10,
        ego: Some(PerGaussian {
            u: &ego_u,
            v: &ego_v,
            valid: None,
        }),
        gs: PerGaussian {
            u: &gs_u,
            v: &gs_v,
            valid: None,
        },
    };
    // Σw·f·Δt = (0.1·(10 + 15), 0.1·(−2)) = (2.5, −0.2); F_ego·Δt + F_gs = (1.5, −0.4).
    let r = [1.0f64, 0.2];
    let n = (r[0] * r[0] + r[1] * r[1]).sqrt();
    for norm in ALL {
        let s = settings(norm);
        let want = match norm {
            Norm::L1 => (1.0f64 + 1e-4).sqrt() + (0.04f64 + 1e-4).sqrt() - 0.02,
            Norm::Charbonnier => (n * n + 1e-4).sqrt() - 0.01,
            Norm::Huber => n - 0.25,
            Norm::L2 => n * n,
        };
        let out = motion_loss(&s, &inp, None);
        assert!(
            (out.loss - want).abs() < 1e-12,
            "{norm:?}: {} vs {want}",
            out.loss
        );
        assert_eq!((out.bound, out.missing_events), (1, 0));
        assert!((out.mean_residual - n).abs() < 1e-12);
    }
}

struct Case {
    offsets: Vec<u32>,
    events: Vec<u64>,
    weights: Vec<f32>,
    flow_u: Vec<f64>,
    flow_v: Vec<f64>,
    gs_valid: Vec<bool>,
    ego_valid: Vec<bool>,
}

fn case(rng: &mut Rng, n: usize) -> Case {
    let mut c = Case {
        offsets: vec![0],
        events: vec![],
        weights: vec![],
        flow_u: (0..50).map(|_| rng.uniform(-80.0, 80.0)).collect(),
        flow_v: (0..50).map(|_| rng.uniform(-80.0, 80.0)).collect(),
        gs_valid: vec![true; n],
        ego_valid: vec![true; n],
    };
    for g in 0..n {
        let k = if g % 4 == 1 { 0 } else { 1 + g % 3 }; // some Gaussians bind to none
        let w: Vec<f64> = (0..k).map(|_| rng.uniform(0.1, 1.0)).collect();
        let sw: f64 = w.iter().sum();
        for wi in w {
            c.events.push(100 + (rng.next_u64() % 50));
            c.weights.push((wi / sw) as f32);
        }
        c.offsets.push(c.events.len() as u32);
    }
    let g4 = c.offsets[4] as usize; // Gaussian 4 has two events; one has no flow
    c.events[g4] = 7;
    c.gs_valid[2] = false;
    c.ego_valid[6] = false;
    c
}

#[test]
fn gradient_matches_finite_differences_for_every_norm() {
    let mut rng = Rng::new(31);
    let n = 12;
    let c = case(&mut rng, n);
    let base: Vec<f64> = (0..4 * n).map(|_| rng.uniform(-3.0, 3.0)).collect();
    for norm in ALL {
        for with_ego in [true, false] {
            let s = settings(norm);
            let run = |x: &[f64], grad: Option<&mut MotionGrad<f64>>| {
                let inp = MotionInputs {
                    dt: 0.05,
                    bindings: CsrBindings {
                        offsets: &c.offsets,
                        events: &c.events,
                        weights: &c.weights,
                    },
                    flow_u: &c.flow_u,
                    flow_v: &c.flow_v,
                    flow_base: 100,
                    ego: with_ego.then_some(PerGaussian {
                        u: &x[0..n],
                        v: &x[n..2 * n],
                        valid: Some(&c.ego_valid),
                    }),
                    gs: PerGaussian {
                        u: &x[2 * n..3 * n],
                        v: &x[3 * n..],
                        valid: Some(&c.gs_valid),
                    },
                };
                motion_loss(&s, &inp, grad)
            };
            let num = fd_grad(&base, 1e-6, |x| run(x, None).loss);
            let mut g = MotionGrad::default();
            let out = run(&base, Some(&mut g));
            // 12 Gaussians: 3 bind to none, one has an invalid F_gs, one (with ego) an
            // invalid F_ego.
            assert_eq!(out.bound, if with_ego { 7 } else { 8 }, "{norm:?}");
            assert_eq!(out.missing_events, 1);
            let an: Vec<f64> = g
                .ego_u
                .iter()
                .chain(&g.ego_v)
                .chain(&g.gs_u)
                .chain(&g.gs_v)
                .copied()
                .collect();
            assert_close(&format!("{norm:?} ego {with_ego}"), &an, &num, 1e-6, 1e-9);
            if !with_ego {
                assert!(g.ego_u.iter().all(|&x| x == 0.0));
            }
        }
    }
}

#[test]
fn no_events_weights_and_f32() {
    let s = MotionSettings::default();
    // Nothing bound: zero loss, zero gradient, no NaN.
    let offsets = [0u32, 0, 0];
    let z = [0.0f32; 2];
    let inp = MotionInputs {
        dt: 0.1f32,
        bindings: CsrBindings {
            offsets: &offsets,
            events: &[],
            weights: &[],
        },
        flow_u: &[],
        flow_v: &[],
        flow_base: 0,
        ego: None,
        gs: PerGaussian {
            u: &z,
            v: &z,
            valid: None,
        },
    };
    let mut g = MotionGrad::default();
    let out = motion_loss(&s, &inp, Some(&mut g));
    assert_eq!((out.loss, out.bound, out.mean_residual), (0.0, 0, 0.0));
    assert_eq!(g.gs_u, vec![0.0; 2]);
    // No Gaussians at all.
    let empty = MotionInputs {
        bindings: CsrBindings {
            offsets: &[],
            events: &[],
            weights: &[],
        },
        gs: PerGaussian {
            u: &[],
            v: &[],
            valid: None,
        },
        ..inp
    };
    assert_eq!(motion_loss(&s, &empty, None).bound, 0);
    // Weights that do not sum to 1 are normalised; all-zero weights skip the Gaussian.
    let offsets = [0u32, 2, 4];
    let events = [0u64, 1, 0, 1];
    let fu = [10.0f64, 30.0];
    let fv = [0.0f64, 0.0];
    let gs0 = [0.0f64; 2];
    let run = |w: &[f32]| {
        let inp = MotionInputs {
            dt: 1.0,
            bindings: CsrBindings {
                offsets: &offsets,
                events: &events,
                weights: w,
            },
            flow_u: &fu,
            flow_v: &fv,
            flow_base: 0,
            ego: None,
            gs: PerGaussian {
                u: &gs0,
                v: &gs0,
                valid: None,
            },
        };
        motion_loss(
            &MotionSettings {
                norm: Norm::L2,
                ..s
            },
            &inp,
            None,
        )
    };
    let a = run(&[1.0, 1.0, 0.5, 0.5]);
    assert_eq!((a.loss, a.bound), (400.0, 2));
    let b = run(&[1.0, 1.0, 0.0, 0.0]);
    assert_eq!((b.loss, b.bound), (400.0, 1));
    // f32 agrees with f64.
    let mut rng = Rng::new(2);
    let c = case(&mut rng, 40);
    let x: Vec<f64> = (0..160).map(|_| rng.uniform(-3.0, 3.0)).collect();
    let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
    let (fu32, fv32): (Vec<f32>, Vec<f32>) = (
        c.flow_u.iter().map(|&v| v as f32).collect(),
        c.flow_v.iter().map(|&v| v as f32).collect(),
    );
    let b = CsrBindings {
        offsets: &c.offsets,
        events: &c.events,
        weights: &c.weights,
    };
    let l64 = motion_loss(
        &s,
        &MotionInputs {
            dt: 0.05,
            bindings: b,
            flow_u: &c.flow_u,
            flow_v: &c.flow_v,
            flow_base: 100,
            ego: Some(PerGaussian {
                u: &x[0..40],
                v: &x[40..80],
                valid: None,
            }),
            gs: PerGaussian {
                u: &x[80..120],
                v: &x[120..],
                valid: None,
            },
        },
        None,
    );
    let l32 = motion_loss(
        &s,
        &MotionInputs {
            dt: 0.05f32,
            bindings: b,
            flow_u: &fu32,
            flow_v: &fv32,
            flow_base: 100,
            ego: Some(PerGaussian {
                u: &x32[0..40],
                v: &x32[40..80],
                valid: None,
            }),
            gs: PerGaussian {
                u: &x32[80..120],
                v: &x32[120..],
                valid: None,
            },
        },
        None,
    );
    assert!((l64.loss - l32.loss as f64).abs() < 1e-5 * l64.loss.abs().max(1.0));
    assert_eq!(l64.bound, l32.bound);
}

#[test]
fn robust_norms_are_smooth_at_zero_and_match_their_derivative() {
    for norm in ALL {
        let s = settings(norm);
        let (v, d) = robust(&s, [0.0f64, 0.0]);
        assert_eq!((v, d), (0.0, [0.0, 0.0]), "{norm:?}");
        for r in [[0.003, -0.002], [0.3, 0.1], [2.0, -1.5]] {
            let num = fd_grad(&r, 1e-7, |x| robust(&s, [x[0], x[1]]).0);
            assert_close(&format!("{norm:?}"), &robust(&s, r).1, &num, 1e-6, 1e-9);
        }
    }
}
