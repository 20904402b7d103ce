//! The analytic world: exact renders and ground truth (docs/DESIGN.md §2: "analytic
//! synthetic scenes with ground truth"). Not a Gaussian rasterizer: every pixel casts a
//! ray against textured planes, boxes and ellipsoids and returns
//!
//! - linear RGB in [0, 1] (`n×n` supersampled: `frame_supersample` for the RGB frames,
//!   `supersample` for the event simulator's internal renders),
//! - depth `d = −z_cam` (OpenGL axes as [`scene::camera`]; 0 where nothing is hit),
//! - dense optical flow in px/s, **analytic**: the time derivative of the projection of
//!   the surface point hit at the pixel centre, including camera motion,
//! - the object id (0 = background, `k + 1` = `objects[k]`).
//!
//! Motion model of object k (see [`Motion`](crate::config::Motion),
//! [`Deform`](crate::config::Deform)): a material
//! point `q` is at `X(t) = c(t) + R(t)·S(t)·D(q, t)` where `S` is a non-uniform pulsing
//! scale and `D` lifts plane points by a travelling wave (both non-rigid; identity for
//! rigid objects). Its velocity is `Ẋ = ċ + ω × (R·S·D) + R·(Ṡ·D + S·Ḋ)` (ω the world
//! angular velocity of R). The camera is at `e(t)` with rotation
//! `R_c(t)` and angular velocity `ω_c`; in camera coordinates
//! `p = R_cᵀ(X − e)`, `ṗ = R_cᵀ(Ẋ − ė − ω_c × (X − e))`, and with `d = −p_z`
//! the flow is `u̇ = f_x(ṗ_x d − p_x ḋ)/d²`, `v̇ = −f_y(ṗ_y d − p_y ḋ)/d²`.
//! Rays that hit nothing see a point at infinity (only the camera rotation moves it).
//!
//! The novel-view camera ([`SynthWorld::novel_camera_at`], setting `novel_angle_deg` = θ)
//! has its centre at `c + R_y(θ)(e(t) − c)`, `c` the path's `target`, and looks at `c`
//! with +Y up (a look-at rotation, so `c` projects to the principal point). Its flow
//! uses its own velocity `R_y(θ)·ė` and the angular velocity of the look-at frame
//! `ω = ½ Σ_i r_i × ṙ_i` over its axes `r_i` (exact for any rotating orthonormal frame).
//!
//! Worlds are built from a [`SynthConfig`] (serde; [`SynthConfig::preset`] for the
//! named presets).

use crate::config::{Shape, SynthConfig};
use crate::geometry::{Wave, intersect, intersect_wave, texture_coords};
use crate::texture;
use glam::{DMat3, DQuat, DVec2, DVec3};
use rayon::prelude::*;
use scene::camera::{Camera, Intrinsics, Pose};
use stagekit::Settings;
use std::f64::consts::{PI, TAU};

/// Everything [`SynthWorld::render`] returns for one time. Arrays are row-major,
/// `width·height` long (`rgb` interleaved, 3 per pixel).
#[derive(Clone, Debug, PartialEq)]
pub struct Render {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<f32>,
    pub depth: Vec<f32>,
    pub flow_u: Vec<f32>,
    pub flow_v: Vec<f32>,
    pub object_id: Vec<u16>,
}

/// The surface point a ray hits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Index into the config's objects (object id − 1).
    pub object: usize,
    /// Camera depth `−z_cam` of the hit point.
    pub depth: f64,
    /// Material coordinates of the hit point.
    pub local: DVec3,
    /// World position of the hit point.
    pub world: DVec3,
}

/// Pose and velocities of one object at one time.
#[derive(Clone, Copy, Debug)]
struct ObjectState {
    centre: DVec3,
    rot: DMat3,
    scale: DVec3,
    /// `S⁻¹·Rᵀ`, world direction → material direction.
    to_local: DMat3,
    centre_rate: DVec3,
    omega: DVec3,
    scale_rate: DVec3,
    wave: Option<Wave>,
}

impl ObjectState {
    /// Material point → its deformed position before `S` (the wave lifts plane points).
    fn displaced(&self, q: DVec3) -> DVec3 {
        match &self.wave {
            Some(w) => DVec3::new(q.x, q.y, q.z + w.height(q.x, q.y)),
            None => q,
        }
    }

    /// Time derivative of [`Self::displaced`] at fixed material point.
    fn displaced_rate(&self, q: DVec3) -> DVec3 {
        match &self.wave {
            Some(w) => DVec3::new(0.0, 0.0, w.height_rate(q.x, q.y)),
            None => DVec3::ZERO,
        }
    }
}

/// Camera pose and velocities at one time.
#[derive(Clone, Copy, Debug)]
struct CameraState {
    eye: DVec3,
    rot: DMat3,
    eye_rate: DVec3,
    omega: DVec3,
}

/// The scene at one instant: what a ray cast needs.
struct Frame<'a> {
    world: &'a SynthWorld,
    cam: CameraState,
    objects: Vec<ObjectState>,
    /// The camera centre in each object's material coordinates (rays share it).
    eye_local: Vec<DVec3>,
    /// World bounding sphere (centre − eye, radius²) of each finite object.
    bounds: Vec<Option<(DVec3, f64)>>,
}

/// A synthetic world built from a [`SynthConfig`].
#[derive(Clone, Debug)]
pub struct SynthWorld {
    cfg: SynthConfig,
    intrinsics: Intrinsics,
    cam_base: DMat3,
    object_base: Vec<DQuat>,
}

impl SynthWorld {
    /// Build the world; `Err` names the bad setting.
    pub fn new(cfg: &SynthConfig) -> Result<SynthWorld, String> {
        cfg.validate()?;
        let intrinsics = Intrinsics::from_fov_x(cfg.width, cfg.height, cfg.fov_x_deg.to_radians());
        let look = Pose::look_at(cfg.camera.eye, cfg.camera.target, DVec3::Y);
        let object_base = cfg
            .objects
            .iter()
            .map(|o| {
                let r = o.motion.rotation_deg;
                DQuat::from_euler(
                    glam::EulerRot::XYZ,
                    r.x.to_radians(),
                    r.y.to_radians(),
                    r.z.to_radians(),
                )
            })
            .collect();
        Ok(SynthWorld {
            cfg: cfg.clone(),
            intrinsics,
            cam_base: DMat3::from_quat(look.rotation),
            object_base,
        })
    }

    pub fn config(&self) -> &SynthConfig {
        &self.cfg
    }

    pub fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    fn camera_state(&self, t: f64) -> CameraState {
        let c = &self.cfg.camera;
        let ws = TAU * c.sway_hz;
        let phase = DVec3::new(0.0, PI / 2.0, PI / 4.0);
        let arg = DVec3::splat(ws * t) + phase;
        let sin = DVec3::new(arg.x.sin(), arg.y.sin(), arg.z.sin());
        let cos = DVec3::new(arg.x.cos(), arg.y.cos(), arg.z.cos());
        let wt = TAU * c.turn_hz;
        let (yaw_a, pitch_a) = (c.yaw_deg.to_radians(), c.pitch_deg.to_radians());
        let yaw = yaw_a * (wt * t).sin();
        let yaw_rate = yaw_a * wt * (wt * t).cos();
        let pitch = pitch_a * (wt * t + PI / 3.0).sin();
        let pitch_rate = pitch_a * wt * (wt * t + PI / 3.0).cos();
        let ry = DMat3::from_rotation_y(yaw);
        // R = R_y(ψ)·R_x(θ)·R₀  ⇒  ω = ψ̇·ŷ + R_y(ψ)·(θ̇·x̂).
        CameraState {
            eye: c.eye + c.sway * sin,
            rot: ry * DMat3::from_rotation_x(pitch) * self.cam_base,
            eye_rate: c.sway * cos * ws,
            omega: DVec3::Y * yaw_rate + ry * (DVec3::X * pitch_rate),
        }
    }

    /// The novel-view camera at `t` (see the module doc).
    fn novel_camera_state(&self, t: f64) -> CameraState {
        let rec = self.camera_state(t);
        let c = self.cfg.camera.target;
        let ry = DMat3::from_rotation_y(self.cfg.novel_angle_deg.to_radians());
        let eye = c + ry * (rec.eye - c);
        let eye_rate = ry * rec.eye_rate;
        let (rot, omega) = look_at_motion(eye - c, eye_rate);
        CameraState {
            eye,
            rot,
            eye_rate,
            omega,
        }
    }

    fn object_state(&self, k: usize, t: f64) -> ObjectState {
        let o = &self.cfg.objects[k];
        let m = &o.motion;
        let wo = TAU * m.oscillation_hz;
        let axis = m.spin_axis.try_normalize().unwrap_or(DVec3::Y);
        let spin = m.spin_deg_per_s.to_radians();
        let rot = DMat3::from_quat(DQuat::from_axis_angle(axis, spin * t) * self.object_base[k]);
        let wd = TAU * o.deform.hz;
        let phase = DVec3::new(0.0, TAU / 3.0, 2.0 * TAU / 3.0);
        let arg = DVec3::splat(wd * t) + phase;
        let a = o.deform.scale_amplitude;
        let scale = DVec3::ONE + a * DVec3::new(arg.x.sin(), arg.y.sin(), arg.z.sin());
        let scale_rate = a * wd * DVec3::new(arg.x.cos(), arg.y.cos(), arg.z.cos());
        let d = &o.deform;
        let wave = (d.wave_amplitude != 0.0).then(|| Wave {
            amplitude: d.wave_amplitude,
            kx: TAU / d.wave_length,
            ky: PI / d.wave_length,
            phase: TAU * d.wave_hz * t,
            rate: TAU * d.wave_hz,
        });
        ObjectState {
            centre: m.position + m.velocity * t + m.oscillation * (wo * t).sin(),
            rot,
            scale,
            to_local: DMat3::from_diagonal(scale.recip()) * rot.transpose(),
            centre_rate: m.velocity + m.oscillation * wo * (wo * t).cos(),
            omega: axis * spin,
            scale_rate,
            wave,
        }
    }

    fn frame(&self, t: f64) -> Frame<'_> {
        self.frame_from(t, self.camera_state(t))
    }

    /// The scene at `t` seen by the camera `cam`.
    fn frame_from(&self, t: f64, cam: CameraState) -> Frame<'_> {
        let objects: Vec<ObjectState> = (0..self.cfg.objects.len())
            .map(|k| self.object_state(k, t))
            .collect();
        let eye_local = objects
            .iter()
            .map(|st| st.to_local * (cam.eye - st.centre))
            .collect();
        let bounds = self
            .cfg
            .objects
            .iter()
            .zip(&objects)
            .map(|(spec, st)| {
                let reach = match &spec.shape {
                    Shape::Plane { half_size } if half_size[0] > 0.0 && half_size[1] > 0.0 => {
                        let lift = st.wave.map_or(0.0, |w| w.amplitude.abs());
                        DVec3::new(half_size[0], half_size[1], lift).length()
                    }
                    Shape::Plane { .. } => return None,
                    Shape::Cuboid { half_size } => half_size.length(),
                    Shape::Ellipsoid { radii } => radii.max_element(),
                };
                let r = reach * st.scale.abs().max_element() * (1.0 + 1e-9) + 1e-12;
                Some((st.centre - cam.eye, r * r))
            })
            .collect();
        Frame {
            world: self,
            cam,
            objects,
            eye_local,
            bounds,
        }
    }

    /// The camera (intrinsics and camera-to-world pose) at time `t`.
    pub fn camera_at(&self, t: f64) -> Camera {
        let c = self.camera_state(t);
        Camera {
            intrinsics: self.intrinsics,
            cam_to_world: Pose::new(DQuat::from_mat3(&c.rot), c.eye),
        }
    }

    /// The novel-view camera at time `t`: the recorded centre rotated by
    /// `novel_angle_deg` about the vertical axis through the path's target, looking at
    /// the target (see the module doc).
    pub fn novel_camera_at(&self, t: f64) -> Camera {
        let c = self.novel_camera_state(t);
        Camera {
            intrinsics: self.intrinsics,
            cam_to_world: Pose::new(DQuat::from_mat3(&c.rot), c.eye),
        }
    }

    /// World position at time `t` of the material point `local` of object `object`.
    pub fn material_to_world(&self, object: usize, local: DVec3, t: f64) -> DVec3 {
        let s = self.object_state(object, t);
        s.centre + s.rot * (s.scale * s.displaced(local))
    }

    /// The ray through pixel `px` (sub-pixel coordinates) at time `t`.
    pub fn cast(&self, t: f64, px: DVec2) -> Option<Hit> {
        self.frame(t).cast(px)
    }

    /// The ray through pixel `px` of the novel-view camera at time `t`.
    pub(crate) fn cast_novel(&self, t: f64, px: DVec2) -> Option<Hit> {
        self.frame_from(t, self.novel_camera_state(t)).cast(px)
    }

    /// Analytic flow (px/s) at pixel `px` and time `t`.
    pub fn flow_at(&self, t: f64, px: DVec2) -> DVec2 {
        let f = self.frame(t);
        f.flow(px, f.cast(px).as_ref())
    }

    /// Render colour, depth, flow and object ids at time `t` as the event simulator's
    /// internal renders see it (`supersample`² colour samples per pixel).
    pub fn render(&self, t: f64) -> Render {
        self.render_sampled(t, self.cfg.supersample)
    }

    /// Render as the RGB (APS) camera sees it: `frame_supersample`² colour samples per
    /// pixel, i.e. the light integrated over the pixel's area, so hard texture edges
    /// and sub-pixel detail (the far checker floor) are area-averaged, not aliased.
    pub fn render_frame(&self, t: f64) -> Render {
        self.render_sampled(t, self.cfg.frame_supersample)
    }

    /// Render from the novel-view camera ([`Self::novel_camera_at`]) as the RGB camera
    /// sees it (`frame_supersample`² colour samples per pixel), with the depth, flow
    /// and object ids that camera sees.
    pub fn render_novel_frame(&self, t: f64) -> Render {
        let frame = self.frame_from(t, self.novel_camera_state(t));
        self.render_from(&frame, self.cfg.frame_supersample)
    }

    /// Render with `ss × ss` colour samples per pixel (rows in parallel); depth, flow
    /// and object ids are those of the pixel centre.
    pub fn render_sampled(&self, t: f64, ss: u32) -> Render {
        self.render_from(&self.frame(t), ss)
    }

    fn render_from(&self, frame: &Frame<'_>, ss: u32) -> Render {
        let (w, h) = (self.cfg.width as usize, self.cfg.height as usize);
        let mut out = Render {
            width: self.cfg.width,
            height: self.cfg.height,
            rgb: vec![0.0; 3 * w * h],
            depth: vec![0.0; w * h],
            flow_u: vec![0.0; w * h],
            flow_v: vec![0.0; w * h],
            object_id: vec![0; w * h],
        };
        let ss = ss.max(1) as usize;
        out.rgb
            .par_chunks_mut(3 * w)
            .zip(out.depth.par_chunks_mut(w))
            .zip(out.flow_u.par_chunks_mut(w))
            .zip(out.flow_v.par_chunks_mut(w))
            .zip(out.object_id.par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, ((((rgb, depth), fu), fv), ids))| {
                for x in 0..w {
                    let centre = DVec2::new(x as f64, y as f64);
                    let hit = frame.cast(centre);
                    let flow = frame.flow(centre, hit.as_ref());
                    fu[x] = flow.x as f32;
                    fv[x] = flow.y as f32;
                    if let Some(hit) = &hit {
                        depth[x] = hit.depth as f32;
                        ids[x] = (hit.object + 1) as u16;
                    }
                    let colour = if ss == 1 {
                        frame.colour(hit.as_ref())
                    } else {
                        let mut acc = [0.0; 3];
                        for j in 0..ss {
                            for i in 0..ss {
                                let off = DVec2::new(
                                    (i as f64 + 0.5) / ss as f64 - 0.5,
                                    (j as f64 + 0.5) / ss as f64 - 0.5,
                                );
                                let c = frame.colour(frame.cast(centre + off).as_ref());
                                for ch in 0..3 {
                                    acc[ch] += c[ch];
                                }
                            }
                        }
                        acc.map(|a| a / (ss * ss) as f64)
                    };
                    for ch in 0..3 {
                        rgb[3 * x + ch] = colour[ch] as f32;
                    }
                }
            });
        out
    }
}

/// Rotation (columns right, up, back as [`Pose::look_at`] with up +Y) and angular
/// velocity of a camera at `v` from the point it looks at, moving at `v_rate`.
fn look_at_motion(v: DVec3, v_rate: DVec3) -> (DMat3, DVec3) {
    let len = v.length();
    let back = v / len;
    let back_rate = (v_rate - back * back.dot(v_rate)) / len;
    let n = DVec3::Y.cross(back);
    let right = n / n.length();
    let n_rate = DVec3::Y.cross(back_rate);
    let right_rate = (n_rate - right * right.dot(n_rate)) / n.length();
    let up = back.cross(right);
    let up_rate = back_rate.cross(right) + back.cross(right_rate);
    let omega = 0.5 * (right.cross(right_rate) + up.cross(up_rate) + back.cross(back_rate));
    (DMat3::from_cols(right, up, back), omega)
}

impl Frame<'_> {
    /// World direction of the ray through `px`, scaled so that its camera-space z is −1
    /// (then the ray parameter of a hit is its depth).
    fn ray_dir(&self, px: DVec2) -> DVec3 {
        let k = &self.world.intrinsics;
        let d_cam = DVec3::new((px.x - k.cx) / k.fx, -(px.y - k.cy) / k.fy, -1.0);
        self.cam.rot * d_cam
    }

    fn cast(&self, px: DVec2) -> Option<Hit> {
        let dir = self.ray_dir(px);
        let origin = self.cam.eye;
        let mut best: Option<(usize, f64, DVec3)> = None;
        let objects = self.world.cfg.objects.iter().zip(&self.objects);
        let dir_len2 = dir.length_squared();
        for (k, ((spec, st), &o)) in objects.zip(&self.eye_local).enumerate() {
            let limit = best.map_or(f64::INFINITY, |b| b.1);
            // Cheap rejection by the bounding sphere (misses the ray or lies behind).
            if let Some((oc, r2)) = self.bounds[k] {
                let along = oc.dot(dir);
                let miss2 = oc.length_squared() - along * along / dir_len2;
                if miss2 > r2 || (along < 0.0 && oc.length_squared() > r2) {
                    continue;
                }
            }
            let d = st.to_local * dir;
            let found = match (&spec.shape, &st.wave) {
                (Shape::Plane { half_size }, Some(w)) => intersect_wave(*half_size, w, o, d, limit),
                (shape, _) => intersect(shape, o, d, limit).map(|s| (s, o + d * s)),
            };
            if let Some((s, local)) = found {
                best = Some((k, s, local));
            }
        }
        best.map(|(object, depth, local)| Hit {
            object,
            depth,
            local,
            world: origin + dir * depth,
        })
    }

    fn colour(&self, hit: Option<&Hit>) -> [f64; 3] {
        match hit {
            Some(h) => {
                let spec = &self.world.cfg.objects[h.object];
                let c = texture::shade(&spec.texture, texture_coords(&spec.shape, h.local));
                match &self.world.cfg.light {
                    Some(light) => c.map(|v| v * self.lit(h, light)),
                    None => c,
                }
            }
            None => self.world.cfg.background,
        }
    }

    /// `ambient + (1 − ambient)·max(0, n·l)` at `h`, with `n` the surface normal turned
    /// towards the camera: the material normal of the shape (a plane's wave is left
    /// out), to world by `(R·S)⁻ᵀ = (S⁻¹·Rᵀ)ᵀ`.
    fn lit(&self, h: &Hit, light: &crate::config::Light) -> f64 {
        let st = &self.objects[h.object];
        let q = h.local;
        let n_local = match &self.world.cfg.objects[h.object].shape {
            Shape::Plane { .. } => DVec3::Z,
            Shape::Cuboid { half_size } => {
                let r = q / *half_size;
                let a = r.abs();
                let (i, s) = if a.x >= a.y && a.x >= a.z {
                    (0, r.x)
                } else if a.y >= a.z {
                    (1, r.y)
                } else {
                    (2, r.z)
                };
                let mut n = DVec3::ZERO;
                n[i] = s.signum();
                n
            }
            Shape::Ellipsoid { radii } => q / (*radii * *radii),
        };
        let mut n = (st.to_local.transpose() * n_local).normalize_or_zero();
        if n.dot(h.world - self.cam.eye) > 0.0 {
            n = -n;
        }
        let l = light.direction.normalize_or_zero();
        light.ambient + (1.0 - light.ambient) * n.dot(l).max(0.0)
    }

    /// Analytic flow at `px` given what its ray hits (see the module doc).
    fn flow(&self, px: DVec2, hit: Option<&Hit>) -> DVec2 {
        let cam = &self.cam;
        let (rel, vel) = match hit {
            Some(h) => {
                let st = &self.objects[h.object];
                let p = st.displaced(h.local);
                let arm = st.rot * (st.scale * p);
                let v = st.centre_rate
                    + st.omega.cross(arm)
                    + st.rot * (st.scale_rate * p + st.scale * st.displaced_rate(h.local));
                let rel = h.world - cam.eye;
                (rel, v - cam.eye_rate - cam.omega.cross(rel))
            }
            // A point at infinity in direction D: only rotation moves it.
            None => {
                let d = self.ray_dir(px);
                (d, -cam.omega.cross(d))
            }
        };
        let rt = cam.rot.transpose();
        let (p, pd) = (rt * rel, rt * vel);
        let (d, dd) = (-p.z, -pd.z);
        if d <= 0.0 {
            return DVec2::ZERO;
        }
        let k = &self.world.intrinsics;
        DVec2::new(
            k.fx * (pd.x * d - p.x * dd) / (d * d),
            -k.fy * (pd.y * d - p.y * dd) / (d * d),
        )
    }
}
