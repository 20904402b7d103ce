//! A saved dynamic Gaussian model (the warm-up's output, the joint training's input):
//! `point_cloud.ply` (canonical Gaussians, 3DGS layout), `field.safetensors` +
//! `field.json` (deformation field, when the model has one) and `model.json`
//! ([`ModelInfo`]: SH degree, background, Gaussian count, per-Gaussian dynamic flags).

use crate::field::{self, Mlp};
use crate::raster::{Rasterizer, RenderedImage, TileRasterizer};
use crate::splats::Splats;
use crate::train::Trainer;
use scene::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

pub const PLY_FILE: &str = "point_cloud.ply";
pub const INFO_FILE: &str = "model.json";
/// Version of the `model.json` layout.
pub const FORMAT_VERSION: u32 = 1;

/// The model's metadata (`model.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelInfo {
    pub format_version: u32,
    /// SH degree the model renders with (and the PLY stores).
    pub sh_degree: u32,
    pub background: [f32; 3],
    /// The field deforms only Gaussians flagged dynamic.
    pub dynamic_only: bool,
    /// Number of Gaussians (must match the PLY).
    pub gaussians: usize,
    /// Whether `field.safetensors` / `field.json` belong to the model.
    pub has_field: bool,
    /// Training iterations the model has seen.
    #[serde(default)]
    pub iterations: u32,
    /// Per-Gaussian flags `'1'` = dynamic, `'0'` = static (absent: all dynamic).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dynamic: Option<String>,
}

impl Default for ModelInfo {
    fn default() -> Self {
        ModelInfo {
            format_version: FORMAT_VERSION,
            sh_degree: 3,
            background: [0.0; 3],
            dynamic_only: false,
            gaussians: 0,
            has_field: false,
            iterations: 0,
            dynamic: None,
        }
    }
}

/// Canonical Gaussians, optional deformation field and metadata.
#[derive(Clone, Debug)]
pub struct Model {
    pub splats: Splats,
    pub field: Option<Mlp<f32>>,
    pub info: ModelInfo,
}

impl Model {
    /// The model a trainer holds now (field included once it has been switched on, or
    /// whenever deformation is enabled and the run got past the static phase).
    pub fn from_trainer(tr: &Trainer) -> Model {
        let s = &tr.settings;
        let field = tr.field_on().then(|| tr.field.clone());
        Model {
            splats: tr.splats.clone(),
            info: ModelInfo {
                sh_degree: s.sh_degree.min(3),
                background: s.background,
                dynamic_only: s.dynamic_only,
                gaussians: tr.splats.len(),
                has_field: field.is_some(),
                iterations: tr.iteration,
                ..ModelInfo::default()
            },
            field,
        }
    }

    /// Write the model files into `dir` (created if missing); each file atomically.
    pub fn save(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let n = self.splats.len();
        let mut info = self.info.clone();
        info.format_version = FORMAT_VERSION;
        info.gaussians = n;
        info.has_field = self.field.is_some();
        info.dynamic = if self.splats.dynamic.is_empty() {
            None
        } else if self.splats.dynamic.len() == n {
            Some(
                self.splats
                    .dynamic
                    .iter()
                    .map(|&d| if d { '1' } else { '0' })
                    .collect(),
            )
        } else {
            return Err(Error::invalid(
                dir.join(INFO_FILE),
                format!(
                    "{} dynamic flags for {n} Gaussians",
                    self.splats.dynamic.len()
                ),
            ));
        };
        crate::ply::write(&dir.join(PLY_FILE), &self.splats, info.sh_degree)?;
        if let Some(f) = &self.field {
            field::io::save(f, dir)?;
        }
        scene::atomic::write_json_atomic(&dir.join(INFO_FILE), &info)
    }

    /// Read a model saved by [`Model::save`]; errors name the offending file.
    pub fn load(dir: &Path) -> Result<Model> {
        let ipath = dir.join(INFO_FILE);
        let text = std::fs::read_to_string(&ipath).map_err(|e| Error::io(&ipath, e))?;
        let mut info: ModelInfo = serde_json::from_str(&text)
            .map_err(|e| Error::invalid(&ipath, format!("not a model description: {e}")))?;
        if info.format_version != FORMAT_VERSION {
            return Err(Error::invalid(
                &ipath,
                format!(
                    "format version {} (expected {FORMAT_VERSION})",
                    info.format_version
                ),
            ));
        }
        if info.sh_degree > 3 || info.background.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid(
                &ipath,
                "sh_degree must be ≤ 3 and background finite",
            ));
        }
        let ppath = dir.join(PLY_FILE);
        let (mut splats, degree) = crate::ply::read(&ppath)?;
        if splats.len() != info.gaussians {
            return Err(Error::invalid(
                &ppath,
                format!(
                    "{} Gaussians but {} says {}",
                    splats.len(),
                    INFO_FILE,
                    info.gaussians
                ),
            ));
        }
        if degree != info.sh_degree {
            return Err(Error::invalid(
                &ppath,
                format!("SH degree {degree} but {INFO_FILE} says {}", info.sh_degree),
            ));
        }
        if let Some(flags) = info.dynamic.take() {
            if flags.len() != info.gaussians || flags.bytes().any(|b| b != b'0' && b != b'1') {
                return Err(Error::invalid(
                    &ipath,
                    format!("`dynamic` must be {} characters '0'/'1'", info.gaussians),
                ));
            }
            splats.dynamic = flags.bytes().map(|b| b == b'1').collect();
        }
        let field = if info.has_field {
            Some(field::io::load(dir)?)
        } else {
            None
        };
        Ok(Model {
            splats,
            field,
            info,
        })
    }

    /// The Gaussians deformed to normalised time `t` (the manifest's `time`); the
    /// canonical ones when the model has no field.
    pub fn at(&self, t: f32) -> Splats {
        match &self.field {
            None => self.splats.clone(),
            Some(mlp) => {
                let (d, _) = field::splat_deltas(mlp, &self.splats, t, self.info.dynamic_only);
                field::deform_splats(&self.splats, &d)
            }
        }
    }

    /// Render colour, depth and alpha at a camera and normalised time.
    pub fn render(&self, cam: &scene::Camera, t: f32) -> RenderedImage {
        TileRasterizer
            .render(&self.at(t), cam, self.info.sh_degree, self.info.background)
            .0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::FieldSettings;
    use crate::train::init::random_splats;

    fn model(with_field: bool) -> Model {
        let mut splats = random_splats(50, glam::DVec3::ZERO, 1.0, 3);
        for (i, r) in splats.sh_rest.iter_mut().enumerate() {
            r[0] = 0.01 * i as f32;
            r[44] = -0.02 * i as f32;
        }
        splats.dynamic = (0..50).map(|i| i % 3 != 0).collect();
        let field = with_field.then(|| {
            let s = FieldSettings {
                depth: 2,
                width: 16,
                ..FieldSettings::default()
            };
            Mlp::<f32>::new(s, 7)
        });
        Model {
            info: ModelInfo {
                dynamic_only: true,
                gaussians: 50,
                background: [0.25, 0.5, 1.0],
                ..ModelInfo::default()
            },
            splats,
            field,
        }
    }

    #[test]
    fn save_load_round_trips_bit_exactly() {
        for with_field in [false, true] {
            let dir = tempfile::tempdir().unwrap();
            let m = model(with_field);
            m.save(dir.path()).unwrap();
            let back = Model::load(dir.path()).unwrap();
            assert_eq!(back.splats, m.splats);
            assert_eq!(back.info.gaussians, 50);
            assert_eq!(back.info.has_field, with_field);
            assert_eq!(back.info.background, m.info.background);
            match (&back.field, &m.field) {
                (Some(a), Some(b)) => {
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&a.params), bits(&b.params));
                    assert_eq!(a.settings, b.settings);
                }
                (None, None) => {}
                _ => panic!("field presence differs"),
            }
            for t in [0.0, 0.4, 1.0] {
                assert_eq!(back.at(t), m.at(t));
            }
        }
    }

    #[test]
    fn field_moves_only_dynamic_gaussians() {
        let m = model(true);
        let a = m.at(0.7);
        let mut moved = 0;
        for i in 0..50 {
            if !m.splats.dynamic[i] {
                assert_eq!(a.means[i], m.splats.means[i]);
            } else if a.means[i] != m.splats.means[i] {
                moved += 1;
            }
        }
        assert!(moved > 0);
        assert_eq!(model(false).at(0.3), model(false).splats);
    }

    fn err_of(dir: &Path) -> String {
        Model::load(dir).unwrap_err().to_string()
    }

    #[test]
    fn missing_or_corrupt_files_give_errors_naming_them() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        assert!(err_of(d).contains(INFO_FILE));
        model(true).save(d).unwrap();
        let info = std::fs::read_to_string(d.join(INFO_FILE)).unwrap();

        std::fs::write(d.join(INFO_FILE), "{ not json").unwrap();
        assert!(err_of(d).contains(INFO_FILE));
        std::fs::write(
            d.join(INFO_FILE),
            info.replace("\"gaussians\": 50", "\"gaussians\": 49"),
        )
        .unwrap();
        let e = err_of(d);
        assert!(e.contains(PLY_FILE) && e.contains("49"), "{e}");
        std::fs::write(
            d.join(INFO_FILE),
            info.replace("\"sh_degree\": 3", "\"sh_degree\": 2"),
        )
        .unwrap();
        assert!(err_of(d).contains(PLY_FILE));
        std::fs::write(d.join(INFO_FILE), info.replacen("1", "2", 1)).unwrap();
        assert!(Model::load(d).is_err());
        std::fs::write(d.join(INFO_FILE), &info).unwrap();
        Model::load(d).unwrap();

        let w = d.join(field::io::WEIGHTS_FILE);
        let bytes = std::fs::read(&w).unwrap();
        std::fs::write(&w, &bytes[..bytes.len() / 2]).unwrap();
        assert!(err_of(d).contains(field::io::WEIGHTS_FILE));
        std::fs::remove_file(&w).unwrap();
        assert!(err_of(d).contains(field::io::WEIGHTS_FILE));
        std::fs::remove_file(d.join(field::io::SETTINGS_FILE)).unwrap();
        assert!(err_of(d).contains(field::io::SETTINGS_FILE));
        std::fs::remove_file(d.join(PLY_FILE)).unwrap();
        assert!(err_of(d).contains(PLY_FILE));
    }

    #[test]
    fn render_uses_the_saved_background() {
        let mut m = model(false);
        m.splats = Splats::default();
        m.info.gaussians = 0;
        m.info.dynamic = None;
        let cam = scene::Camera {
            intrinsics: scene::Intrinsics::from_fov_x(16, 8, 1.0),
            cam_to_world: scene::Pose::default(),
        };
        let f = m.render(&cam, 0.5);
        assert_eq!((f.width, f.height), (16, 8));
        assert!(f.rgb[..128].iter().all(|&v| v == 0.25));
        assert!(f.rgb[256..].iter().all(|&v| v == 1.0));
    }
}
