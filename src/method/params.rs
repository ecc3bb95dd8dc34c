//! The method's own parameters ([`Params`]), shared by the in-memory [`Engine`](crate::method::engine::Engine)
//! and the run options of the command line.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

pub use crate::error::InvalidConfig;
pub use crate::method::baseline::Method;
use crate::method::factor::auto_block;
use crate::method::transfer::Transfer;
use crate::method::window::{choose_window, WindowChoice};

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

/// How each photo's sliding window is chosen ([`Params::window`]).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Window {
    /// With [`Method::Abyss`], per stretch of the mission by the method's first pass, the survey
    /// (the survey, see [`Engine::LOOK_AHEAD`](crate::Engine::LOOK_AHEAD)): each photo's window, the quantile its `M` takes and its near window, from how
    /// much of the ground is dark and how far the camera moves. The other methods take the paper's
    /// paper's 7 photos and the median.
    #[default]
    Auto,
    /// `n` photos (odd) for every photo.
    Fixed(usize),
    /// The paper's rule for a known contamination rate `c` (the share of non-seafloor pixels): the smallest odd
    /// window whose median breaks down with probability at most `risk`. With [`Method::Abyss`] the window's `M` is
    /// its `(1 + c)/2` quantile and the near window the 5 % window of `c`.
    Contamination {
        /// The contamination rate `c`, in `[0, 0.5)`.
        rate: f64,
        /// The breakdown probability `P_half` accepted, in `(0, 1)`.
        risk: f64,
    },
}

/// The paper's window, `n = 7`: the window of every method but [`Method::Abyss`] when none is given, and of a
/// stretch where the survey finds nothing that calls for more.
pub const BASE_WINDOW: usize = 7;

/// The longest window `--window` and `--contamination` may give.
pub const MAX_WINDOW: usize = crate::limits::WINDOW;
/// The largest block size `K`.
pub const MAX_DOWNSAMPLE: usize = crate::limits::DOWNSAMPLE;
/// The largest degree of [`Method::Polynomial`].
pub const MAX_DEGREE: usize = crate::limits::DEGREE;

/// The method's parameters: what the [`Engine`](crate::method::engine::Engine) needs to know. `Params::default()`
/// is exactly what `abysslight correct` runs without options (`Options::default()` is made from it, and
/// [`Options::params`](crate::run::options::Options::params) gives it back); the settings that say `auto` are
/// resolved from the mission's photos in one place, [`Params::resolved`]; [`Params::validate`] checks them for the
/// engine, the command line and Python alike.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// How the lighting is estimated. Default: [`Method::Abyss`].
    pub method: Method,
    /// How each photo's window is chosen. Default: [`Window::Auto`] (per stretch of the mission, by the survey).
    pub window: Window,
    /// Block size `K` of the spatial median; 0 is `auto` ([`Params::auto_block`]: from the photos' size, taken from
    /// `S` or the mask when given, else from the first photo). Default: 0 (auto).
    pub downsample: usize,
    /// Seafloor colour `C`. Default: grey 0.4.
    pub seafloor_colour: SeafloorColour,
    /// Smallest `F` a pixel is divided by, for every method but [`Method::Abyss`] (which uses
    /// [`Steps::relative_floor`]). Default: 0.05.
    pub factor_floor: f32,
    /// Camera curve of the stored values; `None` is `auto`: the curve the files declare
    /// ([`Facts::transfer`]), linear where nothing is declared (photos in memory carry no file facts: give
    /// `Some(Transfer::Srgb)` for camera JPEGs). Default: `None` (auto).
    pub transfer: Option<Transfer>,
    /// Degree of the polynomial of [`Method::Polynomial`]. Default: 4.
    pub degree: usize,
    /// The steps [`Method::Abyss`] adds to the paper.
    pub steps: Steps,
}

/// The steps [`Method::Abyss`] adds to the paper, in the order they run on a photo's window (after the window's
/// quantile; docs/method.md says what each one measured). The other methods ignore them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Steps {
    /// Where the exposure jumps from photo to photo within the window, its photos levelled to one exposure (each
    /// by its gain against the window's `M`) before `M` is taken (`levelled_stack`): the median otherwise takes
    /// the middle-exposure photo's scene whole (ghosts). Default: true.
    pub level_exposures: bool,
    /// Fill the window's `M` where bright spots that move — laser dots, highlights — held more than half of the
    /// window at a block (`outliers`). Default: false.
    pub bright_spots: bool,
    /// Photos in the near window whose `M`'s smooth shape bends the window's
    /// (`near_shape`); `Some(0)`, or a length not shorter than `window`: off; `None` is
    /// `auto`: [`crate::method::window::near_window`]. Default: `None` (auto: 5 inside the default window).
    pub near_window: Option<usize>,
    /// Bend `F` to the ratios of the window's overlapping photos, registered by phase correlation
    /// (`method::overlap`): nodules, burrows and fauna that held the window's `M` cancel in them.
    /// Default: false.
    pub overlaps: bool,
    /// The scale of the water-column `S` for the survey photos; `None` estimates it per window
    /// (`backscatter_scale`). Default: `Some(1.0)` (`S` as measured: the estimate is
    /// biased low on red-starved channels).
    pub backscatter_scale: Option<f32>,
    /// One robust gain per photo and channel against its window's `M`. Default: true.
    pub photo_gain: bool,
    /// The floor of `F` as a share of the photo's lit level, with a smooth hand-over
    /// (`soft_floor`). Default: 0.001.
    pub relative_floor: f32,
    /// Blend dim regions towards their local level by their signal-to-noise ratio instead of amplifying noise
    /// (`noise`). Default: true.
    pub denoise: bool,
    /// With `denoise`: even out the blend's block levels across light levels
    /// (`level_by_light`), so dim regions are not left darker than lit ones. Default: true.
    pub level_by_light: bool,
    /// With the window chosen per stretch ([`Window::Auto`]): where red or green bright spots come back to the same
    /// blocks in the mission's first 41 photos more often than chance explains (the paths of laser dots), leave
    /// those blocks out of every window's `M`, as a mask does, so the dots are not taken into `F` and leave no
    /// stain. Default: true.
    pub laser_paths: bool,
}

impl Default for Steps {
    fn default() -> Self {
        Steps {
            level_exposures: true,
            bright_spots: false,
            near_window: None,
            overlaps: false,
            backscatter_scale: Some(1.0),
            photo_gain: true,
            relative_floor: 0.001,
            denoise: true,
            level_by_light: true,
            laser_paths: true,
        }
    }
}

impl Default for Params {
    fn default() -> Self {
        Params {
            method: Method::default(),
            window: Window::Auto,
            downsample: 0,
            seafloor_colour: SeafloorColour::default(),
            factor_floor: 0.05,
            transfer: None,
            degree: 4,
            steps: Steps::default(),
        }
    }
}

/// What the `auto` settings of [`Params`] are resolved from: facts about the mission's photos.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Facts {
    /// The photos' size (width, height), when known before the first photo.
    pub size: Option<(usize, usize)>,
    /// Static pixels are masked (`--mask`, `--mask-auto`).
    pub masked: bool,
    /// The curve the photos' files declare (`--transfer auto`: `assume`), when read.
    pub transfer: Option<Transfer>,
}

/// Why `auto` blocks are the size they are ([`Params::auto_block`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BlockRule {
    /// Given (`downsample` is not 0).
    Given,
    /// The paper's 8 for a method other than [`Method::Abyss`].
    Paper,
    /// The paper's 8 with a mask: overlays that change from frame to frame (counters, clocks) are partly missed by
    /// `--mask-auto`, and a block of 8 has enough seafloor beside them to outvote the missed pixels (with blocks of
    /// 4, masked text on a 128×96 test dive came out 210–236 instead of white: tests/integration/field.rs).
    Masked,
    /// [`auto_block`] of the photos' size.
    Size,
    /// Not known yet: the engine takes it from the first photo's size.
    Unknown,
}

/// The quantile of its samples the window takes as `M`: with [`Method::Abyss`] and a contamination rate `c`, the
/// `(1 + c)/2` quantile (abyssal contamination is dark — nodules, shadows — so that is the seafloor's own median);
/// otherwise the median.
pub fn window_quantile(method: Method, contamination: Option<f64>) -> f64 {
    match (method, contamination) {
        (Method::Abyss, Some(c)) => (1.0 + c) / 2.0,
        _ => 0.5,
    }
}

impl Params {
    /// Every `auto` setting resolved from `facts` — the one place where that happens, for the command line and the
    /// library alike: the blocks ([`Params::auto_block`]; left at 0 when the size is not known yet), the curve
    /// (what the files declare, else linear) and the near window (`Some(0)` when off).
    pub fn resolved(&self, facts: &Facts) -> Params {
        Params {
            downsample: self.auto_block(facts).0,
            transfer: Some(self.transfer.or(facts.transfer).unwrap_or(Transfer::Linear)),
            steps: Steps {
                near_window: Some(self.near_window().unwrap_or(0)),
                ..self.steps
            },
            ..*self
        }
    }

    /// The block size `K` and the rule that gave it: `downsample` when given; for `auto` the paper's 8 for the
    /// methods other than [`Method::Abyss`] and with a mask, else [`auto_block`] of the photos' size (0 while it is
    /// not known).
    pub fn auto_block(&self, facts: &Facts) -> (usize, BlockRule) {
        let eight = crate::method::factor::AUTO_MAX_BLOCK;
        match (self.downsample, facts.size) {
            (k, _) if k > 0 => (k, BlockRule::Given),
            _ if self.method != Method::Abyss => (eight, BlockRule::Paper),
            _ if facts.masked => (eight, BlockRule::Masked),
            (_, Some((w, h))) => (auto_block(w, h), BlockRule::Size),
            (_, None) => (0, BlockRule::Unknown),
        }
    }

    /// The near window in effect for [`Params::window_length`] (`None`: off): `steps.near_window`, or for `auto`
    /// [`crate::method::window::near_window`]; only with [`Method::Abyss`], and only when shorter than the window.
    pub fn near_window(&self) -> Option<usize> {
        if self.method != Method::Abyss {
            return None;
        }
        let n = self.window_length();
        match self.steps.near_window {
            None => crate::method::window::near_window(n, self.contamination()),
            Some(k) => (k > 0 && k < n).then_some(k),
        }
    }

    /// The quantile the window takes as `M` (`window_quantile`) where the survey does not choose it.
    pub fn window_quantile(&self) -> f32 {
        window_quantile(self.method, self.contamination()) as f32
    }

    /// Whether each photo's window is chosen per stretch of the mission by the survey ([`Window::Auto`] with
    /// [`Method::Abyss`]).
    pub fn window_is_auto(&self) -> bool {
        self.window == Window::Auto && self.method == Method::Abyss
    }

    /// The contamination rate given ([`Window::Contamination`]).
    pub fn contamination(&self) -> Option<f64> {
        match self.window {
            Window::Contamination { rate, .. } => Some(rate),
            _ => None,
        }
    }

    /// The window of every photo the survey does not choose: the window given, the paper's rule's window for a
    /// contamination rate, 7 for [`Window::Auto`] (the survey's starting point, and the window of the
    /// other methods). A contamination rate that no window serves ([`Params::validate`] refuses it) gives
    /// [`limits::WINDOW`](crate::limits::WINDOW).
    pub fn window_length(&self) -> usize {
        self.window_choice().map_or(MAX_WINDOW, |w| w.n)
    }

    /// [`Params::window_length`] with its breakdown probability at the contamination rate given (NaN without one).
    pub fn window_choice(&self) -> Result<WindowChoice, InvalidConfig> {
        match self.window {
            Window::Auto => Ok(WindowChoice {
                n: BASE_WINDOW,
                p_half: f64::NAN,
            }),
            Window::Fixed(n) => Ok(WindowChoice {
                n,
                p_half: f64::NAN,
            }),
            Window::Contamination { rate, risk } => choose_window(rate, risk),
        }
    }

    /// Check every value against its range, each error naming its option (the command's checks and the engine's
    /// are these).
    pub fn validate(&self) -> Result<(), InvalidConfig> {
        if let Window::Fixed(n) = self.window {
            if n == 0 || n.is_multiple_of(2) || n > MAX_WINDOW {
                return Err(InvalidConfig::Window(n));
            }
        }
        self.window_choice()?;
        if self.downsample > MAX_DOWNSAMPLE {
            return Err(InvalidConfig::Downsample(self.downsample));
        }
        if let Some(k) = self
            .steps
            .near_window
            .filter(|&k| k != 0 && (k.is_multiple_of(2) || k > MAX_WINDOW))
        {
            return Err(InvalidConfig::NearWindow(k));
        }
        if !(self.factor_floor > 0.0 && self.factor_floor <= 1.0) {
            return Err(InvalidConfig::FactorFloor(self.factor_floor));
        }
        if !(self.steps.relative_floor > 0.0 && self.steps.relative_floor < 1.0) {
            return Err(InvalidConfig::RelativeFloor(self.steps.relative_floor));
        }
        if let Some(k) = self.steps.backscatter_scale {
            if !(k > 0.0 && k <= 2.0) {
                return Err(InvalidConfig::BackscatterScale(k));
            }
        }
        if !(1..=MAX_DEGREE).contains(&self.degree) {
            return Err(InvalidConfig::Degree(self.degree));
        }
        Ok(())
    }

    /// The curve in effect: `transfer`, or linear where it is `auto` and not resolved ([`Params::resolved`]).
    pub fn curve(&self) -> Transfer {
        self.transfer.unwrap_or(Transfer::Linear)
    }
}
