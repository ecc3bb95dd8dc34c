//! What would go wrong in a run, found before it starts (`correct --dry-run`): photos of another size, formats
//! mixed in one survey, too few photos for the window, two dives in one folder, not enough disk; and a
//! water-column folder that is the survey (checked by every run). Each check reads file names, sizes, modification
//! times and photo headers only (no photo is decoded); each returns what it found in words, or nothing.

use std::path::{Path, PathBuf};
use std::time::SystemTime;

use crate::io::{header_size, Entry};

/// A gap in the photos' capture times at least this long (and [`GAP_OVER_MEDIAN`] times the usual one) suggests
/// two dives in one folder: half an hour without a photo is a surfacing, a lift-off or another station.
pub(crate) const GAP_SECONDS: f64 = 1800.0;
/// How many times the median gap between consecutive photos a gap of [`GAP_SECONDS`] must also be.
pub(crate) const GAP_OVER_MEDIAN: f64 = 20.0;
/// A restart of the numbering counts only where the numbers rise over at least this many photos on either side.
pub(crate) const RUN_MIN: usize = 5;

/// Up to three names of `paths`, for a message.
fn examples<'a>(paths: impl Iterator<Item = &'a Path>) -> String {
    let names: Vec<String> = paths.take(3).map(|p| p.display().to_string()).collect();
    names.join(", ")
}

/// Photos whose header gives another size than the mission's `size` (they are skipped by the run), and photos
/// whose header cannot be read (they fail). Reads every header.
pub(crate) fn other_sizes(photos: &[Entry], size: Option<(usize, usize)>) -> Vec<String> {
    let Some((w, h)) = size else {
        return Vec::new();
    };
    let (mut other, mut unreadable) = (Vec::new(), Vec::new());
    for e in photos {
        match header_size(&e.path) {
            Ok(s) if s != (w, h) => other.push((e, s)),
            Ok(_) => {}
            Err(_) => unreadable.push(e),
        }
    }
    let mut found = Vec::new();
    if !other.is_empty() {
        let list: Vec<String> = other
            .iter()
            .take(3)
            .map(|(e, (ow, oh))| format!("{} ({ow}x{oh})", e.relative.display()))
            .collect();
        found.push(format!(
            "{} photo(s) of another size than the mission's {w}x{h} (the size of most of the first photos) would \
             be skipped: {}{}",
            other.len(),
            list.join(", "),
            if other.len() > 3 { ", ..." } else { "" }
        ));
    }
    if !unreadable.is_empty() {
        found.push(format!(
            "{} photo(s) whose header cannot be read (damaged or not photos) would fail: {}",
            unreadable.len(),
            examples(unreadable.iter().map(|e| e.relative.as_path()))
        ));
    }
    found
}

/// Water-column frames of another size than the mission's photos `size` (`S` cannot be subtracted from photos of
/// another size: left out of `S`, and with none of the mission's size the run stops), and a `--scatter` image of
/// another size. Reads every frame's header.
pub(crate) fn water_sizes(
    frames: &[Entry],
    scatter: Option<&Path>,
    size: Option<(usize, usize)>,
    dir: Option<&Path>,
) -> Vec<String> {
    let Some((w, h)) = size else {
        return Vec::new();
    };
    if let Some(p) = scatter {
        return match header_size(p) {
            Ok((sw, sh)) if (sw, sh) != (w, h) => vec![format!(
                "the scatter image {} is {sw}x{sh}, the survey photos {w}x{h}: the run would stop; give the \
                 scatter image of a run on photos of this size, or --water-column",
                p.display()
            )],
            _ => Vec::new(),
        };
    }
    let sizes: Vec<(usize, usize)> = frames
        .iter()
        .filter_map(|e| header_size(&e.path).ok())
        .collect();
    let other: Vec<&(usize, usize)> = sizes.iter().filter(|&&s| s != (w, h)).collect();
    let Some((ow, oh)) = other.first() else {
        return Vec::new();
    };
    let dir = dir.map_or(String::new(), |d| format!(" in {}", d.display()));
    if other.len() == sizes.len() {
        vec![format!(
            "the water-column frames{dir} are {ow}x{oh}, the survey photos {w}x{h}: S cannot be subtracted from \
             photos of another size, and the run would stop; give frames of the survey camera at the survey's \
             size (the descent of the same dive), or no --water-column (S = 0)"
        )]
    } else {
        vec![format!(
            "{} of {} water-column frames{dir} are of another size than the survey's {w}x{h} (such as {ow}x{oh}): \
             left out of S",
            other.len(),
            sizes.len()
        )]
    }
}

/// The file format of a photo by its name: JPEG, PNG or TIFF.
fn format_name(p: &Path) -> &'static str {
    match p
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("jpg" | "jpeg") => "JPEG",
        Some("png") => "PNG",
        _ => "TIFF",
    }
}

/// More than one file format in one survey (by file name): the camera curve is read from the first photo and
/// taken for all of them, and a JPEG is usually sRGB where a PNG or TIFF is often linear.
pub(crate) fn mixed_formats(photos: &[Entry]) -> Option<String> {
    let mut counts: Vec<(&str, usize, &Path)> = Vec::new();
    for e in photos {
        let f = format_name(&e.path);
        match counts.iter_mut().find(|(g, _, _)| *g == f) {
            Some((_, n, _)) => *n += 1,
            None => counts.push((f, 1, &e.relative)),
        }
    }
    (counts.len() > 1).then(|| {
        let parts: Vec<String> = counts
            .iter()
            .map(|(f, n, first)| format!("{n} {f} (first {})", first.display()))
            .collect();
        format!(
            "the survey mixes formats: {}. One camera curve (--transfer) is taken for all of them, read from the \
             first photo with --transfer auto, though JPEGs are usually sRGB and PNG or TIFF often linear; \
             correct each format on its own, or check that they come from one camera",
            parts.join(", ")
        )
    })
}

/// Fewer survey photos than the window `n`: every window is then the whole survey and the median's breakdown
/// probability is that of the shorter window.
pub(crate) fn too_few(total: usize, n: usize, auto: bool) -> Option<String> {
    if auto {
        let longest = crate::method::stretch::longest_window(total);
        if longest < n {
            return Some(format!(
                "the survey has {total} photo(s): every window is at most {longest} photo(s), fewer than the {n} a \
                 stretch of clean seafloor takes; clutter at one place in {} of them stays in F (the run flags \
                 photos whose window holds too few independent samples); give more photos",
                longest.div_ceil(2)
            ));
        }
        // A short mission (MBARI's 12 frames): the survey that chooses the windows measures each photo against
        // the photos around it, more than the mission holds.
        let ahead = crate::method::survey::LOOK_AHEAD;
        return (total < ahead).then(|| {
            format!(
                "the survey has {total} photo(s), fewer than the {ahead} --window auto looks ahead over to judge \
                 the ground and the camera's motion: its windows are at most {longest} photo(s), and under a slow \
                 camera they hold too few independent views of the seafloor for F to leave the scene out (the run \
                 flags such photos few-samples); only the run can tell, from the photos themselves; give more \
                 photos of the dive if there are any"
            )
        });
    }
    (total < n).then(|| {
        format!(
            "the survey has {total} photo(s), fewer than the window n = {n}: every photo's F would be the median of \
             all {total}, which breaks down more often (clutter at one place in {} of them stays in F); give \
             more photos, or a smaller --window if the seafloor is clean",
            total.div_ceil(2)
        )
    })
}

/// The last number in a file name's stem (`IMG_0042.jpg` → 42), if it has one.
fn last_number(p: &Path) -> Option<u64> {
    let stem = p.file_stem()?.to_str()?;
    let end = stem.rfind(|c: char| c.is_ascii_digit())? + 1;
    let start = stem[..end]
        .rfind(|c: char| !c.is_ascii_digit())
        .map_or(0, |i| i + 1);
    let digits = &stem[start..end];
    digits[digits.len().saturating_sub(18)..].parse().ok()
}

/// Where the numbering of the file names starts again: the indices `i` where the last number in the name falls
/// below the previous photo's, when it does so at one to three places and rises over at least [`RUN_MIN`] photos
/// between them (random numbers, such as hashes in names, fall at about every other photo and are not taken for
/// a numbering). Empty when a name has no number.
pub(crate) fn numbering_restarts(photos: &[Entry]) -> Vec<usize> {
    let Some(numbers) = photos
        .iter()
        .map(|e| last_number(&e.path))
        .collect::<Option<Vec<u64>>>()
    else {
        return Vec::new();
    };
    let drops: Vec<usize> = (1..numbers.len())
        .filter(|&i| numbers[i] < numbers[i - 1])
        .collect();
    let mut bounds = vec![0];
    bounds.extend(&drops);
    bounds.push(numbers.len());
    let long_runs = bounds.windows(2).all(|b| b[1] - b[0] >= RUN_MIN);
    if (1..=3).contains(&drops.len()) && long_runs {
        drops
    } else {
        Vec::new()
    }
}

/// The largest gap between consecutive capture times (`secs`, seconds, in photo order), with the index of the
/// photo after it, when it is at least [`GAP_SECONDS`] and [`GAP_OVER_MEDIAN`] times the median gap. A photo
/// taken before the previous one counts by the size of the jump.
pub(crate) fn time_gap(secs: &[f64]) -> Option<(usize, f64)> {
    let mut gaps: Vec<(usize, f64)> = (1..secs.len())
        .map(|i| (i, (secs[i] - secs[i - 1]).abs()))
        .collect();
    let &(at, largest) = gaps.iter().max_by(|a, b| a.1.total_cmp(&b.1))?;
    gaps.sort_by(|a, b| a.1.total_cmp(&b.1));
    let median = gaps[gaps.len() / 2].1;
    (largest >= GAP_SECONDS && largest >= GAP_OVER_MEDIAN * median).then_some((at, largest))
}

/// The capture time a file name carries (`image_D2023-06-03T16-27-38-624235Z.jpg`, `IMG_20230603_162738.jpg`,
/// `2023-06-03 16:27:38.png`): seconds since 1970 (UTC as written), from the first date and time in the name
/// written year, month, day, hour, minute, second, each field of two digits (the year four), separated by at
/// most one of `-`, `_`, `T`, `:`, `.` or a space. `None` when the name has none.
pub(crate) fn name_time(p: &Path) -> Option<f64> {
    let b = p.file_name()?.to_str()?.as_bytes();
    let sep = |c: u8| matches!(c, b'-' | b'_' | b'T' | b':' | b'.' | b' ');
    'start: for i in 0..b.len() {
        if i > 0 && b[i - 1].is_ascii_digit() {
            continue;
        }
        let (mut j, mut f) = (i, [0u32; 6]);
        for (k, width) in [4usize, 2, 2, 2, 2, 2].into_iter().enumerate() {
            if k > 0 && j < b.len() && sep(b[j]) {
                j += 1;
            }
            let digits = b
                .get(j..j + width)
                .filter(|d| d.iter().all(u8::is_ascii_digit));
            let Some(d) = digits else { continue 'start };
            f[k] = d.iter().fold(0, |v, c| v * 10 + (c - b'0') as u32);
            j += width;
        }
        let [y, mo, d, h, mi, sec] = f;
        let valid = (1970..2200).contains(&y)
            && (1..=12).contains(&mo)
            && (1..=31).contains(&d)
            && h < 24
            && mi < 60
            && sec < 61;
        if valid {
            match crate::io::navigation::utc_seconds(y as i32, mo, d, h, mi, sec) {
                Some(t) => return Some(t),
                None => continue 'start,
            }
        }
    }
    None
}

/// The photos' capture times in seconds and where they come from: the times in their file names when every name
/// has one ([`name_time`]), else the files' modification times (copies may have lost them: then no gap shows).
fn capture_times(photos: &[Entry]) -> Option<(Vec<f64>, &'static str)> {
    if let Some(t) = photos.iter().map(|e| name_time(&e.path)).collect() {
        return Some((t, "the capture times in the file names"));
    }
    let secs = |t: SystemTime| match t.duration_since(SystemTime::UNIX_EPOCH) {
        Ok(d) => d.as_secs_f64(),
        Err(e) => -e.duration().as_secs_f64(),
    };
    let t = photos
        .iter()
        .map(|e| {
            std::fs::metadata(&e.path)
                .and_then(|m| m.modified())
                .ok()
                .map(secs)
        })
        .collect::<Option<Vec<f64>>>()?;
    Some((t, "the file times"))
}

/// The folders (relative to the survey) holding at least [`RUN_MIN`] photos each, with their counts, when there
/// are two or more.
pub(crate) fn photo_folders(photos: &[Entry]) -> Vec<(String, usize)> {
    let mut folders: Vec<(String, usize)> = Vec::new();
    for e in photos {
        let f = e
            .relative
            .parent()
            .map_or(String::new(), |p| p.display().to_string());
        match folders.iter_mut().find(|(g, _)| *g == f) {
            Some((_, n)) => *n += 1,
            None => folders.push((f, 1)),
        }
    }
    folders.retain(|(_, n)| *n >= RUN_MIN);
    if folders.len() < 2 {
        folders.clear();
    }
    folders
}

/// Signs of two dives in one survey, as one message: photos in several folders ([`photo_folders`]), the
/// file-name numbering starting again ([`numbering_restarts`]), a gap of half an hour or more in the capture
/// times ([`time_gap`], [`capture_times`]).
/// A window that spans two dives mixes their lighting.
pub(crate) fn two_dives(photos: &[Entry]) -> Option<String> {
    let mut signs = Vec::new();
    let folders = photo_folders(photos);
    if !folders.is_empty() {
        let list: Vec<String> = folders
            .iter()
            .take(4)
            .map(|(f, n)| format!("{f}/ {n}"))
            .collect();
        signs.push(format!(
            "photos in {} folders ({})",
            folders.len(),
            list.join(", ")
        ));
    }
    let times = capture_times(photos);
    // Numbers in names that carry the time are the time of day (they start again at midnight): the gap in the
    // times is the sign then.
    let timed = times
        .as_ref()
        .is_some_and(|(_, from)| from.contains("names"));
    if let Some(&first) = numbering_restarts(photos).first().filter(|_| !timed) {
        signs.push(format!(
            "the numbering of the file names starts again at {} (after {})",
            photos[first].relative.display(),
            photos[first - 1].relative.display()
        ));
    }
    if let Some(((at, gap), from)) = times
        .as_ref()
        .and_then(|(t, from)| Some((time_gap(t)?, from)))
    {
        signs.push(format!(
            "{from} jump by {:.1} h between {} and {}",
            gap / 3600.0,
            photos[at - 1].relative.display(),
            photos[at].relative.display()
        ));
    }
    (!signs.is_empty()).then(|| {
        format!(
            "two dives (or cameras) in one survey? {}. The windows where they meet would mix their lighting: \
             correct each dive on its own (one --survey each); if this is one dive, ignore this",
            signs.join("; ")
        )
    })
}

/// What identifies a file whatever the path that names it: device and inode on Unix (hard links, bind mounts and
/// links alike), the resolved path elsewhere.
fn file_key(p: &Path) -> Option<String> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let m = std::fs::metadata(p).ok()?;
        Some(format!("{}:{}", m.dev(), m.ino()))
    }
    #[cfg(not(unix))]
    {
        Some(std::fs::canonicalize(p).ok()?.display().to_string())
    }
}

/// A water-column folder that is the survey folder, lies in it or holds it (both are searched recursively), or
/// whose frames are survey photos (the same files under other names: links, a copy by hard links): `S` would then
/// hold the seafloor itself and the correction would remove it, or the frames would be corrected as survey photos.
/// `survey_photos` are the photos the run found; none when streaming (the folders are still compared).
pub(crate) fn water_is_survey(
    water: &Path,
    survey: &Path,
    survey_photos: &[Entry],
) -> Option<String> {
    let real = |p: &Path| std::fs::canonicalize(p).ok();
    let (w, s) = (water.display(), survey.display());
    let (rw, rs): (PathBuf, PathBuf) = (real(water)?, real(survey)?);
    if rw == rs {
        return Some(format!(
            "--water-column {w} is the --survey folder: S would be the median of the survey photos (the seafloor \
             itself) and the correction would remove the seafloor; give the frames taken in open water (the \
             descent), or no --water-column"
        ));
    }
    if rw.starts_with(&rs) {
        return Some(format!(
            "--water-column {w} lies inside the --survey folder {s}, which is searched with its subfolders: its \
             frames would also be corrected as survey photos and enter the seafloor's windows; move them out"
        ));
    }
    if rs.starts_with(&rw) {
        return Some(format!(
            "the --survey folder {s} lies inside --water-column {w}, which is searched with its subfolders: the \
             survey photos would enter S; give the folder of the water-column frames alone"
        ));
    }
    let keys: std::collections::HashSet<String> = survey_photos
        .iter()
        .filter_map(|e| file_key(&e.path))
        .collect();
    let frames = crate::io::find_photos(water).ok()?.photos;
    let shared: Vec<&Entry> = frames
        .iter()
        .filter(|e| file_key(&e.path).is_some_and(|k| keys.contains(&k)))
        .collect();
    (!shared.is_empty()).then(|| {
        format!(
            "{} of the {} frames in --water-column {w} are survey photos (the same files: {}): S would hold the \
             seafloor and the correction would remove it; give the frames taken in open water",
            shared.len(),
            frames.len(),
            examples(shared.iter().map(|e| e.relative.as_path()))
        )
    })
}

/// Free bytes for an unprivileged user on the file system that holds `path` (or its nearest existing parent).
pub(crate) fn free_space(path: &Path) -> Option<u64> {
    let mut p = path;
    while !p.exists() {
        p = match p.parent()? {
            q if q.as_os_str().is_empty() => Path::new("."),
            q => q,
        };
    }
    free_on(p)
}

#[cfg(unix)]
fn free_on(p: &Path) -> Option<u64> {
    let s = rustix::fs::statvfs(p).ok()?;
    Some(s.f_bavail.saturating_mul(s.f_frsize))
}

#[cfg(not(unix))]
fn free_on(_: &Path) -> Option<u64> {
    None
}

/// Bytes `--save-factors` writes for one photo of `width`×`height` with blocks of `k`: its `F·C` as a 16-bit PNG
/// of one pixel per block and an 8-bit preview at least 640 pixels wide, both counted uncompressed (three
/// channels), an upper bound.
pub(crate) fn factor_bytes(width: usize, height: usize, k: usize) -> u64 {
    let (bw, bh) = (width.div_ceil(k.max(1)), height.div_ceil(k.max(1)));
    let pw = bw.max(crate::run::pictures::PREVIEW_MIN_WIDTH as usize);
    let ph = (bh * pw).div_ceil(bw.max(1));
    (bw * bh * 3 * 2 + pw * ph * 3) as u64
}

/// Megabytes or gigabytes, for a message.
pub(crate) fn size_text(bytes: u64) -> String {
    if bytes >= 10_000_000_000 {
        format!("{:.0} GB", bytes as f64 / 1e9)
    } else if bytes >= 1_000_000_000 {
        format!("{:.1} GB", bytes as f64 / 1e9)
    } else {
        format!("{:.1} MB", bytes as f64 / 1e6)
    }
}

/// The disk a run needs (`outputs` bytes, `factors` of them for `--save-factors`) against `free` bytes on the
/// output's file system: a problem when it does not fit.
pub(crate) fn disk(outputs: u64, factors: u64, free: Option<u64>, out: &Path) -> Option<String> {
    let need = outputs + factors;
    let free = free?;
    (need > free).then(|| {
        format!(
            "the outputs need about {}{} but only {} are free on the file system of {}: the writes would fail \
             once the disk is full",
            size_text(need),
            if factors > 0 {
                format!(" ({} of them for --save-factors)", size_text(factors))
            } else {
                String::new()
            },
            size_text(free),
            out.display()
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entries(names: &[&str]) -> Vec<Entry> {
        names
            .iter()
            .map(|n| Entry {
                path: Path::new("/nowhere").join(n),
                relative: n.into(),
            })
            .collect()
    }

    #[test]
    fn last_number_is_the_last_run_of_digits_of_the_stem() {
        let n = |s: &str| last_number(Path::new(s));
        assert_eq!(n("IMG_0042.jpg"), Some(42));
        assert_eq!(n("dive2/img12b.png"), Some(12));
        assert_eq!(n("2023-06-04T16-33-11.jpg"), Some(11));
        assert_eq!(n("nodigits.jpg"), None);
        assert_eq!(n("x123456789012345678901234.jpg"), Some(789012345678901234));
    }

    #[test]
    fn a_restarted_numbering_is_found_and_hashes_are_not() {
        let names: Vec<String> = (1..=8)
            .map(|i| format!("a/IMG_{i:04}.jpg"))
            .chain((1..=6).map(|i| format!("b/IMG_{i:04}.jpg")))
            .collect();
        let refs: Vec<&str> = names.iter().map(String::as_str).collect();
        assert_eq!(numbering_restarts(&entries(&refs)), vec![8]);
        // One numbering through: nothing.
        let one: Vec<String> = (1..=14).map(|i| format!("IMG_{i:04}.jpg")).collect();
        let refs: Vec<&str> = one.iter().map(String::as_str).collect();
        assert!(numbering_restarts(&entries(&refs)).is_empty());
        // Numbers from a hash (xorshift): they fall at many places; nothing.
        let mut x = 88172645463325252u64;
        let hashed: Vec<String> = (0..30)
            .map(|i| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                format!("img{i:03}.rf.{}.jpg", x % 1_000_000)
            })
            .collect();
        let refs: Vec<&str> = hashed.iter().map(String::as_str).collect();
        assert!(numbering_restarts(&entries(&refs)).is_empty());
        // A short run (a stray file) is not a second dive.
        let stray = [
            "IMG_0005.jpg",
            "IMG_0001.jpg",
            "IMG_0002.jpg",
            "IMG_0003.jpg",
        ];
        assert!(numbering_restarts(&entries(&stray)).is_empty());
    }

    #[test]
    fn a_gap_of_hours_among_seconds_is_found() {
        let mut times: Vec<f64> = (0..10).map(|i| 2.0 * i as f64).collect();
        assert_eq!(time_gap(&times), None);
        times.extend((0..10).map(|i| 7200.0 + 2.0 * i as f64));
        assert_eq!(time_gap(&times), Some((10, 7200.0 - 18.0)));
        // A clock set back by an hour between two dives counts too.
        let back: Vec<f64> = [100.0, 102.0, 104.0, 106.0, 100.0 - 3600.0, 98.0 - 3600.0].to_vec();
        assert_eq!(time_gap(&back).map(|g| g.0), Some(4));
        // Photos an hour apart each (a slow time-lapse): the gap is the usual one, nothing.
        let slow: Vec<f64> = (0..10).map(|i| 4000.0 * i as f64).collect();
        assert_eq!(time_gap(&slow), None);
        assert_eq!(time_gap(&times[..1]), None);
    }

    #[test]
    fn name_time_reads_the_date_and_time_of_a_file_name() {
        // Seconds since 1970 by Python's calendar.timegm, an independent calendar.
        let t = |s: &str| name_time(Path::new(s));
        let nephrops =
            "image_D2023-06-03T16-27-38-624235Z_0_jpg.rf.0f602c5d89dc6317d3a2261b942229b6.jpg";
        assert_eq!(t(nephrops), Some(1685809658.0));
        assert_eq!(t("dive/IMG_20230603_162738.jpg"), Some(1685809658.0));
        assert_eq!(t("2023-06-03 16:27:38.png"), Some(1685809658.0));
        assert_eq!(t("20000229000000.tif"), Some(951782400.0));
        assert_eq!(t("cam2_2024-12-31T23:59:59.jpg"), Some(1735689599.0));
        // No date, or digits that are not one (month 13, a longer number, a counter).
        for none in [
            "IMG_0042.jpg",
            "20231303162738.jpg",
            "20230230162738.jpg",
            "120230603162738.jpg",
            "x.jpg",
        ] {
            assert_eq!(t(none), None, "{none}");
        }
    }

    #[test]
    fn two_dives_in_one_folder_by_the_times_in_the_names() {
        let names: Vec<String> = (0..8)
            .map(|i| format!("D2023-06-03T16-27-{:02}.jpg", 10 + 2 * i))
            .chain((0..8).map(|i| format!("D2023-06-04T16-32-{:02}.jpg", 10 + 2 * i)))
            .collect();
        let refs: Vec<&str> = names.iter().map(String::as_str).collect();
        let m = two_dives(&entries(&refs)).unwrap();
        assert!(
            m.contains("24.1 h") && m.contains("D2023-06-04T16-32-10.jpg"),
            "{m}"
        );
        assert!(
            !m.contains("numbering"),
            "times in names are not a numbering: {m}"
        );
        assert!(two_dives(&entries(&refs[..8])).is_none());
    }

    #[test]
    fn a_water_column_that_is_the_survey_is_found() {
        let d = tempfile::tempdir().unwrap();
        let (survey, water) = (d.path().join("survey"), d.path().join("water"));
        std::fs::create_dir_all(survey.join("sub")).unwrap();
        std::fs::create_dir_all(&water).unwrap();
        std::fs::write(survey.join("a.png"), b"x").unwrap();
        std::fs::write(water.join("w.png"), b"y").unwrap();
        let photos = crate::io::find_photos(&survey).unwrap().photos;
        assert!(water_is_survey(&water, &survey, &photos).is_none());
        let same = water_is_survey(&survey.join("sub/.."), &survey, &photos).unwrap();
        assert!(same.contains("is the --survey folder"), "{same}");
        assert!(water_is_survey(&survey.join("sub"), &survey, &photos)
            .unwrap()
            .contains("lies inside"));
        assert!(water_is_survey(d.path(), &survey, &photos)
            .unwrap()
            .contains("lies inside --water-column"));
        // The same file under another name (a hard link) is found; a copy of other bytes is not.
        std::fs::hard_link(survey.join("a.png"), water.join("w2.png")).unwrap();
        let m = water_is_survey(&water, &survey, &photos).unwrap();
        assert!(
            m.contains("1 of the 2 frames") && m.contains("w2.png"),
            "{m}"
        );
    }

    #[test]
    fn disk_compares_the_need_with_the_free_space() {
        let out = Path::new("out");
        assert!(disk(100, 0, Some(1000), out).is_none());
        assert!(disk(100, 0, None, out).is_none());
        let m = disk(800, 300, Some(1000), out).unwrap();
        assert!(m.contains("--save-factors"), "{m}");
        // 4000x3000 with blocks of 8: 500x375 blocks (1,125,000 bytes) and a 640x480 preview (921,600 bytes).
        assert_eq!(factor_bytes(4000, 3000, 8), 500 * 375 * 6 + 640 * 480 * 3);
        assert!(free_space(&std::env::temp_dir().join("not/yet/made")).is_some_and(|f| f > 0));
    }

    #[test]
    fn formats_and_window() {
        assert!(mixed_formats(&entries(&["a.jpg", "b.JPEG"])).is_none());
        let m = mixed_formats(&entries(&["a.jpg", "b.png", "c.jpg"])).unwrap();
        assert!(m.contains("2 JPEG") && m.contains("1 PNG"), "{m}");
        assert!(too_few(7, 7, false).is_none());
        assert!(too_few(4, 7, false).unwrap().contains("n = 7"));
        // Under auto: a window as long as the mission allows (the largest odd number of its photos), never "n = 7".
        assert!(too_few(25, 7, true).is_none());
        let short = too_few(12, 7, true).unwrap();
        assert!(
            short.contains("12 photo(s)")
                && short.contains("at most 11")
                && short.contains("few-samples"),
            "{short}"
        );
        let four = too_few(4, 7, true).unwrap();
        assert!(
            four.contains("at most 3 photo(s)") && !four.contains("n = 7"),
            "{four}"
        );
    }
}
