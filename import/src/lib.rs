//! `import` — converters from the layouts public event datasets use to degs scene
//! directories (docs/DESIGN.md §3, "Importing recordings"); backs `degs import`.
//!
//! Each layout module reads its source into a [`Recording`] (camera, frames with
//! camera-to-world poses in the manifest's OpenGL axes, events, warnings about what it
//! assumed); [`write_scene`] chooses the train and test frames and writes the scene.
//! The pose conventions and their conversion are in [`convention`]. Each layout module
//! also has an exporter (scene → layout), used by the round-trip tests.

pub mod aedat4;
pub mod aligned;
pub mod blender;
pub mod colmap;
mod colmap_files;
pub mod convention;
pub mod ecd;
pub mod hsergb;
pub mod nerfies;
pub mod recording;
mod table;

pub use aligned::EventsAlignment;
pub use recording::{
    FrameImage, ImportOptions, ImportSummary, Recording, SourceFrame, Split, split_by,
    split_frames, write_scene,
};

use scene::error::Result;
use std::path::Path;

/// The source layouts `degs import` understands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// Event Camera Dataset: calib.txt, images.txt + images/, events.txt, groundtruth.txt.
    Ecd,
    /// One AEDAT 4.0 file (DAVIS): events and APS frames, no poses.
    Aedat4,
    /// HS-ERGB sequence: images_corrected/ + timestamp.txt, events_aligned/*.npz (×32).
    Hsergb,
    /// D-NeRF / Blender transforms_*.json with an event file beside them.
    Blender,
    /// nerfies / HyperNeRF / NeRF-DS: dataset.json, metadata.json, camera/, rgb/Nx/,
    /// with an event file beside them.
    Nerfies,
    /// A COLMAP sparse model (sparse/0/, images/) with an event file and the frames'
    /// times (timestamps.txt, or numbers in the image names).
    Colmap,
}

impl Layout {
    pub fn name(&self) -> &'static str {
        match self {
            Layout::Ecd => "ecd",
            Layout::Aedat4 => "aedat4",
            Layout::Hsergb => "hsergb",
            Layout::Blender => "blender",
            Layout::Nerfies => "nerfies",
            Layout::Colmap => "colmap",
        }
    }
}

/// Read `src` in `layout` and write the scene directory `out`.
pub fn import(
    layout: Layout,
    src: &Path,
    opts: &ImportOptions,
    out: &Path,
) -> Result<ImportSummary> {
    let mut rule = scene::atomic::OutputRule::new(recording::IMPORT_COMMAND)
        .force(opts.force)
        .source(src);
    for p in (opts.calib.iter())
        .chain(&opts.alignment.events)
        .chain(&opts.timestamps)
    {
        rule = rule.source(p);
    }
    rule.check(out)?;
    let rec = match layout {
        Layout::Ecd => ecd::read_ecd(src)?,
        Layout::Hsergb => hsergb::read_hsergb(src, opts.calib.as_deref())?,
        Layout::Blender => blender::read_blender(src, &opts.alignment)?,
        Layout::Nerfies => nerfies::read_nerfies(src, &opts.alignment, opts.downscale)?,
        Layout::Colmap => colmap::read_colmap(
            src,
            &colmap::ColmapOptions {
                events: opts.alignment.events.clone(),
                timestamps: opts.timestamps.clone(),
                name_seconds: opts.name_seconds,
            },
        )?,
        Layout::Aedat4 => {
            aedat4::read_aedat4_recording(src, opts.calib.as_deref(), opts.static_camera)?
        }
    };
    recording::write_scene_with(&rec, opts, out, &rule)
}
