//! `evflow` — event voxel grids, the event simulator, EV-FlowNet with LoRA, the
//! contrast-maximisation loss and LoCM fine-tuning (`docs/DESIGN.md` §2, §5).

pub mod cli;
pub mod cm;
pub mod eval;
pub mod finetune;
pub mod flowfile;
pub mod net;
pub mod predict;
pub mod pretrain;
pub mod sim;
pub mod source;
pub mod stage;
pub mod synthesize;
pub mod voxel;
