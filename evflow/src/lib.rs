//! `evflow` — event voxel grids, EV-FlowNet with LoRA, the contrast-maximisation loss
//! and LoCM fine-tuning (docs/DESIGN.md §2, §5). The event simulator is in the `synth`
//! crate.

pub mod budget;
pub mod cli;
pub mod cm;
pub mod eval;
pub mod finetune;
pub mod net;
pub mod predict;
pub mod pretrain;
pub mod settings;
pub mod source;
pub mod stage;
pub mod voxel;

/// The `.evflow` and `.flo` files (in the data layer: their readers need no network).
pub use scene::formats::evflow as flowfile;
