//! `evflow` — event voxel grids, the event simulator, EV-FlowNet with LoRA, the
//! contrast-maximisation loss and LoCM fine-tuning (DESIGN §2, §5).

pub mod cm;
pub mod cm_grad;
pub mod lora;
pub mod net;
pub mod sim;
pub mod synthesize;
pub mod voxel;
