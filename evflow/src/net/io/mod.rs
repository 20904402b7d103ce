//! Every file the flow network reads or writes, in one place:
//!
//! - [`tensor_file`]: named f32 tensors in safetensors files and the JSON sidecar
//!   (`FILE.json`) beside them;
//! - [`weights`]: base weights ([`FlowNet::save`](crate::net::FlowNet::save),
//!   [`FlowNet::load`](crate::net::FlowNet::load), and [`load`], which also takes bare
//!   safetensors without a sidecar), and where the shipped weights are;
//! - [`adapters`]: LoRA adapters on their own, and which file `--adapter` means.
//!
//! Dependencies point one way: this module uses the network ([`crate::net::flownet`])
//! and the adapters' math ([`crate::net::lora`]); they know nothing of files.
//!
//! There is no PyTorch `.pth` reader: external weights are read from safetensors only.

pub mod adapters;
pub mod tensor_file;
pub mod weights;

pub use adapters::{ADAPTER_FILE, AdapterMeta, adapter_file, load_adapters, save_adapters};
pub use tensor_file::{NamedF32, TensorMap, read_safetensors, sidecar, take, write_safetensors};
pub use weights::{
    BareWeights, DEFAULT_MAX_FLOW, Loaded, TENSOR_NAMES_HELP, WEIGHTS_ENV, WeightsMeta,
    infer_config, load, load_base, resolve_weights, shipped_weights_dir,
};
