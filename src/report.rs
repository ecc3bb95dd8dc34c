//! The run report (`_abysslight/report.json`) and the [`Progress`] hooks a front end uses to show a run.

pub use crate::method::monitor::{Flag, FlagNote, Health, Summary};
pub use crate::method::window::WindowChoice;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::method::members::{null_is_nan, nulls_are_nan, Members};
use crate::method::raster::Layout;
use crate::options::Options;

/// Receives what happens during a run. The library prints nothing itself; the CLI draws a progress bar on a
/// terminal and plain log lines otherwise.
pub trait Progress: Sync {
    /// Something the user should know that does not stop the run.
    fn warn(&self, message: &str);
    /// A stage of the run starts (e.g. "estimating scatter from 80 water-column frames").
    fn stage(&self, message: &str);
    /// A file failed; the run goes on without it.
    fn file_error(&self, error: &Error);
    /// The survey pass starts, over `total` photos.
    fn start(&self, total: usize);
    /// A photo was corrected and written (or failed: then `file_error` was called too).
    fn photo_done(&self, input: &Path, ok: bool);
    /// The survey pass ended.
    fn finish(&self);
    /// Asked before each survey photo enters the engine: `true` stops the run there with an error (the photos
    /// written so far are complete; `resume` finishes the run). The Python binding's Ctrl-C. Default: never.
    fn cancelled(&self) -> bool {
        false
    }
}

/// A [`Progress`] that ignores everything.
pub struct Silent;

impl Progress for Silent {
    fn warn(&self, _: &str) {}
    fn stage(&self, _: &str) {}
    fn file_error(&self, _: &Error) {}
    fn start(&self, _: usize) {}
    fn photo_done(&self, _: &Path, _: bool) {}
    fn finish(&self) {}
}

/// One file that could not be used.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct FileError {
    /// The file.
    pub path: PathBuf,
    /// `decode`, `mismatch`, `io`, `encode`, ...
    pub kind: String,
    /// The whole message, naming the file and the reason.
    pub message: String,
}

impl FileError {
    /// The report entry of `e` about `path`.
    pub fn from_error(path: &Path, e: &Error) -> Self {
        FileError {
            path: path.to_owned(),
            kind: e.kind().to_string(),
            message: e.to_string(),
        }
    }
}

/// What happened to one survey photo.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameReport {
    /// The survey photo.
    pub input: PathBuf,
    /// Its corrected output.
    pub output: PathBuf,
    /// Position among the usable photos of the mission.
    pub index: usize,
    /// The usable photos whose median gave this photo's `F`, and whether altitude chose them (`--navigation`). In
    /// JSON `"window": [first, last]`, and where altitude chose them also `"window_by_altitude"`: the photos it
    /// took, in order.
    #[serde(flatten)]
    pub window: Members,
    /// The photo's altitude in the navigation log (`--navigation`), metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub altitude: Option<f32>,
    /// Milliseconds spent decoding the photo.
    pub decode_ms: f64,
    /// Block median, temporal median and `F`.
    pub estimate_ms: f64,
    /// Milliseconds of the correction `A = (I − S) / F`.
    pub correct_ms: f64,
    /// Milliseconds spent encoding and writing the output.
    pub encode_ms: f64,
    /// Pixels where `F` was below `factor-floor`.
    pub floored_pixels: u64,
    /// Samples clipped to the output range (objects brighter than the seafloor colour allows).
    pub clipped_samples: u64,
    /// The output existed already (`--resume`): this photo was read for the windows and its health measured, but
    /// it was not written again (its timings and pixel counts are 0).
    pub resumed: bool,
    /// Contamination, change of F, and flags when the estimate is likely broken.
    pub health: Health<FlagNote>,
    /// `--method abyss`: the scale applied to the water-column `S` per channel (estimated per window unless
    /// `--backscatter-scale` fixed it); empty otherwise.
    #[serde(deserialize_with = "nulls_are_nan")]
    pub backscatter_scale: Vec<f32>,
    /// `--method abyss`: the sensor noise measured on the photo, standard deviation per channel in linear light
    /// (`[0, 1]` = black to white) at the level of its dimmest blocks (the noise grows with the level: the blend
    /// uses it at each block's); empty without `denoise`.
    #[serde(deserialize_with = "nulls_are_nan")]
    pub noise_sigma: Vec<f32>,
    /// `--method abyss`: the seafloor texture measured on the photo, standard deviation of the albedo within a
    /// block per channel, in the units of the seafloor colour (at most three times the median channel's relative
    /// texture); empty without `denoise`.
    #[serde(deserialize_with = "nulls_are_nan")]
    pub texture_sigma: Vec<f32>,
    /// `--window auto`: the window, quantile and near window chosen for this photo, its stretch's dark share and
    /// photos per independent sample, and why (`None` when the window was given).
    pub window_auto: Option<WindowAuto>,
}

impl FrameReport {
    /// A frame known only by its paths, index and health, as the run pictures read it: a window of the photo alone,
    /// no timings or pixel counts (all 0), no per-channel measurements.
    #[cfg(test)]
    pub(crate) fn pictured(
        input: PathBuf,
        output: PathBuf,
        index: usize,
        health: Health<FlagNote>,
    ) -> FrameReport {
        FrameReport {
            input,
            output,
            index,
            window: Members::over_time(index..index + 1),
            altitude: None,
            decode_ms: 0.0,
            estimate_ms: 0.0,
            correct_ms: 0.0,
            encode_ms: 0.0,
            floored_pixels: 0,
            clipped_samples: 0,
            resumed: false,
            health,
            backscatter_scale: Vec::new(),
            noise_sigma: Vec::new(),
            texture_sigma: Vec::new(),
            window_auto: None,
        }
    }
}

/// What `--window auto` chose for one photo (`method::stretch::Choice`), and why in words.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WindowAuto {
    /// The choice.
    #[serde(flatten)]
    pub choice: crate::method::stretch::Choice,
    /// Why, in words.
    pub why: String,
}

impl From<crate::method::stretch::Choice> for WindowAuto {
    fn from(choice: crate::method::stretch::Choice) -> Self {
        WindowAuto {
            why: choice.why(),
            choice,
        }
    }
}

/// How a run's windows were chosen, and the lengths its photos used.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WindowSummary {
    /// `auto` (per stretch of the mission, by the survey), `fixed` (`--window`) or `contamination` (the paper's rule
    /// for `--contamination`).
    pub rule: String,
    /// The window given, or the paper's rule's for the contamination given (`None` under `auto`).
    pub n: Option<usize>,
    /// The breakdown probability `P_half` of `n` at the contamination given (NaN, in JSON `null`, without one).
    #[serde(deserialize_with = "null_is_nan")]
    pub p_half: f64,
    /// The shortest window a photo of the run used (0: no photo).
    pub shortest: usize,
    /// The longest window a photo of the run used (0: no photo).
    pub longest: usize,
    /// With a navigation log (`--navigation`): the photos whose window was chosen by altitude (`None`: no log).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub by_altitude: Option<usize>,
}

impl WindowSummary {
    /// The summary of a run whose windows were chosen by `params` (resolved), with the windows its `frames` used
    /// ([`WindowSummary::count`]).
    pub fn of(
        params: &crate::method::params::Params,
        opts: &Options,
        frames: &[FrameReport],
    ) -> Self {
        use crate::method::params::Window;
        let fixed = opts.window_choice().ok();
        let (rule, n) = match params.window {
            _ if params.window_is_auto() => ("auto", None),
            Window::Contamination { .. } => ("contamination", fixed.map(|w| w.n)),
            _ => ("fixed", fixed.map(|w| w.n)),
        };
        let mut summary = WindowSummary {
            rule: rule.into(),
            n,
            p_half: fixed.map_or(f64::NAN, |w| w.p_half),
            shortest: 0,
            longest: 0,
            by_altitude: None,
        };
        summary.count(frames, opts.navigation.is_some());
        summary
    }

    /// Count the windows `frames` used (a run's, or a mission's merged from shards): the shortest and the longest
    /// (0: no photo), and with a navigation log how many altitude chose.
    pub fn count(&mut self, frames: &[FrameReport], navigation: bool) {
        let lengths = frames.iter().map(|f| f.window.len());
        self.shortest = lengths.clone().min().unwrap_or(0);
        self.longest = lengths.max().unwrap_or(0);
        self.by_altitude =
            navigation.then(|| frames.iter().filter(|f| f.window.by_altitude()).count());
    }

    /// In words, for the console: `windows 7..31 photos, chosen per stretch` or `window n = 9`.
    pub fn describe(&self) -> String {
        match (self.rule.as_str(), self.n) {
            ("auto", _) if self.longest == 0 => {
                "windows chosen per stretch (no photo corrected)".into()
            }
            ("auto", _) if self.shortest == self.longest => {
                format!("window {} photos, chosen per stretch", self.longest)
            }
            ("auto", _) => format!(
                "windows {}..{} photos, chosen per stretch",
                self.shortest, self.longest
            ),
            (_, Some(n)) if self.longest > 0 && self.longest < n => {
                format!(
                    "window n = {n}, {} photos (the whole mission)",
                    self.longest
                )
            }
            (_, n) => format!("window n = {}", n.unwrap_or_default()),
        }
    }
}

/// Where `S` came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScatterInfo {
    /// `water-column`, `file` or `none`.
    pub source: String,
    /// The water-column folder or scatter image.
    pub path: Option<PathBuf>,
    /// Water-column frames that entered the median.
    pub frames: usize,
    /// Row bands the estimate took (each a decoding pass over the frames).
    pub passes: usize,
    /// Where `--save-scatter` wrote `S`.
    pub saved_to: Option<PathBuf>,
}

/// Everything about one `correct` run (or a mission merged from shards), as `report.json` holds it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// `abysslight`.
    pub tool: String,
    /// Version of abysslight that made the report.
    pub version: String,
    /// Every option of the run (with `--transfer auto` resolved to the curve taken).
    pub options: Options,
    /// With `--transfer auto`: the curve taken and why (what the first survey photo's file declares).
    pub transfer_assumed: Option<String>,
    /// How the windows were chosen and the lengths the photos used (each photo's own is in its frame).
    pub window: WindowSummary,
    /// Size of the mission's photos.
    pub layout: Option<Layout>,
    /// Where `S` came from.
    pub scatter: ScatterInfo,
    /// Photos found in the survey folder.
    pub survey_photos: usize,
    /// Photos corrected and written.
    pub corrected: usize,
    /// Photos skipped because `--resume` found their output complete.
    pub skipped_existing: usize,
    /// Most full-resolution photos held at once (waiting for their window, queued for decoding or writing).
    /// Bounded by `n + 3 + 2·threads`, whatever the mission length.
    pub peak_photos_in_memory: usize,
    /// Photos that failed (decode, mismatch or write errors).
    pub failed: usize,
    /// Water-column frames that failed.
    pub water_column_failed: usize,
    /// Files in the survey folder passed over because their names are not photo names.
    pub ignored_files: usize,
    /// Pixels where `F` was below the floor, over all photos.
    pub floored_pixels: u64,
    /// Samples clipped to the output range, over all photos.
    pub clipped_samples: u64,
    /// How many photos were flagged, by reason.
    pub monitor: Summary,
    /// Every photo corrected (and, with `--resume`, found corrected), in mission order.
    pub frames: Vec<FrameReport>,
    /// Every file that failed, with the reason.
    pub errors: Vec<FileError>,
    /// What the user should know.
    pub warnings: Vec<String>,
    /// Seconds the run took.
    pub elapsed_s: f64,
    /// Where this report was written.
    pub report_path: Option<PathBuf>,
}

impl Report {
    /// Write the report as JSON to `opts.report`, or else to `report.json` in `work_dir` (per shard:
    /// `report-shard-K-of-N.json`), and remember where.
    pub fn write(&mut self, opts: &Options, work_dir: Option<&Path>) -> Result<(), Error> {
        self.write_or_print(opts, work_dir, &mut std::io::stderr().lock())
    }

    /// [`Report::write`], printing the report on `instead` when it cannot be written.
    fn write_or_print(
        &mut self,
        opts: &Options,
        work_dir: Option<&Path>,
        instead: &mut dyn std::io::Write,
    ) -> Result<(), Error> {
        let path = opts.report.clone().or_else(|| {
            work_dir.map(|w| {
                w.join(match opts.shard {
                    Some(s) => format!("report-shard-{}-of-{}.json", s.index, s.count),
                    None => "report.json".into(),
                })
            })
        });
        let Some(path) = path else {
            return Ok(());
        };
        self.report_path = Some(path.clone());
        let written = crate::io::write_with(&path, |w| {
            serde_json::to_writer_pretty(w, &*self).map_err(|e| Error::Encode {
                path: path.clone(),
                reason: e.to_string(),
            })
        });
        if written.is_err() {
            // A full disk or a lost folder must not lose the record of a mission: print it instead.
            self.report_path = None;
            self.print_instead(&path, instead);
        }
        written
    }

    /// The report as JSON on `to` (stderr), after a line saying why it is there and not in `path`. Errors of `to`
    /// itself (a closed pipe) are dropped: there is nowhere left to say them.
    fn print_instead(&self, path: &Path, to: &mut dyn std::io::Write) {
        let _ = writeln!(
            to,
            "abysslight: the run report could not be written to {}; here it is instead:",
            path.display()
        );
        let _ = serde_json::to_writer_pretty(&mut *to, self);
        let _ = writeln!(to);
    }

    /// True when every photo was corrected.
    pub fn all_ok(&self) -> bool {
        self.failed == 0 && self.water_column_failed == 0
    }
}

#[cfg(test)]
mod report_fallback_tests {
    use super::*;

    /// A report of 41 photos and none in its frames, with these options.
    pub(super) fn a_report(opts: Options) -> Report {
        Report {
            tool: "abysslight".into(),
            version: String::new(),
            options: opts,
            transfer_assumed: None,
            window: WindowSummary {
                rule: "auto".into(),
                n: None,
                p_half: f64::NAN,
                shortest: 7,
                longest: 7,
                by_altitude: None,
            },
            layout: None,
            scatter: ScatterInfo {
                source: "none".into(),
                path: None,
                frames: 0,
                passes: 0,
                saved_to: None,
            },
            survey_photos: 41,
            corrected: 41,
            skipped_existing: 0,
            peak_photos_in_memory: 0,
            failed: 0,
            water_column_failed: 0,
            ignored_files: 0,
            floored_pixels: 0,
            clipped_samples: 0,
            monitor: Default::default(),
            frames: Vec::new(),
            errors: Vec::new(),
            warnings: Vec::new(),
            elapsed_s: 0.0,
            report_path: None,
        }
    }

    /// A report that cannot be written (its folder cannot be made, as on a lost or full disk) is an error, and the whole
    /// report is printed instead: valid JSON after the line that says why.
    #[test]
    fn a_report_that_cannot_be_written_is_printed() {
        let d = tempfile::tempdir().unwrap();
        // A file where the report's folder should be: no folder can be made there.
        std::fs::write(d.path().join("gone"), b"").unwrap();
        let opts = Options {
            report: Some(d.path().join("gone/report.json")),
            ..Options::default()
        };
        let mut r = a_report(opts.clone());
        // Printed into a buffer, not onto the test's stderr (which `cargo test` does not capture).
        let mut printed = Vec::new();
        assert!(r.write_or_print(&opts, None, &mut printed).is_err());
        assert_eq!(r.report_path, None);
        let text = String::from_utf8(printed).unwrap();
        let (line, json) = text.split_once('\n').unwrap();
        assert!(line.contains("gone/report.json"), "{line}");
        let back: serde_json::Value = serde_json::from_str(json).unwrap();
        assert_eq!(back["corrected"], 41);
    }
}

#[cfg(test)]
mod typed_report_tests {
    use super::report_fallback_tests::a_report;
    use super::*;
    use crate::method::monitor::Flag;
    use crate::method::stretch::{Choice, Rule};

    fn frame(index: usize, window: Members, health: Health) -> FrameReport {
        FrameReport {
            input: format!("survey/img{index}.png").into(),
            output: format!("out/img{index}.png").into(),
            index,
            window,
            altitude: Some(2.5 + index as f32 / 8.0),
            decode_ms: 1.5,
            estimate_ms: 2.25,
            correct_ms: 0.125,
            encode_ms: 3.0,
            floored_pixels: 7,
            clipped_samples: 11,
            resumed: false,
            health: health.noted(),
            backscatter_scale: vec![0.75, 1.0, 1.25],
            noise_sigma: vec![0.01, 0.02, 0.03],
            texture_sigma: Vec::new(),
            window_auto: None,
        }
    }

    /// Report → JSON → report: the same report, and the frames' windows as `report.json` has always written them.
    #[test]
    fn a_report_comes_back_from_its_json_the_same() {
        let mut r = a_report(Options {
            navigation: Some("nav.csv".into()),
            ..Options::default()
        });
        r.window.p_half = 0.03125;
        r.layout = Some(Layout {
            width: 64,
            height: 48,
            channels: 3,
        });
        let flagged = Health {
            contamination: 0.5,
            level: 1.25,
            texture_kept: 0.75,
            motion: Some(1.5),
            flags: vec![
                Flag::Contamination { share: 0.5 },
                Flag::ExposureJump { level: 1.25 },
            ],
            exposure_absorbed: true,
            ..Health::default()
        };
        r.frames = vec![
            frame(0, Members::over_time(0..5), flagged),
            frame(
                1,
                Members::new(vec![0, 1, 3, 6, 8], true),
                Health::default(),
            ),
        ];
        r.frames[1].window_auto = Some(WindowAuto::from(Choice {
            window: 5,
            quantile: 0.5,
            near: Some(3),
            coverage: 0.25,
            photos_per_sample: 1.5,
            samples: 4,
            needed: 3,
            rule: Rule::Sparse,
            misfit: Some([0.125, 0.0625]),
        }));
        r.window.count(&r.frames, true);
        r.monitor = Summary::of(r.frames.iter().map(|f| &f.health));
        r.errors = vec![FileError {
            path: "survey/bad.png".into(),
            kind: "decode".into(),
            message: "survey/bad.png: not a PNG".into(),
        }];
        r.warnings = vec!["a warning".into()];
        r.report_path = Some("out/_abysslight/report.json".into());

        let json = serde_json::to_string_pretty(&r).unwrap();
        let back: Report = serde_json::from_str(&json).unwrap();
        assert_eq!(back, r);
        let v: serde_json::Value = serde_json::from_str(&json).unwrap();
        assert_eq!(v["frames"][0]["window"], serde_json::json!([0, 4]));
        assert!(v["frames"][0].get("window_by_altitude").is_none());
        assert_eq!(v["frames"][1]["window"], serde_json::json!([0, 8]));
        assert_eq!(
            v["frames"][1]["window_by_altitude"],
            serde_json::json!([0, 1, 3, 6, 8])
        );
        assert_eq!(v["frames"][1]["window_auto"]["rule"], "sparse");
        assert_eq!(
            v["frames"][0]["health"]["flags"][1]["kind"],
            "exposure-jump"
        );
        // The one counter of the windows: 5 photos each, one chosen by altitude; the flags by kind.
        assert_eq!(
            (r.window.shortest, r.window.longest, r.window.by_altitude),
            (5, 5, Some(1))
        );
        assert_eq!(
            (
                r.monitor.flagged,
                r.monitor.contamination,
                r.monitor.exposure_jump
            ),
            (1, 1, 1)
        );
        assert_eq!(r.monitor.exposure_absorbed, 1);
    }

    /// What is not measured (NaN, in JSON `null`) is read back as NaN.
    #[test]
    fn unmeasured_figures_come_back_as_nan() {
        let mut r = a_report(Options::default());
        r.frames = vec![frame(
            0,
            Members::over_time(0..1),
            Health {
                factor_change: f32::NAN,
                ..Health::default()
            },
        )];
        let json = serde_json::to_string(&r).unwrap();
        let back: Report = serde_json::from_str(&json).unwrap();
        assert!(back.window.p_half.is_nan() && back.frames[0].health.factor_change.is_nan());
        assert_eq!(serde_json::to_string(&back).unwrap(), json);
    }
}
