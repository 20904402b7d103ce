//! The runner core of degs (docs/DESIGN.md §4): experiment files, the stage registry and
//! the stages' settings as their binaries state them, the graph of cached nodes, the
//! content-addressed cache, the schedule that runs stages as processes ([`run`]), run
//! records, `status` / `gc` / `plan`, and the two nodes the runner builds around the
//! stages' outputs: the synthetic scene ([`synth`]) and the evaluation ([`eval`]).

pub mod baselines;
pub mod cache;
pub mod canon;
pub mod command_line;
pub mod config_show;
pub mod context;
pub mod eval;
pub mod experiment;
pub mod export;
pub mod external;
pub mod graph;
pub mod lock;
pub mod overrides;
pub mod plan;
pub mod process;
pub mod progress;
pub mod record;
pub mod run;
pub mod settings;
pub mod stage_progress;
pub mod stages;
pub mod status;
pub mod synth;
pub mod video;
