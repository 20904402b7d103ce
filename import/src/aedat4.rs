//! A DAVIS recording in one AEDAT 4.0 file: its events and its APS frames
//! ([`scene::formats::read_aedat4_frames`]) become a scene. The file holds neither
//! camera poses nor a calibration:
//!
//! - poses: refused unless the caller says the camera did not move
//!   (`--static-camera`): then every frame gets the identity pose, with a warning;
//! - intrinsics: from an ECD-style `calib.txt` (`--calib`: `fx fy cx cy [k1 k2 p1 p2
//!   k3]`), else a guess (fx = fy = sensor width in pixels, about 53° horizontally,
//!   centred), with a warning.
//!
//! APS frames are linear readouts, so the scene says `frame_encoding: linear`.

use crate::ecd::calib_or_guess;
use crate::recording::{FrameImage, Recording, SourceFrame};
use scene::Pose;
use scene::error::{Error, Result};
use scene::formats::aedat4::read_aedat4;
use scene::formats::{ReadOptions, read_aedat4_frames};
use scene::manifest::FrameEncoding;
use std::path::Path;

/// Read `file` (events and frames); `calib` and `static_camera` as in the module doc.
pub(crate) fn read_aedat4_recording(
    file: &Path,
    calib: Option<&Path>,
    static_camera: bool,
) -> Result<Recording> {
    let events = read_aedat4(file, &ReadOptions::default())?;
    let frames = read_aedat4_frames(file)?;
    let (w, h) = (events.width, events.height);
    if frames.is_empty() {
        return Err(Error::invalid(
            file,
            "no APS frames (no FRME stream): a scene needs frames; record with frames enabled",
        ));
    }
    if !static_camera {
        return Err(Error::invalid(
            file,
            format!(
                "AEDAT4 stores no camera poses ({} frames, {} events found): pass --static-camera \
                 if the camera did not move (identity poses), or convert poses and frames into \
                 another layout (ecd: groundtruth.txt)",
                frames.len(),
                events.len()
            ),
        ));
    }
    let mut warnings = vec![format!(
        "no poses in the file: all {} frames use the identity pose (--static-camera)",
        frames.len()
    )];
    let camera = calib_or_guess(calib, w, h, &mut warnings)?;
    let mut out: Vec<SourceFrame> = Vec::with_capacity(frames.len());
    for (k, f) in frames.into_iter().enumerate() {
        if (f.width, f.height, f.position) != (w, h, (0, 0)) {
            return Err(Error::invalid(
                file,
                format!(
                    "frame {k} is a {}x{} region at {:?}, not the full {w}x{h} sensor",
                    f.width, f.height, f.position
                ),
            ));
        }
        if out.last().is_some_and(|p| p.timestamp >= f.timestamp) {
            warnings.push(format!(
                "frame {k} repeats the previous timestamp: left out"
            ));
            continue;
        }
        out.push(SourceFrame {
            image: FrameImage::Pixels {
                width: f.width,
                height: f.height,
                channels: f.channels,
                pixels: f.pixels,
            },
            timestamp: f.timestamp,
            pose: Pose::default(),
        });
    }
    Ok(Recording {
        layout: "aedat4",
        camera,
        frames: out,
        events,
        frame_encoding: FrameEncoding::Linear,
        warnings,
        held_out: None,
    })
}
