//! abysslight removes the lighting of co-moving artificial lights from deep-sea survey photographs, following
//! Köser et al., "Robustly Removing Deep Sea Lighting Effects for Visual Mapping of Abyssal Plains".
//!
//! A pixel sees `I = A·F + S`: seafloor albedo `A` times a factor image `F` (light cones, attenuation, vehicle
//! pose) plus additive backscatter `S`. What a caller needs is at the crate root:
//!
//! - a whole mission from folders to folders, as `abysslight correct` runs it: [`Options`] (the command line's
//!   options, with its defaults), [`correct_mission`], its [`Report`] ([`report`] has the parts) and
//!   [`Progress`]; [`merge_shards`] and [`cruise`] for cluster runs;
//! - the method on photos in memory: a [`Scatter`] (`S` from water-column frames), [`Params`] (the method's
//!   settings, [`Params::validate`]d; [`Options::params`] maps a run's options onto them, [`Params::resolved`]
//!   resolves every `auto`), the [`Engine`] that runs the method over a stream of [`Photo`]s with bounded memory:
//!   its first pass, the survey, chooses each photo's window as the photos come, as a run over a folder does;
//! - the window rule of the paper: [`p_half`] and [`choose_window`];
//! - [`kernels`]: the method's steps one by one (medians, `F`, the correction), for callers who want one alone;
//! - [`io`]: finding, decoding and writing photos (atomically, with their metadata);
//! - [`eval`]: a renderer of dives with known truth and the scores the project measures itself with.
//!
//! In memory, without files:
//!
//! ```
//! use abysslight::eval::simulate::Simulation;
//! use abysslight::{Engine, Params, Scatter};
//!
//! let dive = Simulation { frames: 9, width: 64, height: 48, ..Simulation::default() }.render()?;
//! let scatter = Scatter::from_frames(&dive.water)?;
//! let mut engine = Engine::new(Params::default(), scatter.as_ref(), None)?;
//! let mut corrected = Vec::new();
//! for (i, photo) in dive.survey.into_iter().enumerate() {
//!     corrected.extend(engine.push((photo, i))?);
//! }
//! corrected.extend(engine.finish());
//! assert_eq!(corrected.len(), 9);
//! # Ok::<(), abysslight::Error>(())
//! ```
//!
//! A mission on disk:
//!
//! ```no_run
//! use abysslight::{correct_mission, Options, Silent};
//! let opts = Options {
//!     water_column: Some("dive42/descent".into()),
//!     survey: Some("dive42/survey".into()),
//!     out: Some("dive42/corrected".into()),
//!     ..Options::default()
//! };
//! let report = correct_mission(&opts, &Silent)?;
//! println!("{} photos corrected, {} failed", report.corrected, report.failed);
//! # Ok::<(), abysslight::Error>(())
//! ```

#![warn(missing_docs)]

// The command line (`cli` feature) is part of the library so that the Python extension can run the same `abysslight`
// command; its code names the crate as `abysslight::`, as the binary did.
extern crate self as abysslight;

#[cfg(feature = "cli")]
#[doc(hidden)]
pub mod cli;
pub mod cruise;
pub mod error;
pub mod eval;
pub mod io;
pub mod kernels;
pub mod limits;
pub(crate) mod method;
pub mod options;
pub mod report;
pub(crate) mod run;
mod simd;

pub use error::{Error, Result};
pub use io::metadata::Metadata;
pub use io::navigation::Navigation;
pub use method::baseline::Method;
pub use method::engine::{Corrected, Engine, PhotoIn, Use};
pub use method::mask::Mask;
pub use method::members::Members;
pub use method::params::{BlockRule, Facts, InvalidConfig, Params, SeafloorColour, Steps, Window};
pub use method::raster::{BitDepth, Layout, Photo, Raster, Sample, Samples};
pub use method::scatter::Scatter;
pub use method::transfer::Transfer;
pub use method::window::{choose_window, p_half};
#[doc(no_inline)]
pub use options::{Options, Shard};
#[doc(no_inline)]
pub use report::{Progress, Report, Silent};
pub use run::correct_mission;
pub use run::merge::merge_shards;
/// The end-of-run summary in the command's words, for the Python binding.
#[doc(hidden)]
pub use run::summary;
