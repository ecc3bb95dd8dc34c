//! The steps [`Method::Abyss`](crate::method::baseline::Method::Abyss) adds to the paper's estimate, one file each,
//! in the order [`crate::method::chain::abyss`] runs them on a photo's window (docs/method.md says what each one
//! measured): the window's quantile, exposure levelling, bright spots, the near window, overlaps, the scale of `S`,
//! then on `F` the per-photo gain, the floor, the blend and the levels by light. Each file holds its step's
//! algorithm, constants and tests; each step reads what it needs of the photo's window
//! ([`Window`](crate::method::seen::Window)) and checks its own switch in [`crate::method::params::Steps`]. Two
//! small modules serve several steps: [`lit_level`] (what the floor and the gains take shares of) and [`nodes`] (the
//! smooth fields of the near window and the bright spots).

pub(crate) mod blend;
pub(crate) mod bright_spots;
pub(crate) mod floor;
pub(crate) mod gain;
pub(crate) mod lasers;
pub(crate) mod levelling;
pub(crate) mod levels_by_light;
pub(crate) mod lit_level;
pub(crate) mod near_window;
pub(crate) mod nodes;
pub(crate) mod overlaps;
pub(crate) mod quantile;
pub(crate) mod scatter_scale;
