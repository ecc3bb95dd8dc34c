//! [`Options`]: every setting of `abysslight correct`, shared by the library, the TOML config file and the CLI.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::limits;
pub(crate) use crate::method::baseline::Method;
pub(crate) use crate::method::params::SeafloorColour;
use crate::method::params::{InvalidConfig, Params, Steps, Window};
pub(crate) use crate::method::transfer::Transfer;
use crate::method::window::{p_half, WindowChoice};

/// One of `count` contiguous chunks of a survey (`--shard K/N`, `K` from 1 to `N`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Shard {
    /// 1-based.
    pub index: usize,
    /// Number of shards the survey is cut into (`N`, at least 1).
    pub count: usize,
}

impl Shard {
    /// The photos `[start, end)` of a survey of `total` photos that this shard writes.
    pub fn range(&self, total: usize) -> std::ops::Range<usize> {
        let bound = |k: usize| k * total / self.count;
        bound(self.index - 1)..bound(self.index)
    }
}

impl FromStr for Shard {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || format!("invalid shard {s:?}: expected K/N with 1 <= K <= N, e.g. 3/10");
        let (k, n) = s.trim().split_once('/').ok_or_else(bad)?;
        let (index, count): (usize, usize) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if index == 0 || index > count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

impl TryFrom<String> for Shard {
    type Error = String;
    fn try_from(s: String) -> Result<Self, Self::Error> {
        s.parse()
    }
}

impl From<Shard> for String {
    fn from(s: Shard) -> String {
        format!("{}/{}", s.index, s.count)
    }
}

/// Settings of a correction run. Field docs give the default and the symbol in Köser et al.
///
/// The same struct is read from a `--config` TOML file (keys in kebab-case, e.g. `seafloor-colour = "#8a7560"`)
/// and filled from command-line flags, which override the file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields, rename_all = "kebab-case")]
pub struct Options {
    /// Folder of water-column frames taken on the way down (for `S`). Default: none, `S = 0`.
    pub water_column: Option<PathBuf>,
    /// A scatter image saved by an earlier run (`_abysslight/scatter.png`), used instead of `water_column`.
    pub scatter: Option<PathBuf>,
    /// Folder of survey photos, searched recursively. Required.
    pub survey: Option<PathBuf>,
    /// Output folder; mirrors the survey tree. Required.
    pub out: Option<PathBuf>,
    /// Temporal window `n` (odd). Default: `None` (auto): with neither this nor `contamination`, `method = abyss`
    /// chooses it per stretch of the mission from a survey of its photos; 7 otherwise. In a TOML file a number or
    /// `"auto"`.
    #[serde(default, deserialize_with = "number_or_auto")]
    pub window: Option<usize>,
    /// Contamination rate `c`: expected share of non-seafloor pixels. Sets `window` to the smallest odd `n` with
    /// `P_half ≤ risk`. Default: `None` (auto: measured per stretch of the mission, as without `window`). In a TOML
    /// file a number or `"auto"`.
    #[serde(default, deserialize_with = "number_or_auto")]
    pub contamination: Option<f64>,
    /// Accepted breakdown probability `P_half` when choosing `n` from `contamination`. Default: 0.01.
    pub risk: f64,
    /// Block size `K` of the spatial median downsampling; `None` (`auto`) takes it, for `method = abyss`, from the
    /// mission's photo size ([`crate::method::factor::auto_block`]: about 160 blocks across the longer side, from
    /// 4 to 8 pixels, so the paper's 8 from 1280 pixels up), and the paper's 8 for the other methods and with a
    /// mask (`mask`, `mask_auto`). Default: `None` (auto). In a TOML file a number or `"auto"`.
    #[serde(default, deserialize_with = "number_or_auto")]
    pub downsample: Option<usize>,
    /// `method = abyss`: photos in the near window, whose `M`'s smooth shape bends the window's so `F` follows the
    /// lights as the vehicle's altitude and roll change (`near_shape`); 0 turns it off, and
    /// a near window not shorter than the window is not used. `None` (`auto`):
    /// [`crate::method::window::near_window`] (the 5 % window of `contamination`, at least 5; 5 without one).
    /// Default: `None` (auto). In a TOML file a number or `"auto"`.
    #[serde(default, deserialize_with = "number_or_auto")]
    pub near_window: Option<usize>,
    /// Seafloor colour `C`. Default: grey 0.4.
    #[serde(alias = "seafloor-color")]
    pub seafloor_colour: SeafloorColour,
    /// Smallest value of `F` a pixel is divided by, so that dark corners do not explode (a gain of at most
    /// `1/factor_floor` relative to a normally lit pixel), for every method but `abyss` (which uses
    /// `relative_floor`). Default: 0.05.
    pub factor_floor: f32,
    /// Write `S` to `<out>/_abysslight/scatter.png` (16-bit). Default: false.
    pub save_scatter: bool,
    /// Write each photo's `F·C = M − S` to `<out>/_abysslight/factors/` (16-bit, one pixel per block). Default: false.
    pub save_factors: bool,
    /// JPEG output quality, 1–100. Default (`None`): the quality of a JPEG input, estimated from its quantisation
    /// tables; 95 for other inputs.
    pub jpeg_quality: Option<u8>,
    /// JPEG output chroma subsampling. Default (`None`): that of a JPEG input; 4:4:4 for other inputs.
    pub jpeg_subsampling: Option<crate::io::Subsampling>,
    /// PNG output compression: `fast`, `default` or `best` (lossless either way; see docs/performance.md).
    /// Default: fast.
    pub png_compression: crate::io::PngCompression,
    /// Worker threads. Default: all cores.
    pub threads: Option<usize>,
    /// Memory the scatter estimate may hold at once, in MiB; more water-column frames than fit are processed in
    /// row bands (each frame decoded once per band). Default: 2048.
    pub scatter_memory_mib: usize,
    /// Skip photos whose output already exists (complete: outputs are only ever renamed into place when
    /// complete). Their neighbours are still read for the windows, so results equal an uninterrupted run.
    /// Default: false.
    pub resume: bool,
    /// Exit with a status of its own (3 in the command; an exception in Python) when any photo is flagged as
    /// likely wrong, after the run has written everything. The library's run is the same either way: callers read
    /// the flags from the report. Default: false.
    #[serde(default)]
    pub strict: bool,
    /// Write only chunk `K` of `N` contiguous chunks of the survey (reading the neighbours its windows need).
    /// The union of all shards' outputs equals a single run. Default: none (the whole survey).
    pub shard: Option<Shard>,
    /// How stored values relate to light: `srgb`, `linear` or `gamma:G`; estimation and correction run in linear
    /// light. `None` (`auto`) takes the curve the first survey photo's file declares (PNG `cICP`/`sRGB`/`gAMA`, ICC
    /// profile, EXIF `ColorSpace`; a JPEG without any is sRGB, anything else linear: `transfer`); the
    /// run says what it assumed and why, and records the curve in its report. Default: `None` (auto). In a TOML
    /// file a curve or `"auto"`.
    #[serde(with = "curve_or_auto")]
    pub transfer: Option<Transfer>,
    /// Mask image, the size of the photos: white pixels (overlays, laser dots, vehicle parts) are left out of every
    /// median; `F` beneath them is interpolated from the seafloor around them and they are corrected with it.
    /// Default: none.
    pub mask: Option<PathBuf>,
    /// Find pixels that stay the same throughout the mission (overlays, lasers) and treat them as masked; the mask
    /// found is written to `_abysslight/mask-auto.png`. Default: false.
    pub mask_auto: bool,
    /// A navigation log (CSV) of each photo's altitude above the seafloor, matched by file name or by the photo's
    /// EXIF time (`io::navigation`): where the altitude swings along the track, each photo's window is chosen among the
    /// photos around it lit from the nearest heights (`method::altitude`). `method = abyss` only. Default: none.
    pub navigation: Option<PathBuf>,
    /// The navigation log's columns, where their names are unusual: `file`, `time` and `altitude` as the log's
    /// header names them (`--navigation-columns time=Date Time,altitude=dvl_alt`; in a config file the same text
    /// or a table `navigation-columns = { time = "Date Time", altitude = "dvl_alt" }`). A column not named is found
    /// by its name (`io::navigation`). Default: all found by name.
    #[serde(skip_serializing_if = "crate::io::navigation::Columns::is_empty")]
    pub navigation_columns: crate::io::navigation::Columns,
    /// Seconds added to the times of a navigation log by time to put them on the camera's clock (the camera's
    /// clock minus the log's: `-7200` for a log 2 h ahead of the camera). Default: 0.
    #[serde(skip_serializing_if = "is_zero")]
    pub navigation_clock_offset: f64,
    /// The SHA-256 of the navigation log's content, recorded by the run (report.json, the lock) with the log's
    /// path resolved: runs that read another log, or the same file edited, are not mixed (shards, `--resume`).
    /// Not an option to give: a run sets it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub navigation_sha256: Option<String>,
    /// The SHA-256 of the mask file's content, recorded by the run as [`Options::navigation_sha256`] is.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mask_sha256: Option<String>,
    /// How the lighting is estimated: `abyss` (the paper's method with the steps of docs/method.md, one file
    /// each under `method/steps/`), `paper` (Köser et al. as published), or the baselines `mean` (mission mean
    /// image, Pizarro & Singh) and `polynomial` (per-photo robust polynomial fit, Singh et al. 2007). Default: abyss.
    pub method: Method,
    /// Degree of the 2-D polynomial of `method = polynomial`. Default: 4.
    pub degree: usize,
    /// Watch the survey folder during a dive: correct photos as they arrive (each once the `n/2` photos after it
    /// are complete) until stopped (SIGINT/SIGTERM in the CLI) or `idle_timeout`. See `watch`.
    /// Default: false.
    pub watch: bool,
    /// With `watch`: stop after this many seconds without a new or changed file. Default: none (until stopped).
    pub idle_timeout: Option<f64>,
    /// With `watch`: milliseconds between two scans of the survey folder. Default: 500.
    pub poll_interval: u64,
    /// Correct only the first `limit` photos of the survey (or of the shard), with the same windows as a whole
    /// run (the photos after them are read for the windows): a quick look at a new rig. Default: none (all).
    pub limit: Option<usize>,
    /// Where to write the run report (JSON). Default: `<out>/_abysslight/report.json`; none when `out` is `-`.
    pub report: Option<PathBuf>,
    /// `method = abyss`: the floor of `F` as a share of the photo's lit level (95th percentile of `F` per channel),
    /// with a smooth hand-over (`soft_floor`). Default: 0.001 (measured on the dive matrix,
    /// docs/evaluation.md).
    pub relative_floor: f32,
    /// `method = abyss`: where the exposure jumps from photo to photo within the window, its photos levelled to one
    /// exposure (each by its gain against the window's `M`) before `M` is taken (`levelled_stack`): the median
    /// otherwise takes the middle-exposure photo's scene whole into `F` (ghosts). Default: true.
    pub level_exposures: bool,
    /// `method = abyss`: one robust gain per photo and channel against its window's `M`. Default: true.
    pub photo_gain: bool,
    /// `method = abyss`: scale of the water-column `S` for the survey photos (the water column is deeper than the
    /// camera's altitude, so its backscatter can be stronger than the survey's); `None` (`auto`) estimates it per
    /// window from how the seafloor's contrast follows the light (`backscatter_scale`).
    /// Default: 1, `S` as measured (the estimate is biased low on red-starved channels, which tints dark objects
    /// red; docs/evaluation.md).
    pub backscatter_scale: Option<f32>,
    /// `method = abyss`: blend dim regions towards their local level by their signal-to-noise ratio (measured on
    /// each photo) instead of amplifying noise (`noise`). Default: true.
    pub denoise: bool,
    /// `method = abyss` with `denoise`: even out the blend's block levels across light levels, so that dim regions
    /// come out as bright as lit ones (`level_by_light`). Default: true.
    pub level_by_light: bool,
    /// `method = abyss`: fill the window's `M` where bright spots that move — laser dots, specular highlights —
    /// held more than half of the window at a block (`outliers`). Default: false (it keeps the
    /// dots at their full brightness, which raises the overlap difference: docs/evaluation.md).
    #[serde(default)]
    pub bright_spots: bool,
    /// `method = abyss`: bend `F` to the ratios of the window's overlapping photos, where nodules, burrows and
    /// fauna cancel (`method::overlap`). Default: false (docs/overlaps.md).
    #[serde(default)]
    pub overlaps: bool,
    /// `method = abyss` with the window chosen per stretch (no `window`, no `contamination`): where red or green
    /// bright spots come back to the same blocks in the mission's first photos (the paths of laser dots), leave those
    /// blocks out of `F` as `mask_auto` does, so the dots keep their colour and leave no stain
    /// (`laser_paths`). Not with `mask_auto`, which finds the paths itself. Default: true.
    pub laser_paths: bool,
}

/// A TOML value that is a number (a whole one for a whole-number option), or the string `"auto"` (`None`); in
/// JSON (a report's options) also `null` (`None`).
fn number_or_auto<'de, D, T>(d: D) -> Result<Option<T>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Value<T> {
        Number(T),
        Text(String),
    }
    // `null` (a report's options, JSON) is `None` as well.
    match Option::<Value<T>>::deserialize(d) {
        Ok(None) => Ok(None),
        Ok(Some(Value::Number(n))) => Ok(Some(n)),
        Ok(Some(Value::Text(t))) if t.trim().eq_ignore_ascii_case("auto") => Ok(None),
        Ok(Some(Value::Text(t))) => Err(serde::de::Error::custom(format!(
            "expected a number or \"auto\", got {t:?}"
        ))),
        Err(_) => Err(serde::de::Error::custom(format!(
            "expected {} or \"auto\"",
            match std::any::type_name::<T>() {
                "f32" | "f64" => "a number",
                _ => "a whole number",
            }
        ))),
    }
}

/// `transfer` in a TOML file or a report: a curve, or `"auto"` (`None`).
mod curve_or_auto {
    use super::Transfer;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(t: &Option<Transfer>, s: S) -> Result<S::Ok, S::Error> {
        match t {
            Some(t) => s.serialize_str(&t.to_string()),
            None => s.serialize_str("auto"),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Transfer>, D::Error> {
        let t = String::deserialize(d)?;
        if t.trim().eq_ignore_ascii_case("auto") {
            return Ok(None);
        }
        t.parse().map(Some).map_err(serde::de::Error::custom)
    }
}

impl Default for Options {
    /// The method's options from [`Params::default`] (what a run gives back with [`Options::params`]), the run's
    /// own defaults beside them.
    fn default() -> Self {
        let p = Params::default();
        let (window, contamination, risk) = match p.window {
            Window::Auto => (None, None, DEFAULT_RISK),
            Window::Fixed(n) => (Some(n), None, DEFAULT_RISK),
            Window::Contamination { rate, risk } => (None, Some(rate), risk),
        };
        Options {
            water_column: None,
            scatter: None,
            survey: None,
            out: None,
            window,
            contamination,
            risk,
            downsample: (p.downsample > 0).then_some(p.downsample),
            near_window: p.steps.near_window,
            seafloor_colour: p.seafloor_colour,
            factor_floor: p.factor_floor,
            save_scatter: false,
            save_factors: false,
            jpeg_quality: None,
            jpeg_subsampling: None,
            png_compression: crate::io::PngCompression::Fast,
            threads: None,
            scatter_memory_mib: 2048,
            resume: false,
            strict: false,
            shard: None,
            transfer: p.transfer,
            mask: None,
            mask_auto: false,
            navigation: None,
            navigation_columns: Default::default(),
            navigation_clock_offset: 0.0,
            navigation_sha256: None,
            mask_sha256: None,
            method: p.method,
            degree: p.degree,
            watch: false,
            idle_timeout: None,
            poll_interval: 500,
            limit: None,
            report: None,
            relative_floor: p.steps.relative_floor,
            level_exposures: p.steps.level_exposures,
            photo_gain: p.steps.photo_gain,
            backscatter_scale: p.steps.backscatter_scale,
            denoise: p.steps.denoise,
            level_by_light: p.steps.level_by_light,
            bright_spots: p.steps.bright_spots,
            overlaps: p.steps.overlaps,
            laser_paths: p.steps.laser_paths,
        }
    }
}

/// The breakdown probability `P_half` accepted when `--contamination` chooses the window (the paper's 1 %).
pub(crate) const DEFAULT_RISK: f64 = 0.01;

/// The largest config file read (a config file is a page of settings).
pub(crate) const CONFIG_MAX_BYTES: u64 = 1 << 20;

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// The switches the command line turns off with `--no-…`, by their config-file keys.
const SWITCHES: [&str; 5] = [
    "level-exposures",
    "photo-gain",
    "denoise",
    "level-by-light",
    "laser-paths",
];

/// Turn a config file's `no-denoise = true` (and the other `--no-…` switches) into `denoise = false`; whether any
/// was there. An error where the value is not true or false, or where `denoise` says otherwise.
fn negated_switches(table: &mut toml::Table) -> Result<bool, String> {
    let mut any = false;
    for key in SWITCHES {
        let no = format!("no-{key}");
        let Some(v) = table.remove(&no) else {
            continue;
        };
        let off = v
            .as_bool()
            .ok_or_else(|| format!("{no} must be true or false, got {v}"))?;
        if let Some(on) = table.get(key) {
            if on.as_bool() != Some(!off) {
                return Err(format!(
                    "{no} = {off} and {key} = {on} contradict each other: give one"
                ));
            }
        }
        table.insert(key.to_string(), toml::Value::Boolean(!off));
        any = true;
    }
    Ok(any)
}

impl Options {
    /// Read options from a TOML file. Relative paths in it are taken relative to the file's folder.
    pub fn from_toml_file(path: &Path) -> Result<Options, Error> {
        let text = crate::io::whole::read_text(path, CONFIG_MAX_BYTES, "config file")?;
        let config = |reason: String| Error::Config {
            path: path.to_owned(),
            reason,
        };
        let mut table: toml::Table = toml::from_str(&text).map_err(|e| config(e.to_string()))?;
        // The switches as the command line spells them (`no-denoise = true`), as well as `denoise = false`.
        let mut opts: Options = if negated_switches(&mut table).map_err(config)? {
            table
                .try_into()
                .map_err(|e: toml::de::Error| config(e.to_string()))?
        } else {
            // Straight from the text, so that an error names its line.
            toml::from_str(&text).map_err(|e| config(e.to_string()))?
        };
        let base = path.parent().unwrap_or(Path::new("."));
        for p in [
            &mut opts.water_column,
            &mut opts.scatter,
            &mut opts.survey,
            &mut opts.out,
            &mut opts.mask,
            &mut opts.report,
            &mut opts.navigation,
        ]
        .into_iter()
        .flatten()
        {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        }
        Ok(opts)
    }

    /// The window of every photo the survey does not choose ([`Params::window_choice`]), with its breakdown
    /// probability at the contamination rate given or, with `--window` and `--contamination` (refused by
    /// [`Options::params`]), without one.
    pub fn window_choice(&self) -> Result<WindowChoice, Error> {
        let w = self.params()?.window_choice()?;
        Ok(match self.contamination {
            Some(c) => WindowChoice {
                n: w.n,
                p_half: p_half(w.n, c),
            },
            None => w,
        })
    }

    /// The longest window a photo of the run can have: with `--window auto` (neither `--window` nor
    /// `--contamination`, `--method abyss`) the longest the survey chooses, 31 photos; else the window.
    pub fn longest_window(&self) -> Result<usize, Error> {
        let params = self.params()?;
        let n = if params.window_is_auto() {
            crate::method::stretch::MAX_AUTO_WINDOW
        } else {
            params.window_length()
        };
        // With a navigation log a window is chosen among the photos around the photo (`method::altitude`).
        Ok(crate::method::altitude::waits_for(
            n,
            self.navigation.is_some(),
        ))
    }

    /// Check values that do not depend on the file system.
    pub fn validate(&self) -> Result<(), Error> {
        self.check_ranges()?;
        let usage = |m: String| Err(Error::Usage(m));
        if self.limit == Some(0) {
            return usage("--limit must be at least 1 photo".into());
        }
        let stdin = self.survey.as_deref() == Some(Path::new("-"));
        let stdout = self.out.as_deref() == Some(Path::new("-"));
        if self.watch && stdin {
            return usage(
                "--watch watches a folder; it cannot be used with --survey - (frames on stdin)"
                    .into(),
            );
        }
        if self.watch || stdin {
            let what = if self.watch { "--watch" } else { "--survey -" };
            for (on, flag) in [
                (self.shard.is_some(), "--shard"),
                (self.resume, "--resume"),
                (
                    self.mask_auto,
                    "--mask-auto (it needs the whole mission up front; give --mask instead)",
                ),
            ] {
                if on {
                    return usage(format!("{flag} cannot be used with {what}"));
                }
            }
        }
        if !self.watch && self.idle_timeout.is_some() {
            return usage("--idle-timeout needs --watch".into());
        }
        if stdout && (self.save_scatter || self.save_factors || self.mask_auto) {
            return usage(
                "--save-scatter, --save-factors and --mask-auto write into the output folder; with --out - there \
                 is none"
                    .into(),
            );
        }
        if self.scatter.is_some() && self.water_column.is_some() {
            return usage("give either --water-column or --scatter, not both".into());
        }
        // A year either way: a clock set to another day, not a photo's whole mission.
        let offset = self.navigation_clock_offset;
        if offset.is_nan() || offset.abs() > 366.0 * 86_400.0 {
            return usage(format!(
                "--navigation-clock-offset {}: seconds, at most a year either way",
                self.navigation_clock_offset
            ));
        }
        if self.navigation.is_some() {
            if stdin {
                return usage(
                    "--navigation matches photos by file name or EXIF time; frames on stdin (--survey -) have \
                     neither"
                        .into(),
                );
            }
            if self.method != Method::Abyss {
                return usage(format!(
                    "--navigation chooses windows by altitude, a step of --method abyss (not {})",
                    self.method
                ));
            }
        }
        Ok(())
    }
}

impl Options {
    /// The encoder settings of a run: JPEG quality and subsampling follow each JPEG input unless set.
    pub fn encode_settings(&self) -> crate::io::EncodeSettings {
        let d = crate::io::EncodeSettings::default();
        crate::io::EncodeSettings {
            jpeg_quality: self.jpeg_quality.unwrap_or(d.jpeg_quality),
            png_compression: self.png_compression,
            jpeg_subsampling: self.jpeg_subsampling.unwrap_or(d.jpeg_subsampling),
            jpeg_like_input: crate::io::LikeInput {
                quality: self.jpeg_quality.is_none(),
                subsampling: self.jpeg_subsampling.is_none(),
            },
        }
    }
}

impl Options {
    /// The block size `K`: `downsample`, or the paper's 8 where `auto` has not been resolved (a run resolves it
    /// from the photos' size before it starts: `Plan::downsample`).
    pub fn block(&self) -> usize {
        self.downsample
            .unwrap_or(crate::method::factor::AUTO_MAX_BLOCK)
    }

    /// The quantile the window takes over its photos (`window_quantile`).
    pub fn window_quantile(&self) -> f64 {
        crate::method::params::window_quantile(self.method, self.contamination)
    }

    /// The method's parameters of these options: the one mapping from a run's settings to the
    /// [`Engine`](crate::method::engine::Engine)'s, with the `auto` settings still `auto` (a run resolves them
    /// with [`Params::resolved`]). Every field of `Options` is named here, so a new one cannot be forgotten: it is
    /// either the method's or the run's.
    pub fn params(&self) -> Result<Params, Error> {
        let Options {
            // The method's.
            window: _,
            contamination,
            risk: _,
            downsample,
            near_window,
            seafloor_colour,
            factor_floor,
            transfer,
            method,
            degree,
            relative_floor,
            level_exposures,
            photo_gain,
            backscatter_scale,
            denoise,
            level_by_light,
            bright_spots,
            overlaps,
            laser_paths,
            // The run's: where photos come from and go to, and how the run goes.
            water_column: _,
            scatter: _,
            survey: _,
            out: _,
            save_scatter: _,
            save_factors: _,
            jpeg_quality: _,
            jpeg_subsampling: _,
            png_compression: _,
            threads: _,
            scatter_memory_mib: _,
            resume: _,
            strict: _,
            shard: _,
            mask: _,
            mask_auto: _,
            navigation: _,
            navigation_columns: _,
            navigation_clock_offset: _,
            navigation_sha256: _,
            mask_sha256: _,
            watch: _,
            idle_timeout: _,
            poll_interval: _,
            limit: _,
            report: _,
        } = *self;
        let window = match (self.window, contamination) {
            (Some(_), Some(_)) => {
                return Err(Error::Usage(
                    "give either --window or --contamination, not both".into(),
                ))
            }
            (Some(n), None) => Window::Fixed(n),
            (None, Some(rate)) => Window::Contamination {
                rate,
                risk: self.risk,
            },
            (None, None) => Window::Auto,
        };
        Ok(Params {
            method,
            window,
            downsample: downsample.unwrap_or(0),
            seafloor_colour,
            factor_floor,
            transfer,
            degree,
            steps: Steps {
                bright_spots,
                near_window,
                backscatter_scale,
                level_exposures,
                photo_gain,
                relative_floor,
                denoise,
                level_by_light,
                overlaps,
                laser_paths,
            },
        })
    }

    /// These options with the `auto` settings of `params` (resolved by [`Params::resolved`]) written in, so that the
    /// report and the lock record what ran.
    pub fn with_resolved(&self, params: &Params) -> Options {
        Options {
            transfer: params.transfer,
            downsample: (params.downsample > 0).then_some(params.downsample),
            near_window: params.steps.near_window,
            ..self.clone()
        }
    }

    /// Range checks of every numeric option, each error naming its flag. Part of [`Options::validate`]. The checks
    /// run in a fixed order and the first failure is reported.
    pub fn check_ranges(&self) -> Result<(), Error> {
        self.check_estimate_ranges()?;
        self.check_run_ranges()
    }

    /// Range checks of the method's options: [`Params::validate`], and `--risk` (which only counts with
    /// `--contamination`) on its own.
    fn check_estimate_ranges(&self) -> Result<(), Error> {
        if !(self.risk > 0.0 && self.risk < 1.0) {
            return Err(InvalidConfig::Risk(self.risk).into());
        }
        Ok(self.params()?.validate()?)
    }

    /// Range checks of the remaining numeric options: JPEG quality, threads, polynomial degree, watch timing,
    /// scatter memory, shard, seafloor colour.
    fn check_run_ranges(&self) -> Result<(), Error> {
        let usage = |m: String| Err(Error::Usage(m));
        if let Some(q) = self.jpeg_quality.filter(|q| !(1..=100).contains(q)) {
            return usage(format!("--jpeg-quality must be 1 to 100, got {q}"));
        }
        if let Some(t) = self.threads {
            if !(1..=limits::THREADS).contains(&t) {
                return usage(format!(
                    "--threads must be 1 to {}, got {t}",
                    limits::THREADS
                ));
            }
        }
        if let Some(t) = self.idle_timeout {
            if !(0.0..=limits::IDLE_TIMEOUT_S).contains(&t) {
                return usage(format!(
                    "--idle-timeout must be 0 to {} seconds, got {t}",
                    limits::IDLE_TIMEOUT_S
                ));
            }
        }
        if !(1..=limits::POLL_INTERVAL_MS).contains(&self.poll_interval) {
            return usage(format!(
                "--poll-interval must be 1 to {} ms, got {}",
                limits::POLL_INTERVAL_MS,
                self.poll_interval
            ));
        }
        if !(1..=limits::SCATTER_MEMORY_MIB).contains(&self.scatter_memory_mib) {
            return usage(format!(
                "scatter-memory-mib must be 1 to {}, got {}",
                limits::SCATTER_MEMORY_MIB,
                self.scatter_memory_mib
            ));
        }
        if let Some(s) = self.shard {
            if s.count > limits::SHARDS || s.index == 0 || s.index > s.count {
                return usage(format!(
                    "--shard K/N needs 1 <= K <= N <= {}, got {}/{}",
                    limits::SHARDS,
                    s.index,
                    s.count
                ));
            }
        }
        let c = self.seafloor_colour.0;
        if c.iter().any(|&v| !(v > 0.0 && v <= 1.0)) {
            return usage(format!(
                "--seafloor-colour components must be above 0 and at most 1, got {c:?}"
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A config file takes the switches as the command line spells them (`no-denoise = true`); a value that is
    /// not a boolean, or that contradicts the positive key, is an error naming both.
    #[test]
    fn config_files_take_the_no_switches() {
        let d = tempfile::tempdir().unwrap();
        let file = d.path().join("dive.toml");
        let read = |text: &str| {
            std::fs::write(&file, text).unwrap();
            Options::from_toml_file(&file)
        };
        let o =
            read("no-denoise = true\nno-photo-gain = false\nno-level-by-light = true\n").unwrap();
        assert!(!o.denoise && o.photo_gain && !o.level_by_light && o.level_exposures);
        let o = read("no-level-exposures = true\nlevel-exposures = false\n").unwrap();
        assert!(!o.level_exposures);
        let e = read("no-denoise = true\ndenoise = true\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no-denoise") && e.contains("denoise = true"),
            "{e}"
        );
        let e = read("no-denoise = 1\n").unwrap_err().to_string();
        assert!(e.contains("no-denoise must be true or false"), "{e}");
        // Other errors still name their line.
        let e = read("window = 7\nbogus = 1\n").unwrap_err().to_string();
        assert!(e.contains("bogus") && e.contains('2'), "{e}");
    }

    #[test]
    fn colour_forms() {
        let c: SeafloorColour = "0.42,0.36,0.28".parse().unwrap();
        assert_eq!(c.0, [0.42, 0.36, 0.28]);
        let h: SeafloorColour = "#8a7560".parse().unwrap();
        assert!((h.0[0] - 138.0 / 255.0).abs() < 1e-6);
        assert!((h.0[1] - 117.0 / 255.0).abs() < 1e-6);
        assert!((h.0[2] - 96.0 / 255.0).abs() < 1e-6);
        assert_eq!(
            "grey".parse::<SeafloorColour>().unwrap().0,
            [crate::method::params::DEFAULT_GREY; 3]
        );
        assert_eq!("gray:0.5".parse::<SeafloorColour>().unwrap().0, [0.5; 3]);
        let b: SeafloorColour = "138,117,96".parse().unwrap();
        assert_eq!(b, h);
        for bad in ["", "red", "#12345", "0,0,0", "1.5,0.2", "#gg0000", "-0.1"] {
            assert!(bad.parse::<SeafloorColour>().is_err(), "{bad:?}");
        }
    }

    #[test]
    fn toml_round_trip_and_relative_paths() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = dir.path().join("mission.toml");
        std::fs::write(
            &cfg,
            "survey = \"photos\"\nout = \"/abs/out\"\nwindow = 9\nseafloor-colour = \"#8a7560\"\n",
        )
        .unwrap();
        let o = Options::from_toml_file(&cfg).unwrap();
        assert_eq!(o.survey.unwrap(), dir.path().join("photos"));
        assert_eq!(o.out.unwrap(), PathBuf::from("/abs/out"));
        assert_eq!(o.window, Some(9));
        assert_eq!(o.downsample, None, "unset keys keep their defaults (auto)");
        for (text, want) in [("4", Some(4)), ("\"auto\"", None), ("\"Auto\"", None)] {
            std::fs::write(&cfg, format!("downsample = {text}\n")).unwrap();
            assert_eq!(
                Options::from_toml_file(&cfg).unwrap().downsample,
                want,
                "{text}"
            );
        }
        for (text, window, contamination) in [
            ("window = \"auto\"", None, None),
            ("window = 15", Some(15), None),
            ("contamination = \"auto\"", None, None),
            ("contamination = 0.3", None, Some(0.3)),
        ] {
            std::fs::write(&cfg, format!("{text}\n")).unwrap();
            let o = Options::from_toml_file(&cfg).unwrap();
            assert_eq!(
                (o.window, o.contamination),
                (window, contamination),
                "{text}"
            );
        }
        for bad in ["window = 7.5", "window = -3", "contamination = \"high\""] {
            std::fs::write(&cfg, format!("{bad}\n")).unwrap();
            let err = Options::from_toml_file(&cfg).unwrap_err().to_string();
            assert!(err.contains("auto"), "{bad}: {err}");
        }
        std::fs::write(&cfg, "downsample = \"big\"\n").unwrap();
        let err = Options::from_toml_file(&cfg).unwrap_err().to_string();
        assert!(err.contains("auto") && err.contains("big"), "{err}");
        std::fs::write(&cfg, "windw = 9\n").unwrap();
        let err = Options::from_toml_file(&cfg).unwrap_err().to_string();
        assert!(
            err.contains("mission.toml") && err.contains("windw"),
            "{err}"
        );
    }

    #[test]
    fn options_read_back_from_a_report_s_json() {
        // A report keeps the options as JSON, where an option left to auto is `null`.
        for (window, contamination) in [(None, None), (Some(9), None), (None, Some(0.3))] {
            let o = Options {
                window,
                contamination,
                ..Options::default()
            };
            let json = serde_json::to_string(&o).unwrap();
            let back: Options = serde_json::from_str(&json).unwrap();
            assert_eq!(
                (back.window, back.contamination),
                (window, contamination),
                "{json}"
            );
            assert_eq!(
                (back.downsample, back.near_window),
                (o.downsample, o.near_window)
            );
        }
    }

    #[test]
    fn shards_cover_the_survey_exactly_once() {
        assert_eq!(
            "3/10".parse::<Shard>().unwrap(),
            Shard {
                index: 3,
                count: 10
            }
        );
        for bad in ["0/3", "4/3", "3", "a/b", "1/0"] {
            assert!(bad.parse::<Shard>().is_err(), "{bad}");
        }
        for total in [0usize, 1, 5, 17, 100] {
            for count in 1..=7 {
                let mut next = 0;
                for index in 1..=count {
                    let r = Shard { index, count }.range(total);
                    assert_eq!(r.start, next);
                    assert!(r.len() <= total.div_ceil(count));
                    next = r.end;
                }
                assert_eq!(next, total);
            }
        }
    }

    #[test]
    fn validation() {
        let ok = Options::default();
        assert!(ok.validate().is_ok());
        assert_eq!(
            ok.window_choice().unwrap().n,
            crate::method::params::BASE_WINDOW
        );
        let even = Options {
            window: Some(6),
            ..Options::default()
        };
        assert!(even.validate().is_err());
        let both = Options {
            window: Some(7),
            contamination: Some(0.2),
            ..Options::default()
        };
        assert!(both.validate().is_err());
        let from_c = Options {
            contamination: Some(0.2),
            risk: 0.05,
            ..Options::default()
        };
        let w = from_c.window_choice().unwrap();
        assert_eq!(w.n, 7);
        assert!((w.p_half - 0.033344).abs() < 1e-9);
    }
}
