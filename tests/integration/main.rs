//! The integration tests: one binary (as ripgrep has), one module per subject. Each module makes its own small
//! synthetic photos; those that need `../shared/data/real` are `#[ignore]`d with the reason.

mod common;

mod abyss_quality;
mod altitude;
mod api;
mod batch;
mod budgets;
mod cli;
mod cluster_runs;
mod correct_e2e;
mod defaults;
mod do_no_harm;
mod engine;
mod exposure;
mod faults;
mod field;
mod first_day;
mod flag_ranges;
mod hardening;
mod honest_results;
mod jpeg_encoder_differential;
mod jpeg_like_input;
mod jpeg_reference;
mod lasers;
mod live;
mod merge_shards;
mod metadata;
mod newcomer;
mod nodules;
mod one_method;
mod real_photos;
mod run_locks;
mod simulate_evaluate;
mod threads_identical;
mod unlit_border;
mod vehicle_logs;
mod write_gate;
