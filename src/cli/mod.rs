//! Command-line definition (clap) and the glue from flags to [`abysslight::Options`].
//!
//! Its doc comments are the `--help` text, written for a terminal (`<out>/…` is a placeholder, not HTML).
#![allow(rustdoc::invalid_html_tags)]

// Console output that never panics: a closed stdout or stderr (`abysslight ... 2>&1 | head`) must not end a
// mission; what cannot be printed is dropped (the run report still holds it). These shadow the std macros in
// the command's modules (declared below them).
macro_rules! eprintln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($t)*);
    }};
}
macro_rules! println {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($t)*);
    }};
}
macro_rules! print {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = write!(std::io::stdout(), $($t)*);
    }};
}

mod cluster;
mod extras;
mod ranges;

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Mutex;

use abysslight::io::gate::{Gate, Output};
use abysslight::run::options::{Method, Transfer};
use abysslight::{choose_window, Error, Options, Progress, SeafloorColour, Shard};
use clap::{Args, CommandFactory, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

/// Exit status: everything worked.
const EXIT_OK: u8 = 0;
/// Exit status: the run finished, but some photos (or water-column frames) failed; see the report.
const EXIT_SOME_FAILED: u8 = 1;
/// Exit status: bad usage or a fatal error; nothing (more) was done.
const EXIT_USAGE: u8 = 2;
/// Exit status with `--strict`: the run finished and every file was written, but photos were flagged.
const EXIT_FLAGGED: u8 = 3;

const EXIT_HELP: &str = "\
Exit status:
  0    every photo was corrected
  1    the run finished, but some files failed (listed on stderr and in _abysslight/report.json)
  2    bad usage or a fatal error (nothing, or nothing more, was written)
  3    with --strict: every file was written, but photos were flagged as likely wrong (see the
       report); without --strict such a run exits 0
  130  interrupted (Ctrl-C): run the same command again with --resume to finish";

/// `correct --help`: examples first, then the exit status.
const CORRECT_LONG_HELP: &str = "\
Examples:
  Correct a dive, with S from the frames of the descent:
    abysslight correct --water-column dive042/descent --survey dive042/survey \\
        --out dive042/corrected

  JPEGs from an sRGB camera, with pictures to check the estimate (the default window is chosen
  per stretch from a survey of the photos, on cluttered ground and nodule fields too;
  --contamination C pins one for the whole dive):
    abysslight correct --water-column descent --survey survey --out corrected \\
        --transfer srgb --save-factors

  Finish an interrupted run (finished photos are skipped, the result is the same):
    abysslight correct --water-column descent --survey survey --out corrected --resume

  One of 16 array jobs, S computed once with `abysslight scatter`:
    abysslight correct --scatter scatter.png --survey survey --out corrected --resume --shard 3/16

  Windows among photos lit from similar heights, from the vehicle's log (a towed sledge,
  an ROV whose altitude swings; docs/guide.md, \"Your vehicle's log\"):
    abysslight correct --water-column descent --survey survey --out corrected \\
        --navigation nav.csv

  Options from a file, one flag overridden:
    abysslight correct --config dive042.toml --window 9

Afterwards look at <out>/_abysslight/overview.png and flagged.png, and draw a before/after sheet:
  abysslight sheet SURVEY OUT sheet.png

Exit status:
  0    every photo was corrected
  1    the run finished, but some files failed (listed on stderr and in _abysslight/report.json)
  2    bad usage or a fatal error (nothing, or nothing more, was written)
  3    with --strict: every file was written, but photos were flagged as likely wrong (see the
       report); without --strict such a run exits 0
  130  interrupted (Ctrl-C): run the same command again with --resume to finish";

const SCATTER_EXIT_HELP: &str = "\
Exit status:
  0  S was estimated from every water-column frame
  1  S was written, but some frames failed (named on stderr)
  2  bad usage or a fatal error (nothing was written)";

const TOP_HELP: &str = "\
Start with `abysslight demo` (a simulated dive, corrected and scored in seconds), then
`abysslight correct --help`. Exit status 0: all went well, 1: some files failed, 2: bad usage or a fatal error,
3: photos flagged (only with --strict).";

const H_IN: &str = "Inputs";
const H_OUT: &str = "Outputs";
const H_METHOD: &str = "Method";
const H_MON: &str = "Monitoring";
const H_RUN: &str = "Run control";
const H_LIVE: &str = "During a dive (--watch)";

/// Remove the lighting of co-moving artificial lights from deep-sea survey photos (Köser et al.).
///
/// A pixel sees I = A·F + S: seafloor albedo A times a factor image F (light cones, attenuation, vehicle pose)
/// plus backscatter S. abysslight estimates S from water-column frames, F from a sliding window of survey photos,
/// and writes A = (I - S) / F. No calibration of lights, water or camera is needed.
#[derive(Parser, Debug)]
#[command(name = "abysslight", version = abysslight::io::jpeg::VERSION, after_help = TOP_HELP, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Correct a dive: water-column frames + survey photos -> lighting-compensated photos.
    #[command(
        override_usage = "abysslight correct [OPTIONS] --survey DIR --out DIR\n       abysslight correct --config FILE.toml [OPTIONS]\n       abysslight correct --cruise CRUISE --out DIR [OPTIONS]",
        after_help = EXIT_HELP,
        after_long_help = CORRECT_LONG_HELP
    )]
    Correct(Box<CorrectArgs>),
    /// Print the window size n for a contamination rate, and its breakdown probability P_half.
    Window(WindowArgs),
    /// Estimate the backscatter S from water-column frames once, for --scatter (e.g. before sharded runs).
    #[command(after_help = SCATTER_EXIT_HELP)]
    Scatter(ScatterArgs),
    /// Draw a before/after sheet of a corrected folder: input | corrected | F·C, a few photos spread over the dive.
    Sheet(SheetArgs),
    /// Benchmark: generate a 12 MP JPEG mission in a temp folder and measure correct against decode + encode.
    Bench(BenchArgs),
    /// Render a simulated dive with known albedo (water/, survey/, truth/, navigation.csv) for tests and evaluation.
    Simulate(SimulateArgs),
    /// Score corrected photos: against a simulated dive's truth, and/or by consistency over overlapping photos.
    Evaluate(EvaluateArgs),
    /// Simulate a small dive, correct it with every method, score them and draw a contact sheet.
    Demo(DemoArgs),
    /// Merge the reports of `correct --shard K/N` runs into the mission's report and pictures, as one run's.
    #[command(after_long_help = cluster::MERGE_LONG_HELP)]
    MergeShards(cluster::MergeShardsArgs),
    /// Print a shell completion script (bash, zsh, fish, powershell, elvish) to stdout.
    #[command(after_long_help = "\
Examples:
  abysslight completions bash > ~/.local/share/bash-completion/completions/abysslight
  abysslight completions zsh > ~/.zfunc/_abysslight      # with fpath+=(~/.zfunc) in ~/.zshrc
  abysslight completions fish > ~/.config/fish/completions/abysslight.fish")]
    Completions(CompletionsArgs),
    /// Print the manual page (roff) to stdout: abysslight manpage | man -l -
    #[command(after_long_help = "\
Examples:
  abysslight manpage | man -l -
  abysslight manpage correct > /usr/local/share/man/man1/abysslight-correct.1")]
    Manpage(ManpageArgs),
}

#[derive(Args, Debug)]
struct CompletionsArgs {
    /// The shell to complete for.
    #[arg(value_name = "SHELL")]
    shell: clap_complete::Shell,
}

#[derive(Args, Debug)]
struct ManpageArgs {
    /// A subcommand's page (e.g. correct) instead of the top-level page.
    #[arg(value_name = "COMMAND")]
    command: Option<String>,
}

#[derive(Args, Debug)]
struct SheetArgs {
    /// The survey folder that was corrected.
    #[arg(value_name = "SURVEY")]
    survey: PathBuf,
    /// The corrected folder (the --out of correct); F·C is added where --save-factors wrote it.
    #[arg(value_name = "CORRECTED")]
    corrected: PathBuf,
    /// The PNG to write.
    #[arg(value_name = "SHEET.png")]
    sheet: PathBuf,
    /// Photos on the sheet, spread evenly over the dive.
    #[arg(long, value_name = "N", default_value_t = 4)]
    rows: usize,
    /// Width of each picture on the sheet, in pixels.
    #[arg(long, value_name = "PX", default_value_t = 480)]
    width: u32,
}

#[derive(Args, Debug)]
struct BenchArgs {
    /// Photo size WIDTHxHEIGHT.
    #[arg(long, default_value = "4000x3000", value_name = "WxH")]
    size: String,
    /// Survey photos of the mission.
    #[arg(long, default_value_t = 60)]
    photos: usize,
    /// Above 1: correct a mission this many times longer too, and measure on it (peak memory of both).
    #[arg(long, default_value_t = 1)]
    long_factor: usize,
    /// Water-column frames of the mission.
    #[arg(long, default_value_t = 9)]
    water_column: usize,
    /// Sensor noise added to the generated photos: standard deviation in 8-bit levels.
    #[arg(long, default_value_t = 3.0)]
    noise: f32,
    /// JPEG quality of the generated photos (4:2:0).
    #[arg(long, default_value_t = 92)]
    quality: u8,
    /// A Python with OpenCV, for the libjpeg-turbo floor (cv2.imread + cv2.imencode, one thread).
    #[arg(long, value_name = "PYTHON", default_value = "python3")]
    python: PathBuf,
    /// Also time this peer script on the same mission (run as PYTHON PEER paper WATER SURVEY OUT).
    #[arg(long, value_name = "SCRIPT")]
    peer: Option<PathBuf>,
    /// Worker threads of correct and of the floor.
    #[arg(long, short = 'j', default_value_t = 2)]
    threads: usize,
    /// Sliding window n of correct and the peer [default: correct's own, auto; the peer's own].
    #[arg(long, value_name = "N")]
    window: Option<usize>,
    /// JPEG output quality [default: each input's, as `correct` does].
    #[arg(long, value_name = "Q")]
    jpeg_quality: Option<u8>,
    /// JPEG output subsampling: 444, 422 or 420 [default: each input's, as `correct` does].
    #[arg(long, value_name = "444|422|420")]
    jpeg_subsampling: Option<abysslight::io::Subsampling>,
    /// Generate the mission here instead of in a temporary folder.
    #[arg(long, value_name = "DIR")]
    dir: Option<PathBuf>,
    #[arg(long, hide = true)]
    child: bool,
    #[arg(long, hide = true)]
    child_water_column: Option<PathBuf>,
    #[arg(long, hide = true)]
    child_survey: Option<PathBuf>,
    #[arg(long, hide = true)]
    child_out: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct SimulateArgs {
    /// Output folder (water/, survey/, navigation.csv, truth/ are written below it).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Survey photos.
    #[arg(long, value_name = "N", default_value_t = 30)]
    frames: usize,
    /// Water-column frames.
    #[arg(long, value_name = "B", default_value_t = 15)]
    water_column: usize,
    /// Photo size.
    #[arg(long, value_name = "WxH", default_value = "320x240", value_parser = parse_size)]
    size: (usize, usize),
    /// Random seed (the same seed renders the same dive).
    #[arg(long, value_name = "S", default_value_t = 1)]
    seed: u64,
    /// Share of the seafloor covered by dark nodules.
    #[arg(long, value_name = "C", default_value_t = 0.2)]
    contamination: f64,
    /// Bits per sample of the PNGs written.
    #[arg(long, value_name = "8|16", default_value_t = 8)]
    bit_depth: u32,
    /// Curve applied before quantisation: linear or srgb (what a JPEG camera does).
    #[arg(long, value_name = "CURVE", default_value = "linear")]
    encode: Transfer,
    /// Light rig: two (beside the camera), three (two beside, one behind) or four (ring).
    #[arg(long, value_name = "RIG", default_value = "three")]
    rig: abysslight::eval::simulate::Rig,
    /// Mean altitude above the seafloor, metres.
    #[arg(long, value_name = "M", default_value_t = 3.0)]
    altitude: f32,
    /// Share of a photo's along-track extent that the next photo sees again.
    #[arg(long, value_name = "O", default_value_t = 0.6)]
    overlap: f32,
    /// Horizontal field of view, degrees.
    #[arg(long, value_name = "DEG", default_value_t = 75.0)]
    fov: f32,
    /// Beam width of the lights, degrees (σ of the fall-off); narrower beams put the cone edges into the frame.
    #[arg(long, value_name = "DEG", default_value_t = 36.0)]
    beam: f32,
    /// Sensor noise multiplier (0: none).
    #[arg(long, value_name = "X", default_value_t = 1.0)]
    noise: f32,
    /// Water: a preset (mild, oceanic-i, oceanic-iii, coastal) or attenuation per metre r,g,b (e.g. 0.4,0.07,0.03).
    #[arg(long, value_name = "PRESET|R,G,B", default_value = "mild")]
    water: abysslight::eval::simulate::Water,
    /// Altitude swing, metres (a slow and a faster oscillation) [default: 5 % of the altitude, slow].
    #[arg(long, value_name = "M")]
    altitude_swing: Option<f32>,
    /// Camera white-balance gains r,g,b (applied after the sensor noise), e.g. 6,1.3,1 for deep water.
    #[arg(long, value_name = "R,G,B", default_value = "1,1,1", value_parser = parse_gains)]
    white_balance: [f32; 3],
    /// Exposure: centre (sediment at the centre reads 0.7) or brightest (the brightest sediment reads 0.8).
    #[arg(long, value_name = "MODE", default_value = "centre")]
    exposure: abysslight::eval::simulate::Exposure,
    /// Also write each survey photo's true lighting: truth/lit/ (F·0.4) and truth/backscatter/ (S), linear 16-bit.
    #[arg(long)]
    truth_lighting: bool,
}

fn parse_gains(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("invalid gains {s:?}: expected R,G,B such as 6,1.3,1"))?;
    match v.as_slice() {
        [r, g, b] => Ok([*r, *g, *b]),
        _ => Err(format!(
            "invalid gains {s:?}: expected R,G,B such as 6,1.3,1"
        )),
    }
}

#[derive(Args, Debug)]
struct EvaluateArgs {
    /// Folders of photos to score, as LABEL=DIR or DIR (label = folder name). Photos are matched by file name.
    #[arg(value_name = "[LABEL=]DIR", required = true)]
    sets: Vec<String>,
    /// A simulated dive (the folder given to simulate --out): scores albedo error and residual lighting pattern.
    #[arg(long, value_name = "DIR")]
    truth: Option<PathBuf>,
    /// Placement of each photo in a mosaic (see docs/evaluation.md), for the consistency metric
    /// [default with --truth: the simulator's poses].
    #[arg(long, value_name = "FILE")]
    placements: Option<PathBuf>,
    /// Register the photos of this folder (the RAW photos, before any correction) by phase correlation of
    /// consecutive photos, and score every set's consistency on those placements (instead of --placements).
    #[arg(long, value_name = "RAW_DIR")]
    register: Option<PathBuf>,
    /// With --register: write the placements found (placement file format, reusable with --placements).
    #[arg(long, value_name = "FILE", requires = "register")]
    save_placements: Option<PathBuf>,
    /// Box-average photos by K before the consistency metric (each set is held in memory); placements and
    /// --cell stay in full-resolution units.
    #[arg(long, value_name = "K", default_value_t = 1)]
    eval_downsample: usize,
    /// Mosaic cell size of the consistency metric, in mosaic units.
    #[arg(long, value_name = "UNITS", default_value_t = 8.0)]
    cell: f64,
    /// Mask image the size of the photos, white = not seafloor (overlays, laser dots; e.g. a run's
    /// _abysslight/mask-auto.png): its pixels are left out of the consistency metric in every set.
    #[arg(long, value_name = "FILE")]
    mask: Option<PathBuf>,
    /// How the photos' values relate to light [default: the simulated dive's encoding, else linear].
    #[arg(long, value_name = "CURVE")]
    transfer: Option<Transfer>,
    /// Also write the scores as JSON to this file [default: none; the table goes to stdout].
    #[arg(long, value_name = "FILE.json")]
    json: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct DemoArgs {
    /// Output folder.
    #[arg(long, value_name = "DIR", default_value = "abysslight-demo")]
    out: PathBuf,
    /// Random seed of the simulated dive.
    #[arg(long, value_name = "S", default_value_t = 1)]
    seed: u64,
    /// Curve the simulated camera applies: linear or srgb (the correction is told the same).
    #[arg(long, value_name = "CURVE", default_value = "srgb")]
    encode: Transfer,
}

fn parse_size(s: &str) -> Result<(usize, usize), String> {
    let bad = || format!("invalid size {s:?}: expected WIDTHxHEIGHT, e.g. 320x240");
    let (w, h) = s.trim().split_once(['x', 'X']).ok_or_else(bad)?;
    Ok((
        w.trim().parse().map_err(|_| bad())?,
        h.trim().parse().map_err(|_| bad())?,
    ))
}

#[derive(Args, Debug)]
struct CorrectArgs {
    /// Folder of water-column frames (only water in view) for the backscatter S.
    ///
    /// Frames taken on the way down, with the lights on and only water and particles in view; their per-pixel
    /// median is S. Without it (and without --scatter) S = 0 and a warning says so.
    #[arg(long, value_name = "DIR", help_heading = H_IN)]
    water_column: Option<PathBuf>,

    /// A cruise: one folder per dive, each with survey/ and water-column/; OUT/<dive> per dive.
    ///
    /// Every folder CRUISE/<dive>/ holding a survey/ folder is a dive, its water-column frames in
    /// CRUISE/<dive>/water-column/ (or S from --scatter for every dive). The dives run one after the other with
    /// the same flags (with --shard K/N: chunk K of each dive); a dive that fails does not stop the others.
    /// With --report FILE each dive's report goes to FILE-<dive>.json. --out must lie outside every dive.
    #[arg(long, value_name = "CRUISE", conflicts_with_all = ["survey", "water_column"], help_heading = H_IN)]
    cruise: Option<PathBuf>,

    /// Set by --cruise for each dive's run: the dive's survey and water column replace those of --config.
    #[arg(skip)]
    dive_of_cruise: bool,

    /// Reuse a scatter image saved by an earlier run with --save-scatter.
    ///
    /// For another dive with the same rig, or shards sharing one S (see `abysslight scatter`).
    #[arg(long, value_name = "FILE", conflicts_with = "water_column", help_heading = H_IN)]
    scatter: Option<PathBuf>,

    /// Folder of survey photos (required; - reads frames from stdin).
    ///
    /// Searched recursively and processed in natural file-name order (img2 before img10). With - the frames
    /// (binary PPM/PGM or PNG, back to back, e.g. from ffmpeg -f image2pipe) are read from stdin.
    #[arg(long, value_name = "DIR", help_heading = H_IN)]
    survey: Option<PathBuf>,

    /// Mask image, white = not seafloor (overlays, laser dots, vehicle parts).
    ///
    /// The size of the photos. White pixels are left out of every median; F beneath them is interpolated from the
    /// seafloor around them and they are corrected with it (burned-in text stays readable).
    #[arg(long, value_name = "FILE", help_heading = H_IN)]
    mask: Option<PathBuf>,

    /// Also mask pixels that stay the same through the mission (overlays, lasers), and where laser dots wander.
    ///
    /// Static pixels are found in medians of the mission's three thirds. Laser dots that move with the altitude
    /// are found as blocks where a red or green bright spot comes back more often than chance would bring
    /// anything there (up to 400 photos spread over the mission are read once more for it; grey photos get no
    /// laser paths). The masked dots are corrected like the seafloor around them, so no stain is left where they
    /// are not; they themselves stay visible (score overlaps with `evaluate --mask`). The mask found is written to
    /// <out>/_abysslight/mask-auto.png, to check and to reuse with --mask.
    #[arg(long, help_heading = H_IN)]
    mask_auto: bool,

    /// Navigation log (CSV) of each photo's altitude: windows are chosen among photos lit from similar heights.
    ///
    /// A header row, then a row per photo; cells separated by commas, semicolons or tabs, quoted or not; lines
    /// starting with # are comments; a units row under the header (s,deg,m) is passed over. The photo's column is
    /// named file, filename, image, photo, relative_path or path, the altitude's contains "altitude" (metres;
    /// oplab's "altitude [m]", dvl_altitude_m) or is alt; --navigation-columns names others. Photos are matched
    /// by file name (else by name without the extension). A log without a file column but with a time column
    /// (time, timestamp, datetime, date time, epoch, utc: seconds since 1970 UTC or dates such as
    /// 2023-06-03T16:27:01.5Z, with an offset or in UTC) is read at each photo's EXIF time (DateTimeOriginal, its
    /// sub-seconds and offset; --navigation-clock-offset for a log on another clock), interpolated between rows
    /// at most 10 s apart. Rows without an altitude (empty, NaN, 0, negative: a DVL without bottom lock) are
    /// passed over and counted in a warning; an altitude over 1000 m is refused. Where the altitude swings along
    /// the track (more than 15 % over a window), each photo's window is taken among the photos around it lit from
    /// the nearest heights, half before and half after it, instead of the photos nearest in time: a towed sledge
    /// or an ROV over rough ground. Photos not in the log keep the window over time. --method abyss; each photo
    /// waits for a whole window of photos after it. The report lists each photo's altitude and the photos its
    /// window took.
    #[arg(long, value_name = "FILE.csv", help_heading = H_IN)]
    navigation: Option<PathBuf>,

    /// The navigation log's columns where their names are unusual: KEY=NAME pairs, keys file, time, altitude.
    ///
    /// E.g. --navigation-columns "time=Date Time,altitude=dvl_range". Names are matched in any case. A column not
    /// named is found by its name (see --navigation). Config file: navigation-columns = "time=…,altitude=…" or a
    /// table { time = "…", altitude = "…" }.
    #[arg(long, value_name = "KEY=NAME,…", help_heading = H_IN)]
    navigation_columns: Option<abysslight::io::navigation::Columns>,

    /// Seconds added to the navigation log's times to put them on the camera's clock [default: 0].
    ///
    /// The camera's clock minus the log's: -7200 for a log kept 2 h ahead of the camera (UTC against local
    /// time). When no photo's time falls in the log, the error gives both spans and the offset that aligns them.
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true, help_heading = H_IN)]
    navigation_clock_offset: Option<f64>,

    /// How stored values relate to light: auto, srgb (most JPEGs), linear or gamma:G [default: auto].
    ///
    /// auto reads what the first survey photo's file declares (PNG cICP/sRGB/gAMA, an ICC profile, EXIF
    /// ColorSpace); a JPEG that declares nothing is taken as srgb, any other file as linear. The run prints the
    /// curve it took and why, and report.json records it. srgb for most JPEG cameras, linear for machine-vision
    /// cameras and RAW conversions, gamma:G for a pure power law. Estimation and correction run in linear light;
    /// the output is stored with the same curve.
    #[arg(long, value_name = "CURVE", value_parser = parse_transfer, help_heading = H_IN)]
    transfer: Option<TransferArg>,

    /// Options from a TOML file (keys as the long flags); flags override it.
    ///
    /// E.g. seafloor-colour = "#8a7560". Relative paths in the file are relative to the file.
    #[arg(long, value_name = "FILE.toml", help_heading = H_IN)]
    config: Option<PathBuf>,

    /// Output folder (required; - writes the frames to stdout).
    ///
    /// Mirrors the survey tree (same names, format and bit depth); run files go to <out>/_abysslight/. With -
    /// the corrected frames go to stdout in order, in the format they came in (log on stderr, report only with
    /// --report).
    #[arg(long, value_name = "DIR", help_heading = H_OUT)]
    out: Option<PathBuf>,

    /// JPEG output quality, 1-100 [default: the JPEG input's].
    ///
    /// By default each JPEG output gets the quality of its input, estimated from the input's quantisation
    /// tables (as ImageMagick does), so a corrected dive is about the size of the raw one; 95 for other inputs.
    #[arg(long, value_name = "Q", help_heading = H_OUT)]
    jpeg_quality: Option<u8>,

    /// JPEG output chroma subsampling: 444, 422 or 420 [default: the JPEG input's].
    ///
    /// By default each JPEG output gets its input's subsampling; 444 for other inputs.
    #[arg(long, value_name = "444|422|420", help_heading = H_OUT)]
    jpeg_subsampling: Option<abysslight::io::Subsampling>,

    /// PNG output compression: fast, default or best [default: fast].
    ///
    /// Lossless either way; fast writes a 12 MP photo several times quicker for files somewhat larger
    /// (docs/performance.md). TIFF is written uncompressed.
    #[arg(long, value_name = "LEVEL", help_heading = H_OUT)]
    png_compression: Option<abysslight::io::PngCompression>,

    /// Write S as a 16-bit PNG to <out>/_abysslight/scatter.png (reusable with --scatter).
    #[arg(long, help_heading = H_OUT)]
    save_scatter: bool,

    /// Photos in the sliding window whose median gives F (odd) [default: auto].
    ///
    /// Centred on the photo, shifted at the mission's ends. More photos tolerate more clutter (rocks, fauna,
    /// shadow) at one place in the frame, but follow altitude changes more slowly.
    /// Without --window and --contamination (--method abyss): auto, chosen per stretch of the mission from a
    /// survey of its photos (their dark share and how many photos see the same scene; docs/nodules.md): 7 and
    /// the median on sparse ground under a moving camera, longer windows and the (1 + c)/2 quantile on dense
    /// nodule fields and under a slow camera, never longer than the mission. Photos as they come (--watch,
    /// --survey -) are surveyed as they come: each is corrected once the 25 after it are in.
    #[arg(long, value_name = "N|auto", value_parser = parse_window, conflicts_with = "contamination", help_heading = H_METHOD)]
    window: Option<WindowArg>,

    /// --method abyss: photos in the near window, or auto; 0 turns it off [default: auto].
    ///
    /// The window is long enough that its median almost never breaks; over that many photos the lights' footprint
    /// moves with the vehicle's altitude and roll. The median of the nearest photos follows it, and only its smooth
    /// shape (the median ratio over squares an eighth of the frame across) bends the window's M, so its local
    /// breakdowns are outvoted.
    /// auto: with --contamination the smallest window with P_half <= 5 % (at least 5), else 5; used when shorter
    /// than --window.
    #[arg(long, value_name = "N|auto", value_parser = parse_near, help_heading = H_METHOD)]
    near_window: Option<NearArg>,

    /// Expected share of non-seafloor pixels (0 to 0.5); sets --window from it.
    ///
    /// --window becomes the smallest odd n with P_half <= --risk (see `abysslight window`). With --method abyss
    /// the contamination is taken to be darker than the seafloor (nodules, shadows, burrows): M is the window's
    /// (1 + C)/2 quantile instead of its median, the seafloor's own median; bright clutter (fauna, shells) above
    /// (1 - C)/2 of the window then breaks the estimate sooner than with the median. One window for the whole
    /// mission: on nodule fields (C of 0.3 and more) the default without it, a window per stretch from a survey of
    /// the photos, does better (docs/guide.md).
    /// auto: as without --window and --contamination, measured per stretch of the mission (also undoes a config
    /// file's window or contamination).
    #[arg(long, value_name = "C|auto", value_parser = parse_contamination, help_heading = H_METHOD)]
    contamination: Option<ContaminationArg>,

    /// Accepted breakdown probability of the median, for --contamination [default: 0.01].
    #[arg(long, value_name = "R", help_heading = H_METHOD)]
    risk: Option<f64>,

    /// How the lighting is estimated: abyss, paper, mean or polynomial [default: abyss].
    ///
    /// abyss is the paper's sliding-window F (with --contamination C: the window's (1 + C)/2 quantile) with a
    /// per-photo gain against its window, a floor relative to the photo's lit level with a smooth hand-over, and
    /// dim regions blended towards their local level by their measured signal-to-noise ratio (docs/evaluation.md);
    /// paper is Köser et al. as published
    /// (absolute --factor-floor); the baselines are mean (divide by the mission's mean image) and polynomial
    /// (per-photo robust polynomial fit of log intensity).
    #[arg(long, value_name = "METHOD", help_heading = H_METHOD)]
    method: Option<Method>,

    /// --method abyss: floor of F as a share of the photo's lit level [default: 0.001].
    ///
    /// The lit level is the 95th percentile of F per channel; F is floored softly, F' = (F^4 + phi^4)^(1/4).
    #[arg(long, value_name = "SHARE", help_heading = H_METHOD)]
    relative_floor: Option<f32>,

    /// --method abyss: do not level the window's photos to one exposure before its M (on by default).
    ///
    /// Where the exposure jumps from photo to photo (a sledge that lifts and drops, an automatic exposure: some
    /// photo more than 10 % off its neighbours in every channel), the window's median at most blocks is the photo
    /// whose level is the middle one, and F takes that photo's burrows and nodules whole (ghosts); each photo of
    /// such a window is divided by its gain against the window's M before the median. A smooth drift is left alone,
    /// and so are windows shorter than 7 photos and, in windows longer than 11, a jump at the first or last photo.
    #[arg(long, help_heading = H_METHOD)]
    no_level_exposures: bool,

    /// --method abyss: no per-photo gain against the window (on by default).
    #[arg(long, help_heading = H_METHOD)]
    no_photo_gain: bool,

    /// --method abyss: scale of the water-column S for the survey photos, or auto [default: 1].
    ///
    /// Water-column frames look into open water, survey photos end at the floor, so S measured on the way down
    /// can over-estimate the survey's backscatter. auto estimates the scale per window from how the seafloor's
    /// contrast follows the light (clamped to 0.2..1, kept at 1 where the fit is unsure); on simulated dives it
    /// reads red about 4 % low, which tints dark objects red, so it is not the default. report.json gives the
    /// scale per photo.
    #[arg(long, value_name = "K|auto", value_parser = parse_scale, help_heading = H_METHOD)]
    backscatter_scale: Option<ScaleArg>,

    /// --method abyss: do not blend dim regions towards their local level (on by default).
    ///
    /// By default, where the lights leave little signal, a pixel's correction is blended with its block's level by
    /// the signal-to-noise ratio measured on each photo (a Wiener estimate), so unlit corners show the local
    /// seafloor instead of amplified noise; with this flag they are divided by F like the rest.
    #[arg(long, help_heading = H_METHOD)]
    no_denoise: bool,

    /// --method abyss: do not even out the blended levels of dim regions (on by default).
    ///
    /// In dim blocks noise, an over-estimated S and the window's quantile bias the local level low; by default
    /// each photo measures that loss as the typical level of its blocks at each light level against its brightest
    /// quarter's, and divides it out, so dim regions are not left darker than lit ones.
    #[arg(long, help_heading = H_METHOD)]
    no_level_by_light: bool,

    /// --method abyss, --window auto: do not leave the paths of laser dots out of F (on by default).
    ///
    /// By default the survey looks at the mission's first 41 photos for blocks where a red or green bright spot
    /// comes back more often than chance would bring anything there: the paths of laser dots, which wander with the
    /// altitude. Those blocks are left out of every window's median, F beneath them is filled from the seafloor
    /// around, and the dots are corrected like it: they stay red and leave no teal stain in the photos where they
    /// are not. The run says what it masked. With this flag the median may take the dots into F, as it did before.
    /// Grey photos get no laser paths; --mask-auto finds the paths over the whole mission instead.
    #[arg(long, help_heading = H_METHOD)]
    no_laser_paths: bool,

    /// --method abyss: fill F where laser dots or highlights that move held the window's median (off by default).
    ///
    /// Laser dots move in the frame with the altitude, so over a window they can sit on the same few blocks in
    /// most photos, and the window's median takes them into F: a coloured stain (teal beside a red laser) in the
    /// photos where the dot is not. With this flag each photo's blocks at least twice as bright as the seafloor
    /// around them, in small groups, count as spots, and where spots held more than half of the window F is
    /// filled from the blocks around. The dots themselves then keep their full brightness, which raises the
    /// overlap difference (docs/evaluation.md). For red or green laser dots --mask-auto does more: it masks their
    /// whole path, so fainter stains go too.
    #[arg(long, help_heading = H_METHOD)]
    bright_spots: bool,

    /// --method abyss: bend F to the ratios of overlapping photos (off by default).
    ///
    /// Consecutive photos see the same seafloor shifted; the ratio of two photos at the same ground is the ratio
    /// of F at the two places in the frame, whatever lies there, so nodules, burrows and fauna that held the
    /// window's median cancel. F is fitted to the ratios of every registered pair of the window; what the shifts
    /// leave open (across the track, the overall level) comes from the window's median. See docs/overlaps.md.
    #[arg(long, help_heading = H_METHOD)]
    overlaps: bool,

    /// Block size K of the spatial median before the temporal median, or auto [default: auto].
    ///
    /// auto, with --method abyss: about 160 blocks across the photo's longer side, from 4 to 8 pixels, so the
    /// paper's 8 from 1280 pixels up (every 12-24 MP camera) and 4 up to 800. F and the blend's level are
    /// estimated per block, so a block large against the frame smooths the light cones' edges and the seafloor's
    /// detail (docs/evaluation.md). The other methods, and runs with --mask or --mask-auto (overlays), take the
    /// paper's 8. The run says what it took.
    #[arg(long, value_name = "K|auto", value_parser = parse_blocks, help_heading = H_METHOD)]
    downsample: Option<BlocksArg>,

    /// Colour C the seafloor gets after correction (white balance) [default: grey = 0.4].
    ///
    /// grey, grey:0.5, 0.42,0.36,0.28, 107,92,71 or #8a7560. The default 0.4 leaves 2.5x headroom for objects
    /// brighter than the sediment.
    #[arg(long, value_name = "COLOUR", visible_alias = "seafloor-color", help_heading = H_METHOD)]
    seafloor_colour: Option<SeafloorColour>,

    /// Smallest F a pixel is divided by, for every method but abyss [default: 0.05].
    ///
    /// Caps the gain in dark corners (at 20x a normally lit pixel for 0.05); the count of floored pixels is
    /// reported.
    #[arg(long, value_name = "F", help_heading = H_METHOD)]
    factor_floor: Option<f32>,

    /// Degree of the polynomial of --method polynomial [default: 4].
    #[arg(long, value_name = "D", help_heading = H_METHOD)]
    degree: Option<usize>,

    /// Write each photo's lit seafloor F·C = M - S to <out>/_abysslight/factors/ (and a preview).
    ///
    /// factors/ holds 16-bit PNGs, one pixel per KxK block (the data); factors-preview/ holds 8-bit PNGs scaled
    /// to each photo's range and enlarged to at least 640 pixels wide (for looking at). A seafloor colour change
    /// or a broken estimate (a window full of rocks) shows up here first.
    #[arg(long, help_heading = H_MON)]
    save_factors: bool,

    /// Write the run report (JSON) here [default: <out>/_abysslight/report.json].
    ///
    /// With --out - this is the only report.
    #[arg(long, value_name = "FILE", help_heading = H_MON)]
    report: Option<PathBuf>,

    /// No progress bar and no log lines (errors are still printed).
    #[arg(long, short = 'q', help_heading = H_MON)]
    quiet: bool,

    /// Worker threads [default: all cores].
    #[arg(long, short = 'j', value_name = "N", help_heading = H_RUN)]
    threads: Option<usize>,

    /// Skip photos whose output already exists (to finish an interrupted run).
    ///
    /// Outputs are only renamed into place when complete. The skipped photos' neighbours are still read, so the
    /// result is byte-identical to an uninterrupted run.
    #[arg(long, help_heading = H_RUN)]
    resume: bool,

    /// Exit with status 3 when any photo is flagged as likely wrong (and no file failed).
    ///
    /// For pipelines that must not pass a doubtful run on: the run still corrects every photo and writes its
    /// report (which names the flags); only the exit status differs. Config key: strict = true.
    #[arg(long, help_heading = H_RUN)]
    strict: bool,

    /// Print what would be read and written, then stop: nothing is written.
    ///
    /// The photos to correct and those read for the windows only, outputs that exist already, the window n,
    /// where S comes from, the method and its parameters, and about how much disk the outputs need.
    #[arg(long, help_heading = H_RUN)]
    dry_run: bool,

    /// Correct only the first N photos (of the survey, or of the shard), with the windows of a whole run.
    ///
    /// A quick look at a new rig: the photos after them are read for the windows, so these N come out exactly as
    /// in a run over everything.
    #[arg(long, value_name = "N", help_heading = H_RUN)]
    limit: Option<usize>,

    /// Write only chunk K of N contiguous chunks of the survey (K = 1..N).
    ///
    /// Reads the neighbours its windows need: the union of all N shards equals one run. For SLURM/PBS array
    /// jobs and GNU parallel.
    #[arg(long, value_name = "K/N", help_heading = H_RUN)]
    shard: Option<Shard>,

    /// Correct photos as they arrive in the survey folder during a dive.
    ///
    /// Each photo is corrected once the n/2 photos after it are complete, until Ctrl-C/SIGTERM or
    /// --idle-timeout; then the last photos are finished and the report written. A file is taken once its size
    /// and mtime are unchanged over two scans: writers should rename files into place.
    #[arg(long, help_heading = H_LIVE)]
    watch: bool,

    /// With --watch: stop after SECS seconds without a new or changed file [default: never].
    #[arg(long, value_name = "SECS", help_heading = H_LIVE)]
    idle_timeout: Option<f64>,

    /// With --watch: milliseconds between two scans of the survey folder [default: 500].
    #[arg(long, value_name = "MS", help_heading = H_LIVE)]
    poll_interval: Option<u64>,
}

#[derive(Args, Debug)]
struct ScatterArgs {
    /// Folder of water-column frames.
    #[arg(long, value_name = "DIR")]
    water_column: PathBuf,
    /// Where to write S (16-bit PNG).
    #[arg(long, value_name = "FILE.png")]
    out: PathBuf,
    /// Memory the estimate may hold at once, in MiB (more frames are processed in row bands).
    #[arg(long, value_name = "MIB", default_value_t = 2048)]
    memory: usize,
    /// No log lines (errors are still printed).
    #[arg(long, short = 'q')]
    quiet: bool,
}

#[derive(Args, Debug)]
struct WindowArgs {
    /// Contamination rate c: expected share of non-seafloor pixels (0 to 0.5).
    #[arg(long, value_name = "C")]
    contamination: f64,
    /// Accepted breakdown probability P_half.
    #[arg(long, value_name = "R", default_value_t = 0.01)]
    risk: f64,
}

/// Start from the config file (if any) and let each given flag override it.
fn options_from(args: &CorrectArgs) -> Result<Options, Error> {
    let mut o = match &args.config {
        Some(p) => Options::from_toml_file(p)?,
        None => Options::default(),
    };
    let config_scatter = o.scatter.clone();
    set_run_flags(args, &mut o);
    set_method_flags(args, &mut o);
    if args.dive_of_cruise {
        // A dive of a cruise reads its own water column (none when it has none), unless a scatter image, given as
        // a flag or in --config, serves every dive: a --config water column is another dive's.
        o.scatter = args.scatter.clone().or(config_scatter);
        o.water_column = if o.scatter.is_some() {
            None
        } else {
            args.water_column.clone()
        };
        // Its own navigation log, or none: a --config log is another dive's.
        o.navigation = args.navigation.clone();
    }
    if o.survey.is_none() {
        return Err(Error::Usage(
            "--survey DIR is required (or survey = \"DIR\" in --config)".into(),
        ));
    }
    if o.out.is_none() {
        return Err(Error::Usage(
            "--out DIR is required (or out = \"DIR\" in --config)".into(),
        ));
    }
    o.validate()?;
    // The config file is an input too: no output may overwrite or surround it.
    if let Some(cfg) = &args.config {
        let outs: Vec<(&str, &Path)> = [
            ("--out", o.out.as_deref()),
            ("--report", o.report.as_deref()),
        ]
        .into_iter()
        .filter_map(|(f, p)| Some((f, p.filter(|p| *p != Path::new("-"))?)))
        .collect();
        abysslight::io::paths::check_outputs(&outs, &[("config file", cfg)])?;
    }
    Ok(o)
}

/// The flags that say where photos come from and go to, and how the run goes.
fn set_run_flags(args: &CorrectArgs, o: &mut Options) {
    macro_rules! set {
        ($($f:ident),*) => {$( if let Some(v) = &args.$f { o.$f = Some(v.clone()); } )*};
    }
    set!(
        water_column,
        scatter,
        survey,
        out,
        threads,
        mask,
        navigation,
        idle_timeout,
        report,
        jpeg_quality,
        jpeg_subsampling,
        limit,
        shard
    );
    if args.water_column.is_some() {
        o.scatter = None;
    }
    if args.scatter.is_some() {
        o.water_column = None;
    }
    o.watch |= args.watch;
    o.mask_auto |= args.mask_auto;
    o.save_scatter |= args.save_scatter;
    o.save_factors |= args.save_factors;
    o.resume |= args.resume;
    o.strict |= args.strict;
    if let Some(v) = args.poll_interval {
        o.poll_interval = v;
    }
    if let Some(v) = args.png_compression {
        o.png_compression = v;
    }
    if let Some(v) = &args.navigation_columns {
        o.navigation_columns = v.clone();
    }
    if let Some(v) = args.navigation_clock_offset {
        o.navigation_clock_offset = v;
    }
}

/// The flags of the method (src/method/params.rs says what each one does).
fn set_method_flags(args: &CorrectArgs, o: &mut Options) {
    macro_rules! set {
        ($($f:ident),*) => {$( if let Some(v) = &args.$f { o.$f = v.clone(); } )*};
    }
    set!(
        method,
        degree,
        relative_floor,
        risk,
        seafloor_colour,
        factor_floor
    );
    // `--transfer auto` is `None`, as in a config file and by default.
    if let Some(TransferArg(t)) = args.transfer {
        o.transfer = t;
    }
    if let Some(ScaleArg(k)) = args.backscatter_scale {
        o.backscatter_scale = k;
    }
    if let Some(BlocksArg(v)) = args.downsample {
        o.downsample = v;
    }
    if let Some(NearArg(v)) = args.near_window {
        o.near_window = v;
    }
    o.level_exposures &= !args.no_level_exposures;
    o.photo_gain &= !args.no_photo_gain;
    o.denoise &= !args.no_denoise;
    o.level_by_light &= !args.no_level_by_light;
    o.laser_paths &= !args.no_laser_paths;
    o.bright_spots |= args.bright_spots;
    o.overlaps |= args.overlaps;
    if let Some(WindowArg(n)) = args.window {
        // `auto` also undoes a config file's window.
        o.window = n;
        o.contamination = None;
    }
    if let Some(ContaminationArg(c)) = args.contamination {
        // `auto` also undoes a config file's contamination and window.
        o.contamination = c;
        o.window = None;
    }
}

/// Progress on stderr: a bar on a terminal, plain lines otherwise, nothing but errors with --quiet.
struct Console {
    bar: Option<ProgressBar>,
    plain: bool,
    count: Mutex<(usize, usize)>,
}

impl Console {
    fn new(quiet: bool) -> Self {
        let tty = std::io::stderr().is_terminal();
        Console {
            bar: None,
            plain: !quiet && !tty,
            count: Mutex::new((0, 0)),
        }
        .with_bar(!quiet && tty)
    }
    fn with_bar(mut self, on: bool) -> Self {
        if on {
            let bar = ProgressBar::new(0);
            bar.set_style(
                ProgressStyle::with_template(
                    "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} photos ({per_sec}, eta {eta}) {msg}",
                )
                .unwrap(),
            );
            self.bar = Some(bar);
        }
        self
    }
    fn line(&self, s: &str) {
        match &self.bar {
            Some(b) => b.println(s),
            None => eprintln!("{s}"),
        }
    }
}

impl Progress for Console {
    fn warn(&self, m: &str) {
        if self.plain || self.bar.is_some() {
            self.line(&format!("abysslight: warning: {m}"));
        }
    }
    fn stage(&self, m: &str) {
        if self.plain || self.bar.is_some() {
            self.line(&format!("abysslight: {m}"));
        }
    }
    fn file_error(&self, e: &Error) {
        self.line(&format!("abysslight: error: {e}"));
    }
    fn start(&self, total: usize) {
        *self.count.lock().unwrap() = (0, total);
        if self.plain && self.bar.is_none() && total > 1 {
            // `[68/71] done IMG_0070.png`: photos finish out of order on several threads.
            eprintln!(
                "abysslight: [k/{total}] below counts the photos finished so far, not the photo's place in the survey"
            );
        }
        if let Some(b) = &self.bar {
            if total == 0 {
                // A watch or a stream: no total to show a bar against.
                b.set_style(
                    ProgressStyle::with_template(
                        "{spinner} [{elapsed_precise}] {pos} photos ({per_sec}) {msg}",
                    )
                    .unwrap(),
                );
            }
            b.set_length(total as u64);
        }
    }
    fn photo_done(&self, input: &Path, ok: bool) {
        let (i, n) = {
            let mut c = self.count.lock().unwrap();
            c.0 += 1;
            *c
        };
        if let Some(b) = &self.bar {
            b.inc(1);
        } else if self.plain {
            let status = if ok { "done" } else { "FAILED" };
            // Below the current folder: the path as the user would type it, not the machine's absolute one.
            let cwd = std::env::current_dir().unwrap_or_default();
            let shown = input.strip_prefix(&cwd).unwrap_or(input).display();
            if n == 0 {
                // A watch or a stream: the total is not known.
                eprintln!("abysslight: [{i}] {status} {shown}");
            } else {
                eprintln!("abysslight: [{i}/{n}] {status} {shown}");
            }
        }
    }
    fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

fn correct(args: &CorrectArgs) -> Result<ExitCode, Error> {
    let opts = options_from(args)?;
    if args.dry_run {
        // The same checks and listing as a run, and nothing written.
        let plan = abysslight::run::plan::Plan::new(&opts, &abysslight::Silent)?;
        print!("{}", plan.describe(&opts)?);
        println!("dry run: nothing was written");
        return Ok(ExitCode::from(EXIT_OK));
    }
    if opts.watch {
        // Ctrl-C or SIGTERM ends the watch cleanly (the last photos are finished, the report is written); a
        // second one kills at once. signal-hook rather than raw libc: its handlers only set an atomic flag, which
        // is what is safe in a signal handler, and it keeps unsafe code out of abysslight.
        let stop = abysslight::run::watch::stop_flag();
        for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
            signal_hook::flag::register_conditional_shutdown(sig, 1, stop.clone())
                .and_then(|_| signal_hook::flag::register(sig, stop.clone()))
                .map_err(|e| Error::Usage(format!("cannot install the signal handler: {e}")))?;
        }
    }
    // A batch run into a folder (not --watch, not a pipe: --resume is for these only).
    let piped = |p: &Option<PathBuf>| p.as_deref() == Some(Path::new("-"));
    let batch_out = opts
        .out
        .clone()
        .filter(|_| !opts.watch && !piped(&opts.survey) && !piped(&opts.out));
    if let Some(out) = &batch_out {
        extras::hint_on_interrupt()?;
        if !args.quiet {
            extras::note_non_empty_out(out, opts.resume);
        }
    }
    let console = Console::new(args.quiet);
    let report = abysslight::correct_mission(&opts, &console)?;
    if !args.quiet {
        for line in abysslight::run::summary::lines(&report, &opts, batch_out.as_deref()) {
            eprintln!("abysslight: {line}");
        }
    }
    let flagged = abysslight::run::summary::flagged(&report);
    if opts.strict && flagged > 0 && report.all_ok() {
        eprintln!(
            "abysslight: --strict: {flagged} of {} photos flagged as likely wrong: exit status {EXIT_FLAGGED}",
            report.frames.len()
        );
        return Ok(ExitCode::from(EXIT_FLAGGED));
    }
    Ok(ExitCode::from(if report.all_ok() {
        EXIT_OK
    } else {
        EXIT_SOME_FAILED
    }))
}

fn scatter(args: ScatterArgs) -> Result<ExitCode, Error> {
    let most = abysslight::limits::SCATTER_MEMORY_MIB;
    if !(1..=most).contains(&args.memory) {
        return Err(Error::Usage(format!(
            "--memory must be 1 to {most} MiB, got {}",
            args.memory
        )));
    }
    let console = Console::new(args.quiet);
    let s = abysslight::run::estimate_scatter_file(
        &args.water_column,
        &args.out,
        args.memory,
        &console,
    )?;
    if !args.quiet {
        eprintln!(
            "abysslight: S from {} frame(s) written to {} ({} failed)",
            s.frames,
            args.out.display(),
            s.failed
        );
    }
    Ok(ExitCode::from(if s.failed == 0 {
        EXIT_OK
    } else {
        EXIT_SOME_FAILED
    }))
}

fn bench(a: BenchArgs) -> Result<ExitCode, Error> {
    use abysslight::eval::bench;
    if a.child {
        let need = |p: &Option<PathBuf>| {
            p.clone()
                .ok_or_else(|| Error::Usage("bench --child needs its folders".into()))
        };
        let r = bench::child(
            &need(&a.child_water_column)?,
            &need(&a.child_survey)?,
            &need(&a.child_out)?,
            a.threads,
            a.window,
            a.jpeg_quality,
            a.jpeg_subsampling,
        )?;
        println!(
            "{}{}",
            bench::CHILD_LINE,
            serde_json::to_string(&r).unwrap_or_default()
        );
        return Ok(ExitCode::from(EXIT_OK));
    }
    let (w, h) = a
        .size
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
        .ok_or_else(|| Error::Usage(format!("--size {}: expected WIDTHxHEIGHT", a.size)))?;
    let _gate = match &a.dir {
        Some(d) => Some(Gate::open(&[Output::Folder("--dir", d)], &[])?),
        None => None,
    };
    ranges::within("--size (width)", w, 16, ranges::SIDE)?;
    ranges::within("--size (height)", h, 16, ranges::SIDE)?;
    let o = bench::BenchOptions {
        width: w,
        height: h,
        photos: a.photos,
        long_factor: a.long_factor,
        water_column: a.water_column,
        noise: a.noise,
        quality: a.quality,
        python: a.python,
        peer: a.peer,
        threads: a.threads,
        window: a.window,
        jpeg_quality: a.jpeg_quality,
        jpeg_subsampling: a.jpeg_subsampling,
        dir: a.dir,
        ..bench::BenchOptions::default()
    };
    let exe = std::env::current_exe()
        .map_err(|e| Error::Usage(format!("cannot find the abysslight binary: {e}")))?;
    let r = bench::run(&exe, &o, &|m| eprintln!("abysslight bench: {m}"))?;
    println!("{}", r.table());
    Ok(ExitCode::from(EXIT_OK))
}

fn simulate(a: SimulateArgs) -> Result<ExitCode, Error> {
    use abysslight::eval::simulate::MAX_FRAMES;
    let sim = abysslight::eval::simulate::Simulation {
        frames: a.frames,
        water_column: a.water_column,
        width: a.size.0,
        height: a.size.1,
        seed: a.seed,
        contamination: a.contamination,
        bit_depth: a.bit_depth,
        encode: a.encode,
        rig: a.rig,
        altitude: a.altitude,
        overlap: a.overlap,
        fov_deg: a.fov,
        noise: a.noise,
        beam_deg: a.beam,
        water: a.water,
        altitude_swing: a.altitude_swing,
        white_balance: a.white_balance,
        exposure: a.exposure,
        contamination_along: None,
    };
    // The flags' ranges (the library's, shared with the Python binding), before anything is written; the command
    // writes at least one water-column frame.
    sim.validate()?;
    ranges::within("--water-column", a.water_column, 1, MAX_FRAMES)?;
    let _gate = Gate::open(&[Output::Folder("--out", &a.out)], &[])?;
    let t = std::time::Instant::now();
    if a.truth_lighting {
        sim.render_with_lighting()?.write(&a.out)?;
    } else {
        sim.write(&a.out)?;
    }
    eprintln!(
        "abysslight: simulated {} survey photos and {} water-column frames in {:.1} s into {}",
        sim.frames,
        sim.water_column,
        t.elapsed().as_secs_f64(),
        a.out.display()
    );
    Ok(ExitCode::from(EXIT_OK))
}

fn evaluate(a: EvaluateArgs) -> Result<ExitCode, Error> {
    let sets: Vec<(String, PathBuf)> = a
        .sets
        .iter()
        .map(|s| match s.split_once('=') {
            Some((l, d)) => (l.to_string(), PathBuf::from(d)),
            None => {
                let p = PathBuf::from(s);
                let label = p
                    .file_name()
                    .map_or_else(|| s.clone(), |n| n.to_string_lossy().into_owned());
                (label, p)
            }
        })
        .collect();
    let settings = abysslight::eval::evaluate::EvalSettings {
        cell: a.cell,
        transfer: a.transfer,
        register: a.register.clone(),
        save_placements: a.save_placements.clone(),
        downsample: a.eval_downsample,
        mask: a.mask.clone(),
        ..Default::default()
    };
    settings.validate()?;
    let mut inputs: Vec<(&str, &std::path::Path)> = sets
        .iter()
        .map(|(_, d)| ("photo folder", d.as_path()))
        .collect();
    for (what, p) in [
        ("--truth folder", &a.truth),
        ("--placements file", &a.placements),
        ("--register folder", &a.register),
        ("--mask", &a.mask),
    ] {
        inputs.extend(p.as_deref().map(|p| (what, p)));
    }
    let mut outputs: Vec<Output> = a.json.iter().map(|j| Output::File("--json", j)).collect();
    outputs.extend(
        a.save_placements
            .as_deref()
            .map(|p| Output::File("--save-placements", p)),
    );
    let _gate = Gate::open(&outputs, &inputs)?;
    let ev = abysslight::eval::evaluate::evaluate(
        &sets,
        a.truth.as_deref(),
        a.placements.as_deref(),
        &settings,
    )?;
    if let Some(r) = &ev.registration {
        eprintln!(
            "abysslight: registered {} photos: {} of {} consecutive pairs matched{}",
            r.photos,
            r.accepted_pairs,
            r.pairs,
            r.median_ncc
                .map_or(String::new(), |v| format!(" (median correlation {v:.2})"))
        );
    }
    print!("{}", ev.table());
    for line in ev.legend() {
        eprintln!("abysslight: {line}");
    }
    for w in &ev.warnings {
        eprintln!("abysslight: warning: {w}");
    }
    // Written only where asked: a file in the current folder nobody asked for was overwritten by the next run.
    if let Some(json) = &a.json {
        ev.save_json(json)?;
        eprintln!("abysslight: scores written to {}", json.display());
    }
    Ok(ExitCode::from(EXIT_OK))
}

fn demo(a: DemoArgs) -> Result<ExitCode, Error> {
    let sim = abysslight::eval::simulate::Simulation {
        seed: a.seed,
        encode: a.encode,
        ..abysslight::eval::demo::demo_simulation()
    };
    let _gate = Gate::open(&[Output::Folder("--out", &a.out)], &[])?;
    let console = Console::new(false);
    let r = abysslight::eval::demo::run_demo(&a.out, &sim, &console)?;
    print!("{}", r.evaluation.table());
    for line in r.evaluation.legend() {
        eprintln!("abysslight: {line}");
    }
    eprintln!(
        "abysslight: demo done in {:.1} s: contact sheet {}, scores {}",
        r.seconds,
        r.sheet.display(),
        r.scores_md.display()
    );
    Ok(ExitCode::from(EXIT_OK))
}

fn sheet(a: SheetArgs) -> Result<ExitCode, Error> {
    ranges::within("--width", a.width, 16, 8192)?;
    ranges::within("--rows", a.rows, 1, 100)?;
    let _gate = Gate::open(
        &[Output::File("--sheet", &a.sheet)],
        &[
            ("survey folder", &a.survey),
            ("corrected folder", &a.corrected),
        ],
    )?;
    let (survey, corrected, swapped) =
        abysslight::run::pictures::sheet_folders(&a.survey, &a.corrected);
    if let Some(w) = swapped {
        eprintln!("abysslight: warning: {w}");
    }
    let (img, with_factors) =
        abysslight::run::pictures::before_after_sheet(&survey, &corrected, a.rows, a.width)?;
    abysslight::run::pictures::save_png(&img, &a.sheet)?;
    if with_factors {
        eprintln!(
            "abysslight: before/after sheet written to {} (input | corrected | F·C)",
            a.sheet.display()
        );
    } else {
        eprintln!(
            "abysslight: before/after sheet written to {} (input | corrected; for an F·C column run correct with \
             --save-factors)",
            a.sheet.display()
        );
    }
    Ok(ExitCode::from(EXIT_OK))
}

fn window(args: WindowArgs) -> Result<ExitCode, Error> {
    let w = choose_window(args.contamination, args.risk)?;
    println!("n = {}", w.n);
    println!("P_half = {:.6} ({:.3} %)", w.p_half, 100.0 * w.p_half);
    Ok(ExitCode::from(EXIT_OK))
}

/// The `abysslight` command with the process's arguments.
pub fn run() -> ExitCode {
    run_from(std::env::args_os())
}

/// The `abysslight` command with `args` (the first is the program's name).
pub fn run_from(args: impl IntoIterator<Item = std::ffi::OsString>) -> ExitCode {
    extras::survive_file_size_limit();
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() { EXIT_USAGE } else { EXIT_OK };
            let _ = e.print();
            return ExitCode::from(code);
        }
    };
    let result = match cli.command {
        Command::Correct(a) => match a.cruise.clone() {
            Some(c) => cluster::correct_cruise(*a, &c),
            None => correct(&a),
        },
        Command::MergeShards(a) => cluster::merge(a),
        Command::Window(a) => window(a),
        Command::Scatter(a) => scatter(a),
        Command::Bench(a) => bench(a),
        Command::Simulate(a) => simulate(a),
        Command::Evaluate(a) => evaluate(a),
        Command::Demo(a) => demo(a),
        Command::Sheet(a) => sheet(a),
        Command::Completions(a) => {
            extras::completions(a.shell, &mut Cli::command());
            Ok(ExitCode::from(EXIT_OK))
        }
        Command::Manpage(a) => extras::manpage(Cli::command(), a.command.as_deref()),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("abysslight: error: {e}");
            ExitCode::from(EXIT_USAGE)
        }
    }
}

/// `auto` (`None`) or a value `T` parses to; `example` names one in the error.
fn auto_or<T: std::str::FromStr>(s: &str, example: &str) -> Result<Option<T>, String> {
    if s.trim().eq_ignore_ascii_case("auto") {
        return Ok(None);
    }
    s.trim()
        .parse::<T>()
        .map(Some)
        .map_err(|_| format!("expected {example}, or auto, got {s:?}"))
}

/// `--backscatter-scale`: a number, or `None` for `auto`.
#[derive(Debug, Clone, Copy)]
struct ScaleArg(Option<f32>);

/// `--backscatter-scale`: `auto` or a number.
fn parse_scale(s: &str) -> Result<ScaleArg, String> {
    auto_or(s, "a number such as 0.8").map(ScaleArg)
}

/// `--near-window`: a number of photos, or `None` for `auto`.
#[derive(Debug, Clone, Copy)]
struct NearArg(Option<usize>);

/// `--near-window`: `auto` or a whole number of photos (0: off).
fn parse_near(s: &str) -> Result<NearArg, String> {
    auto_or(s, "a number of photos such as 5 (0: off)").map(NearArg)
}

/// `--window`: a number of photos, or `None` for `auto`.
#[derive(Debug, Clone, Copy)]
struct WindowArg(Option<usize>);

/// `--window`: `auto` or a whole (odd) number of photos.
fn parse_window(s: &str) -> Result<WindowArg, String> {
    auto_or(s, "an odd number of photos such as 15").map(WindowArg)
}

/// `--contamination`: a share of the pixels, or `None` for `auto`.
#[derive(Debug, Clone, Copy)]
struct ContaminationArg(Option<f64>);

/// `--contamination`: `auto` or a number (the range is checked with the other options).
fn parse_contamination(s: &str) -> Result<ContaminationArg, String> {
    auto_or(s, "a share of the pixels such as 0.3").map(ContaminationArg)
}

/// `--downsample`: a block size, or `None` for `auto`.
#[derive(Debug, Clone, Copy)]
struct BlocksArg(Option<usize>);

/// `--downsample`: `auto` or a whole number of pixels.
fn parse_blocks(s: &str) -> Result<BlocksArg, String> {
    auto_or(s, "a block size in pixels such as 8").map(BlocksArg)
}

/// `--transfer`: a curve, or `None` for `auto`.
#[derive(Debug, Clone, Copy)]
struct TransferArg(Option<Transfer>);

/// `--transfer`: `auto` or a curve (`srgb`, `linear`, `gamma:G`).
fn parse_transfer(s: &str) -> Result<TransferArg, String> {
    if s.trim().eq_ignore_ascii_case("auto") {
        return Ok(TransferArg(None));
    }
    s.parse::<Transfer>().map(|t| TransferArg(Some(t)))
}
