//! The `evaluate` stage of degs: image quality of a model's renders on the held-out test
//! frames and the novel views (PSNR, SSIM, LPIPS; on the moving objects' and the
//! co-visible pixels too), the 2D baselines a user has without a model (nearest frame,
//! linear blend, two-sided event pseudo image) and the per-event flow's error against
//! ground truth. `degs eval RUN` runs it as a cached stage over a run's outputs and
//! completes its `metrics.json` ([`scene::evaluation::Metrics`]).
//!
//! - [`stage`]: the stage (inputs, outputs);
//! - [`images`]: PSNR and SSIM of image files, renders paired with held-out images;
//! - [`masked`]: the novel views on masks, depth error, the trajectory figures;
//! - [`sheet`]: the novel views' contact sheet;
//! - [`lpips_use`]: LPIPS when its weights can be had;
//! - [`baselines`]: the 2D baselines;
//! - [`flow`]: the flow error;
//! - [`settings`]: what it computes beyond PSNR and SSIM (LPIPS or not).

pub mod baselines;
pub mod flow;
pub mod images;
pub mod lpips_use;
pub mod masked;
pub mod settings;
pub mod sheet;
pub mod stage;
