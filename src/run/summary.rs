//! The end of a run in words: what `abysslight correct` prints after the last photo and Python's `correct()` logs,
//! from the run's [`Report`] (one text, so that the two never say different things).

use std::path::Path;

use crate::report::Report;
use crate::run::options::Options;

/// How many flagged photos the closing summary names.
const FLAGGED_NAMED: usize = 5;

/// The closing lines of a run (each without the `abysslight: ` prefix): photos corrected and failed, windows by
/// altitude, the flags raised, the first flagged photos by name and reason and where to look, floored pixels.
/// `out`: the output folder of a batch run (where `overview.png` and `flagged.png` are looked for).
pub fn lines(report: &Report, opts: &Options, out: Option<&Path>) -> Vec<String> {
    let mut lines = vec![format!(
        "{} of {} photos corrected in {:.1} s ({} failed); report: {}",
        report.corrected,
        report.survey_photos,
        report.elapsed_s,
        report.failed + report.water_column_failed,
        report
            .report_path
            .as_deref()
            .unwrap_or(Path::new("-"))
            .display()
    )];
    if let (Some(n), Some(log)) = (report.window.by_altitude, &opts.navigation) {
        let photos = report.frames.len();
        lines.push(format!(
            "windows by altitude ({}): {n} of {photos} photos took theirs among the photos lit from the nearest \
             heights{}",
            log.display(),
            match photos - n {
                0 => String::new(),
                _ => "; the others kept the window over time (the altitude spanned less than 15 % of it, or was \
                      not in the log)"
                    .into(),
            }
        ));
    }
    lines.push(report.monitor.line(report.frames.len()));
    lines.extend(flagged_lines(report, report.options.survey.as_deref(), out));
    if report.floored_pixels > 0 {
        lines.push(format!(
            "{} pixels had F below --factor-floor {} (dark corners; their gain was capped)",
            report.floored_pixels, opts.factor_floor
        ));
    }
    lines
}

/// Survey photos flagged as likely wrong.
pub fn flagged(report: &Report) -> usize {
    report
        .frames
        .iter()
        .filter(|f| !f.health.flags.is_empty())
        .count()
}

/// The first flagged photos by name and reason, and where to look.
fn flagged_lines(report: &Report, survey: Option<&Path>, out: Option<&Path>) -> Vec<String> {
    let flagged: Vec<_> = report
        .frames
        .iter()
        .filter(|f| !f.health.flags.is_empty())
        .collect();
    if flagged.is_empty() {
        return Vec::new();
    }
    let mut lines = Vec::new();
    for f in flagged.iter().take(FLAGGED_NAMED) {
        lines.push(format!(
            "  flagged #{} {}: {}",
            f.index + 1,
            // Relative to the survey folder: the name the user knows (and the output's), without a long prefix.
            survey
                .and_then(|s| f.input.strip_prefix(s).ok())
                .unwrap_or(&f.input)
                .display(),
            f.health
                .flags
                .iter()
                .map(|f| f.to_string())
                .collect::<Vec<_>>()
                .join("; ")
        ));
    }
    if flagged.len() > FLAGGED_NAMED {
        lines.push(format!(
            "  ... and {} more (every one is in the report)",
            flagged.len() - FLAGGED_NAMED
        ));
    }
    let mut look = Vec::new();
    if let Some(r) = &report.report_path {
        look.push(format!("{} (frames[].health.flags)", r.display()));
    }
    if let Some(out) = out {
        for pic in ["overview.png", "flagged.png"] {
            let p = out.join("_abysslight").join(pic);
            if p.is_file() {
                look.push(p.display().to_string());
            }
        }
    }
    if !look.is_empty() {
        lines.push(format!("  where to look: {}", look.join(", ")));
    }
    lines
}
