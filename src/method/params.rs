//! The method's own parameters ([`Params`]), shared by the in-memory [`Engine`](crate::method::engine::Engine)
//! and the run options of the command line.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

pub use crate::method::baseline::Method;
use crate::method::transfer::Transfer;

/// Grey level of the default seafloor colour `C`. Below mid-grey, so that objects brighter than the sediment
/// (corals, sponges, white shells, litter) keep 2.5× headroom before they clip.
pub const DEFAULT_GREY: f32 = 0.4;

/// The colour the seafloor is assumed to have after correction (`C` in `F = (M − S) / C`). It acts as a white
/// balance: a measured sediment colour gives photos in that colour, grey gives neutral ones.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct SeafloorColour(pub [f32; 3]);

impl Default for SeafloorColour {
    fn default() -> Self {
        SeafloorColour([DEFAULT_GREY; 3])
    }
}

impl SeafloorColour {
    /// `C` for a photo with `channels` colour channels (grey photos use the mean of the three).
    pub fn for_channels(&self, channels: usize) -> Vec<f32> {
        if channels == 3 {
            self.0.to_vec()
        } else {
            vec![(self.0[0] + self.0[1] + self.0[2]) / 3.0; channels]
        }
    }
}

impl FromStr for SeafloorColour {
    type Err = String;

    /// Accepts `grey` (or `gray`), `grey:0.5`, a single level `0.5`, three components `0.42,0.36,0.28` (in
    /// `(0, 1]`, or 8-bit `107,92,71` when any exceeds 1) or a hex colour `#8a7560`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim().to_ascii_lowercase();
        let bad = || {
            format!(
                "invalid seafloor colour {s:?}: expected grey, grey:0.4, 0.42,0.36,0.28, 107,92,71 or #8a7560"
            )
        };
        let rgb: [f32; 3] = if t == "grey" || t == "gray" {
            [DEFAULT_GREY; 3]
        } else if let Some(level) = t.strip_prefix("grey:").or_else(|| t.strip_prefix("gray:")) {
            let v: f32 = level.trim().parse().map_err(|_| bad())?;
            [v; 3]
        } else if let Some(hex) = t.strip_prefix('#') {
            if hex.len() != 6 || !hex.chars().all(|c| c.is_ascii_hexdigit()) {
                return Err(bad());
            }
            let byte = |i: usize| u8::from_str_radix(&hex[i..i + 2], 16).unwrap() as f32 / 255.0;
            [byte(0), byte(2), byte(4)]
        } else {
            let parts: Vec<f32> = t
                .split(',')
                .map(|p| p.trim().parse::<f32>())
                .collect::<Result<_, _>>()
                .map_err(|_| bad())?;
            let mut rgb = match parts.as_slice() {
                [v] => [*v; 3],
                [r, g, b] => [*r, *g, *b],
                _ => return Err(bad()),
            };
            if rgb.iter().any(|&v| v > 1.0) {
                for v in &mut rgb {
                    *v /= 255.0;
                }
            }
            rgb
        };
        if rgb.iter().any(|&v| !(v > 0.0 && v <= 1.0)) {
            return Err(format!(
                "invalid seafloor colour {s:?}: every component must be above 0 and at most 1 (or 255)"
            ));
        }
        Ok(SeafloorColour(rgb))
    }
}

impl TryFrom<String> for SeafloorColour {
    type Error = String;
    fn try_from(s: String) -> Result<Self, Self::Error> {
        s.parse()
    }
}

impl From<SeafloorColour> for String {
    fn from(c: SeafloorColour) -> String {
        c.to_string()
    }
}

impl fmt::Display for SeafloorColour {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [r, g, b] = self.0;
        write!(f, "{r},{g},{b}")
    }
}

/// What the [`Engine`](crate::method::engine::Engine) needs to know about the method. Defaults are those of
/// `abysslight correct`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// How the lighting is estimated. Default: [`Method::Paper`].
    pub method: Method,
    /// Photos in the sliding window, `n` (odd). Default: 7.
    pub window: usize,
    /// Block size `K` of the spatial median; 0 takes [`crate::method::factor::auto_block`] of the photos' size
    /// (from `S` or the mask when given, else from the first photo). Default: 8.
    pub downsample: usize,
    /// Seafloor colour `C`. Default: grey 0.4.
    pub seafloor_colour: SeafloorColour,
    /// Smallest `F` a pixel is divided by. Default: 0.05.
    pub factor_floor: f32,
    /// Camera curve of the stored values. Default: linear.
    pub transfer: Transfer,
    /// Degree of the polynomial of [`Method::Polynomial`]. Default: 4.
    pub degree: usize,
    /// [`Method::Abyss`]: the floor of `F` as a share of the photo's lit level, with a smooth hand-over
    /// ([`crate::method::refine::soft_floor`]). Default: 0.001.
    pub relative_floor: f32,
    /// [`Method::Abyss`]: one robust gain per photo and channel against its window's `M`. Default: true.
    pub photo_gain: bool,
    /// [`Method::Abyss`]: the scale of the water-column `S` for the survey photos; `None` estimates it per window
    /// ([`crate::method::refine::backscatter_scale`]). Default: `Some(1.0)` (`S` as measured: the estimate is
    /// biased low on red-starved channels, docs/evaluation.md).
    pub backscatter_scale: Option<f32>,
    /// [`Method::Abyss`]: blend dim regions towards their local level by their signal-to-noise ratio instead of
    /// amplifying noise ([`crate::method::noise`]). Default: true.
    pub denoise: bool,
    /// [`Method::Abyss`] with `denoise`: even out the blend's block levels across light levels
    /// ([`crate::method::noise::level_by_light`]), so dim regions are not left darker than lit ones. Default: true.
    pub level_by_light: bool,
    /// [`Method::Abyss`]: the quantile of the window's samples taken as `M` (0.5: the median, as in the paper).
    /// With a contamination rate `c` of dark objects (nodules, shadows) the seafloor's own median is the
    /// `(1 + c)/2` quantile; `correct` sets that when `--contamination` is given. Default: 0.5.
    pub window_quantile: f32,
    /// [`Method::Abyss`]: photos in the near window whose `M`'s smooth shape bends the window's
    /// ([`crate::method::refine::near_shape`]); 0, or not shorter than `window`: off. `correct` sets
    /// [`crate::method::window::near_window`]. Default: 0.
    pub near_window: usize,
    /// [`Method::Abyss`]: fill the window's `M` where bright spots that move — laser dots, highlights — held more
    /// than half of the window at a block ([`crate::method::outliers`]). Default: false.
    pub bright_spots: bool,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            method: Method::default(),
            window: 7,
            downsample: 8,
            seafloor_colour: SeafloorColour::default(),
            factor_floor: 0.05,
            transfer: Transfer::default(),
            degree: 4,
            relative_floor: 0.001,
            photo_gain: true,
            backscatter_scale: Some(1.0),
            denoise: true,
            level_by_light: true,
            window_quantile: 0.5,
            near_window: 0,
            bright_spots: false,
        }
    }
}
