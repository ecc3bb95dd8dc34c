//! abysslight removes the lighting of co-moving artificial lights from deep-sea survey photographs, following
//! Köser et al., "Robustly Removing Deep Sea Lighting Effects for Visual Mapping of Abyssal Plains".
//!
//! A pixel sees `I = A·F + S`: seafloor albedo `A` times a factor image `F` (light cones, attenuation, vehicle
//! pose) plus additive backscatter `S`. The modules follow the method:
//!
//! - [`scatter`]: `S`, the temporal median of water-column frames;
//! - [`median`]: the spatial (block) and temporal median kernels;
//! - [`window`]: the sliding window and its size `n` from the contamination rate;
//! - [`factor`]: `F = (M − S) / C` and its upsampling;
//! - [`correct`]: `A = (I − S) / F`;
//! - [`pipeline`]: a whole mission, streamed in one pass.
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

pub mod baseline;
pub mod bench;
pub mod correct;
pub mod demo;
pub mod draw;
pub mod error;
pub mod evaluate;
pub mod factor;
pub mod io;
pub mod mask;
pub mod median;
pub mod metadata;
pub mod monitor;
pub mod options;
pub mod overview;
pub mod pipeline;
pub mod raster;
pub mod refine;
pub mod report;
pub mod scatter;
pub mod simulate;
pub mod source;
pub mod stream;
pub mod transfer;
pub mod watch;
pub mod window;

pub use error::{Error, Result};
pub use metadata::Metadata;
pub use options::{Options, SeafloorColour, Shard};
pub use pipeline::correct_mission;
pub use raster::{Photo, Raster};
pub use report::{Progress, Report, Silent};
pub use window::{choose_window, p_half};
