//! abysslight removes the lighting of co-moving artificial lights from deep-sea survey photographs, following
//! Köser et al., "Robustly Removing Deep Sea Lighting Effects for Visual Mapping of Abyssal Plains".
//!
//! A pixel sees `I = A·F + S`: seafloor albedo `A` times a factor image `F` (light cones, attenuation, vehicle
//! pose) plus additive backscatter `S`. The crate is layered; each layer uses only those before it:
//!
//! - [`method`]: the paper on photos in memory — `S` ([`method::scatter`]), block and temporal medians, the
//!   sliding window, `F` ([`method::factor`]), `A` ([`method::correct`]), and the [`Engine`] that runs them over a
//!   stream of photos with memory bounded by the window;
//! - [`io`]: finding, decoding and writing photos (atomically, with their metadata);
//! - [`run`]: a whole mission from folders to folders as `abysslight correct` runs it ([`correct_mission`]);
//! - [`eval`]: a renderer of dives with known truth, scores, the demo and the speed bench.
//!
//! In memory, without files:
//!
//! ```
//! use abysslight::eval::simulate::Simulation;
//! use abysslight::{Engine, Params, Scatter};
//!
//! let dive = Simulation { frames: 9, width: 64, height: 48, ..Simulation::default() }.render()?;
//! let scatter = Scatter::from_frames(&dive.water)?;
//! let mut engine = Engine::new(Params { window: 5, ..Params::default() }, scatter.as_ref(), None)?;
//! let mut corrected = Vec::new();
//! for (i, photo) in dive.survey.into_iter().enumerate() {
//!     corrected.extend(engine.push(photo, i)?);
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
pub mod error;
pub mod eval;
pub mod io;
pub mod method;
pub mod run;

pub use error::{Error, Result};
pub use io::metadata::Metadata;
pub use method::engine::{Corrected, Engine, Use};
pub use method::params::{Params, SeafloorColour};
pub use method::raster::{Photo, Raster};
pub use method::scatter::Scatter;
pub use method::window::{choose_window, p_half};
pub use run::correct_mission;
pub use run::options::{Options, Shard};
pub use run::report::{Progress, Report, Silent};
