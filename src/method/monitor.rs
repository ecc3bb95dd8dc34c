//! Breakdown monitoring: the method's assumptions fail silently (more than half of a window contaminated, a
//! seafloor colour change absorbed into `F`), so every photo gets a few health figures and a flag with a reason
//! when its estimate is likely wrong. The paper: a seafloor colour change "can only be detected by monitoring the
//! multiplicative image".

use serde::{Deserialize, Serialize};

use crate::method::members::null_is_nan;

use crate::method::raster::Raster;

/// Thresholds for the flags.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Thresholds {
    /// Contamination estimate above which a photo is flagged (the median breaks at 0.5).
    pub contamination: f32,
    /// Relative change of `F` from the previous photo above which a photo is flagged...
    pub factor_change: f32,
    /// ...when it is also this many times the typical (median) change so far.
    pub factor_change_ratio: f32,
    /// Relative change of a channel's share of `F` against what the mission so far predicts from `F`'s level
    /// (for a channel with less than the average share: in units of the average), above which a photo is flagged.
    pub colour_shift: f32,
    /// A block counts as contaminated when its corrected value is off the seafloor colour by this share.
    pub block_deviation: f32,
    /// Roughness of `F` above which a photo is flagged (see [`roughness`]).
    pub roughness: f32,
    /// Share of the photo's texture kept by the correction below which `F` is taken to hold the scene. 0.2: MBARI
    /// midwater (no seafloor) keeps 0.06–0.12; sound abyssal dives of the matrix keep 0.23 and more (their block
    /// images' fine structure is largely the light's steep fall-off, which the correction rightly removes; 0.45,
    /// the threshold before, flagged every photo of four of the twelve dives).
    pub texture_kept: f32,
    /// Relative level of a photo against its window's `M` beyond which (either way) it is an exposure jump.
    pub exposure_jump: f32,
    /// Share of the photo's texture kept by the correction above which the correction added structure: `F` holds
    /// dark objects the window saw at the same place in most of its photos (burrows under a slow sledge), and
    /// the corrected photo shows their bright inverse ghosts. 1.15: on Nephrops run 1627 its ghost photo 64 keeps
    /// 1.33 with the window 7 and 1.21 with the window 11, the photos without ghosts at most 1.14; the held-out
    /// nodule fields and run 1632 at most 1.02.
    pub structure_added: f32,
    /// The photo's lights against its window's `M` ([`Health::lights_misfit`], log units) above which the
    /// correction is taken to leave the lights' pattern. 0.07, chosen on the randomized family's tuning dives of both
    /// simulators (docs/results.md) as the lowest, in steps of 0.01, that flags no more than 10 % of their good
    /// photos on either (0.06: 13 % of ours); the figure also holds the seafloor's texture.
    pub lights_misfit: f32,
}

impl Default for Thresholds {
    fn default() -> Self {
        Thresholds {
            contamination: 0.4,
            factor_change: 0.15,
            factor_change_ratio: 4.0,
            colour_shift: 0.1,
            block_deviation: 0.5,
            roughness: 0.12,
            texture_kept: 0.2,
            exposure_jump: 0.25,
            structure_added: 1.15,
            lights_misfit: 0.07,
        }
    }
}

/// Why a photo's correction is likely wrong. In `report.json` each flag is written as `{"kind": "...", "message":
/// "..."}`: `kind` is a stable kebab-case name for scripts ([`Flag::kind`]), `message` the explanation for people
/// (the [`Display`](std::fmt::Display) text, which may be reworded).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Flag {
    /// More of the photo is off the seafloor colour than the median can take (it breaks down at 50 %).
    Contamination {
        /// Share of blocks off the seafloor colour, after the photo's overall level is removed.
        share: f32,
    },
    /// `F` jumped from the previous photo (altitude or attitude jump, or a seafloor change).
    FactorChange {
        /// Mean relative change of `F`.
        change: f32,
        /// With a navigation log: the previous photo's altitude and this one's, metres.
        altitude: Option<(f32, f32)>,
    },
    /// `F`'s colour balance moved away from what its overall level predicts (seafloor or water colour change).
    ColourShift {
        /// Largest relative change of a channel's share.
        shift: f32,
    },
    /// `F` holds the scene instead of only the lighting: the window holds too little seafloor at some pixels, or
    /// the camera hardly moves.
    SceneInFactor {
        /// Fine structure of `F` (its roughness).
        roughness: f32,
        /// Share of the photo's fine structure left after the correction (see `PhotoFit`).
        texture_kept: f32,
    },
    /// The whole photo is brighter or darker than its window predicts while the lighting pattern stays: an
    /// exposure (gain, shutter, strobe) jump of this photo.
    ExposureJump {
        /// The photo's level relative to its window's `M` (1: as predicted).
        level: f32,
    },
    /// The camera hardly moves: over a window the ground moves less than a quarter of the frame, so `F` holds
    /// the scene (the method needs a moving camera).
    CameraStill {
        /// Ground moved over a window, as a share of the frame's short side.
        span: f32,
    },
    /// The correction added structure instead of removing the lights' (see `Thresholds::structure_added`):
    /// bright inverse ghosts of objects the window saw at the same place in most of its photos.
    StructureAdded {
        /// Share of the photo's fine structure after the correction (above 1: added).
        texture_kept: f32,
        /// The photo's window.
        window: usize,
        /// A longer window to try, one the mission holds (`None`: none; the engine leaves out what it does not
        /// hold).
        longer: Option<usize>,
        /// The photo's level against its window's where it jumped by more than
        /// `Thresholds::exposure_jump`: the structure came in with the jump, not with a slow camera.
        exposure: Option<f32>,
        /// Whether exposure levelling ran (`false`: turned off, and turning it on is the advice for a jump).
        levelled: bool,
    },
    /// The lights' shape in the photo differs from its window's `M`: the lighting changed along the window (the
    /// altitude swings, the vehicle pitches or rolls, a light dims) and the correction leaves its pattern.
    LightsMisfit {
        /// [`Health::lights_misfit`].
        misfit: f32,
    },
    /// Fewer photos in the mission than the window: every `F` is the median of all of them.
    ShortMission {
        /// Photos in the mission.
        photos: usize,
        /// The window `n`.
        window: usize,
    },
    /// The window chosen per stretch holds fewer independent samples than its quantile needs (the camera moves
    /// less than the dark objects' extent between photos, or the mission is too short): `F` may hold the scene.
    FewSamples {
        /// Independent samples the window holds.
        samples: usize,
        /// Independent samples its quantile needs.
        needed: usize,
        /// The window's photos.
        window: usize,
        /// The window is the whole mission (it could not grow further).
        whole_mission: bool,
    },
}

impl Flag {
    /// Stable kebab-case name of the kind of flag (what `report.json` writes as `kind`).
    pub fn kind(&self) -> &'static str {
        match self {
            Flag::Contamination { .. } => "contamination",
            Flag::FactorChange { .. } => "factor-change",
            Flag::ColourShift { .. } => "colour-shift",
            Flag::SceneInFactor { .. } => "scene-in-factor",
            Flag::ExposureJump { .. } => "exposure-jump",
            Flag::CameraStill { .. } => "camera-still",
            Flag::StructureAdded { .. } => "structure-added",
            Flag::LightsMisfit { .. } => "lights-misfit",
            Flag::ShortMission { .. } => "short-mission",
            Flag::FewSamples { .. } => "few-samples",
        }
    }
}

impl std::fmt::Display for Flag {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Flag::Contamination { share } => write!(
                f,
                "contamination {:.0} % is {} the 50 % at which the median breaks down",
                100.0 * share,
                if share > 0.5 { "past" } else { "near" }
            ),
            Flag::FactorChange {
                change,
                altitude: None,
            } => write!(
                f,
                "F changed {:.0} % from the previous photo (altitude or attitude jump, or a seafloor change)",
                100.0 * change
            ),
            Flag::FactorChange {
                change,
                altitude: Some((before, now)),
            } => write!(
                f,
                "F changed {:.0} % from the previous photo; the navigation log puts it at {now:.2} m, the previous \
                 at {before:.2} m ({:+.0} %){}",
                100.0 * change,
                100.0 * (now / before - 1.0),
                if (now / before - 1.0).abs() < 0.03 {
                    ": hardly an altitude jump (attitude, or a seafloor change)"
                } else {
                    ""
                }
            ),
            Flag::ColourShift { shift } => write!(
                f,
                "F's colour balance differs {:.0} % from what its level predicts (seafloor or water colour \
                 change: it is absorbed into F and removed from the photos)",
                100.0 * shift
            ),
            Flag::SceneInFactor {
                roughness,
                texture_kept,
            } => write!(
                f,
                "F shows the scene ({:.0} % fine structure, {:.0} % of the photo's texture kept): the window holds \
                 too little seafloor here or the camera hardly moves; raise --window or mask the objects",
                100.0 * roughness,
                100.0 * texture_kept
            ),
            Flag::ExposureJump { level } => write!(
                f,
                "exposure jump: the photo is {:+.0} % off its window's level while the lighting pattern stays",
                100.0 * (level - 1.0)
            ),
            Flag::CameraStill { span } => write!(
                f,
                "the camera hardly moves (the ground moves {:.0} % of the frame over a window): F holds the \
                 scene; the method needs photos of changing ground",
                100.0 * span
            ),
            Flag::StructureAdded {
                texture_kept,
                window,
                longer,
                exposure,
                levelled,
            } => structure_added(f, texture_kept, window, longer, exposure, levelled),
            Flag::LightsMisfit { misfit } => write!(
                f,
                "the lights' shape in the photo is {:.0} % off its window's (the altitude or attitude changed along \
                 the window): the correction leaves about that much of the lighting pattern; with the vehicle's \
                 altitudes (--navigation) each window is chosen among photos lit from the same height",
                100.0 * misfit
            ),
            Flag::ShortMission { photos, window } => write!(
                f,
                "only {photos} photos in the mission, fewer than the window n = {window}"
            ),
            Flag::FewSamples {
                samples,
                needed,
                window,
                whole_mission,
            } => write!(
                f,
                "too few independent samples: F may hold the scene; the window of {window} photos{} sees {samples} \
                 of the {needed} views of the ground its quantile needs (a slow camera{})",
                if whole_mission { " (the whole mission)" } else { "" },
                if whole_mission { ", or a short mission" } else { "" }
            ),
        }
    }
}

/// The message of [`Flag::StructureAdded`]: what the correction added, where it came from, and what to do.
fn structure_added(
    f: &mut std::fmt::Formatter<'_>,
    texture_kept: f32,
    window: usize,
    longer: Option<usize>,
    exposure: Option<f32>,
    levelled: bool,
) -> std::fmt::Result {
    write!(
        f,
        "the correction added structure ({:.0} % of the photo's texture): F holds objects its {window} \
         photos saw at the same place ({}){}",
        100.0 * texture_kept,
        match exposure {
            Some(l) => format!("taken in with this photo's exposure jump: {l:.2}× its window's level"),
            None => "a slow camera".to_string(),
        },
        match (exposure, levelled, longer) {
            (Some(_), false, _) => {
                "; exposure levelling keeps such jumps out of F (drop --no-level-exposures)".into()
            }
            (_, _, Some(n)) => format!("; try --window {n}"),
            _ => String::new(),
        }
    )
}

impl Serialize for Flag {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let mut st = s.serialize_struct("Flag", 2)?;
        st.serialize_field("kind", self.kind())?;
        st.serialize_field("message", &self.to_string())?;
        st.end()
    }
}

/// Health figures of one photo, in the run report. The figures are `NaN` (in JSON `null`) where they could not be
/// measured. The flags are the [`Flag`]s as the monitor raised them, or in a report as it records them
/// ([`FlagNote`]: [`Health::noted`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Health<F = Flag> {
    /// Share of blocks whose corrected value is far from the seafloor colour once the photo's overall level is
    /// removed (not seafloor, or a broken `F`).
    #[serde(deserialize_with = "null_is_nan")]
    pub contamination: f32,
    /// The photo's overall level relative to its window's `M` (median over blocks of `(I − S)/(M − S)`; 1 when
    /// only the factor-image figures were observed).
    #[serde(deserialize_with = "null_is_nan")]
    pub level: f32,
    /// Share of the photo's fine structure (texture) left after the correction: about 1 when `F` is smooth,
    /// small when `F` copies the scene (see `PhotoFit`).
    #[serde(deserialize_with = "null_is_nan")]
    pub texture_kept: f32,
    /// Mean relative change of `F` from the previous photo.
    #[serde(deserialize_with = "null_is_nan")]
    pub factor_change: f32,
    /// Largest relative change of `F`'s channel shares (each channel's mean over the mean of all channels; a
    /// channel below the average share in units of the average) against what the mission so far predicts from
    /// `F`'s overall level (altitude changes the level and, through attenuation, the colour together).
    #[serde(deserialize_with = "null_is_nan")]
    pub colour_shift: f32,
    /// Fine structure in `F` (its roughness): lights make smooth patterns, a window short of seafloor leaves
    /// the scene in `F`.
    #[serde(deserialize_with = "null_is_nan")]
    pub roughness: f32,
    /// How far the lights in the photo are from its window's `M` (log units; NaN: not measured): per part of an 8×6
    /// grid of the frame, a quantile of its blocks' log ratios photo / window (above `S`), their mean absolute
    /// spread over the parts once the level is taken out, the lesser of its readings at the 0.9 quantile and at the
    /// window's ([`lights_misfit`](crate::method::stretch::lights_misfit)).
    /// About the lighting pattern the correction leaves (0.05: 5 % brighter or darker in places), plus what the
    /// seafloor's texture puts into each part's quantile.
    #[serde(deserialize_with = "null_is_nan", default = "not_measured")]
    pub lights_misfit: f32,
    /// Shift from the previous photo, in blocks, found by phase correlation of the block medians' texture
    /// (see `register`); `None` for the first photo or images too small.
    pub motion: Option<f32>,
    /// Correlation of the two texture images at that shift (how sure the match is).
    pub motion_ncc: Option<f32>,
    /// How far the ground moves over a window, as a share of the frame's short side (median step of the last
    /// few trusted matches times `n − 1`); `None` until enough photos were seen.
    pub window_span: Option<f32>,
    /// Why this photo's correction is likely wrong (empty: no reason to doubt it).
    pub flags: Vec<F>,
    /// The photo's exposure differs from its window's by more than the exposure-jump threshold and the per-photo
    /// gain absorbed it (information, not a flag).
    pub exposure_absorbed: bool,
}

impl<F> Default for Health<F> {
    fn default() -> Self {
        Health {
            contamination: 0.0,
            level: 0.0,
            texture_kept: 0.0,
            factor_change: 0.0,
            colour_shift: 0.0,
            roughness: 0.0,
            lights_misfit: 0.0,
            motion: None,
            motion_ncc: None,
            window_span: None,
            flags: Vec::new(),
            exposure_absorbed: false,
        }
    }
}

impl Health {
    /// The health as the run report records it: each flag by its kind and message.
    pub fn noted(self) -> Health<FlagNote> {
        Health {
            flags: self.flags.iter().map(FlagNote::from).collect(),
            contamination: self.contamination,
            level: self.level,
            texture_kept: self.texture_kept,
            factor_change: self.factor_change,
            colour_shift: self.colour_shift,
            roughness: self.roughness,
            lights_misfit: self.lights_misfit,
            motion: self.motion,
            motion_ncc: self.motion_ncc,
            window_span: self.window_span,
            exposure_absorbed: self.exposure_absorbed,
        }
    }
}

/// A [`Flag`] as the run report records it (and reads it back): its kind, for scripts ([`Flag::kind`]), and its
/// message, for people (its [`Display`](std::fmt::Display) text, also this note's).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FlagNote {
    /// [`Flag::kind`].
    pub kind: String,
    /// The flag's text.
    pub message: String,
}

impl From<&Flag> for FlagNote {
    fn from(f: &Flag) -> Self {
        FlagNote {
            kind: f.kind().to_string(),
            message: f.to_string(),
        }
    }
}

impl FlagNote {
    /// [`Flag::kind`].
    pub fn kind(&self) -> &str {
        &self.kind
    }
}

impl std::fmt::Display for FlagNote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

/// A flag's kind, as [`Summary`] counts it: a [`Flag`]'s or a [`FlagNote`]'s.
pub trait FlagKind {
    /// The kind ([`Flag::kind`]).
    fn flag_kind(&self) -> &str;
}

impl FlagKind for Flag {
    fn flag_kind(&self) -> &str {
        self.kind()
    }
}

impl FlagKind for FlagNote {
    fn flag_kind(&self) -> &str {
        &self.kind
    }
}

/// Share of blocks of `low` (the photo's own block medians, linear) whose ratio to `M − S` (i.e. the corrected
/// value relative to `C`) is off by more than `deviation`. `NaN` (masked) blocks are not counted.
#[cfg(test)]
pub fn contamination(
    low: &Raster,
    m_minus_s: &Raster,
    s_low: Option<&Raster>,
    deviation: f32,
) -> f32 {
    let (mut bad, mut n) = (0usize, 0usize);
    for p in 0..low.width * low.height {
        if let Some(b) = block_sums(low, m_minus_s, s_low, p) {
            n += 1;
            bad += ((b.ratio() - 1.0).abs() > deviation) as usize;
        }
    }
    if n == 0 {
        0.0
    } else {
        bad as f32 / n as f32
    }
}

/// Block size, in photo pixels, at which the monitor judges a photo: its thresholds were set on 8×8-pixel blocks
/// (docs/evaluation.md), and a finer block's median is noisier (blocks of 4 on the dive matrix read sound dim
/// photos as "contamination").
pub const JUDGED_BLOCK: usize = 8;

/// How many blocks of `k` pixels [`pooled`] groups along each side so the monitor judges blocks of about
/// [`JUDGED_BLOCK`] pixels: `round(8 / k)`, at least 1.
pub fn pool_factor(k: usize) -> usize {
    ((JUDGED_BLOCK + k / 2) / k.max(1)).max(1)
}

/// `r` with each `p`×`p` group of samples (partial at the right and bottom edges) replaced by the median of its
/// values that are not `NaN` (masked), per channel; `NaN` where none is. `p = 1` is a copy.
pub fn pooled(r: &Raster, p: usize) -> Raster {
    if p <= 1 {
        return r.clone();
    }
    let (w, h, c) = (r.width.div_ceil(p), r.height.div_ceil(p), r.channels);
    let mut out = Raster::filled(w, h, c, f32::NAN);
    let mut v = Vec::with_capacity(p * p);
    for by in 0..h {
        for bx in 0..w {
            for ch in 0..c {
                v.clear();
                for y in by * p..((by + 1) * p).min(r.height) {
                    for x in bx * p..((bx + 1) * p).min(r.width) {
                        let s = r.get(x, y, ch);
                        if !s.is_nan() {
                            v.push(s);
                        }
                    }
                }
                if !v.is_empty() {
                    out.data[(by * w + bx) * c + ch] = crate::method::median::median_of_f32(&mut v);
                }
            }
        }
    }
    out
}

/// `M − S` at or below which a channel of a block carries no light to judge (a red channel after 10 m of water).
const NO_LIGHT: f32 = 1e-6;

/// A block's `I − S` and `M − S`, summed over the channels that carry light there.
#[derive(Debug, Clone, Copy)]
struct BlockSums {
    /// `Σ (I − S)` over the lit channels.
    i: f32,
    /// `Σ (M − S)` over the lit channels.
    m: f32,
    /// Lit channels.
    channels: usize,
}

impl BlockSums {
    /// The block's corrected value relative to `C`: `Σ (I − S) / Σ (M − S)`, each channel weighted by its light.
    /// (The mean of the channels' own ratios, used before, let a starved channel — `M − S` of 10⁻⁵, `I − S` its
    /// noise — swing the block by hundreds: dark abyssal dives read 60–100 % "contamination".)
    fn ratio(&self) -> f32 {
        self.i / self.m
    }
}

/// Block `p`: [`BlockSums`] over its channels whose `M − S` is above [`NO_LIGHT`]; `None` when a channel is
/// masked (`NaN`) or no channel carries light.
fn block_sums(
    low: &Raster,
    m_minus_s: &Raster,
    s_low: Option<&Raster>,
    p: usize,
) -> Option<BlockSums> {
    let c = low.channels;
    let mut b = BlockSums {
        i: 0.0,
        m: 0.0,
        channels: 0,
    };
    for ch in 0..c {
        let i = p * c + ch;
        let s = s_low.map_or(0.0, |s| s.data[i]);
        let (v, m) = (low.data[i] - s, m_minus_s.data[i]);
        if v.is_nan() || m.is_nan() {
            return None;
        }
        if m > NO_LIGHT {
            b.i += v;
            b.m += m;
            b.channels += 1;
        }
    }
    (b.channels > 0).then_some(b)
}

/// How a photo's own block medians compare with its window's `M − S` (both at block resolution, linear).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhotoFit {
    /// The photo's overall level: median over blocks of the ratio `Σ(I − S)/Σ(M − S)` over the channels that
    /// carry light (`BlockSums::ratio`).
    pub level: f32,
    /// Share of blocks whose ratio, divided by `level`, is off 1 by more than the block deviation.
    pub contamination: f32,
    /// Fine structure of the corrected photo over that of the photo itself: the median of `|hp(ln I′ − ln M′)|`
    /// over that of `|hp(ln I′)|`, where `I′ = I − S` and `M′ = M − S` are means over the channels that carry
    /// light, `hp(v) = v − v̄` with `v̄` the box average of [`roughness`], over blocks lit in both (above a tenth of
    /// the 99th percentile).
    /// When `F` is smooth the correction keeps the seafloor's texture (≈ 1); when `F` copies the scene (a camera
    /// that hardly moves, or a window short of seafloor) the corrected photo is flat (≪ 1). 1 when the image is
    /// smaller than [`MIN_ROUGHNESS_SIZE`] or has no texture at all.
    pub texture_kept: f32,
}

/// [`PhotoFit`] of a photo's block medians `low` against its window's `m_minus_s`; `s_low` is subtracted from
/// `low` first. `NaN` (masked) blocks are left out.
#[cfg(test)]
pub fn photo_fit(
    low: &Raster,
    m_minus_s: &Raster,
    s_low: Option<&Raster>,
    deviation: f32,
) -> PhotoFit {
    photo_fit_at(low, m_minus_s, s_low, deviation, 0.5)
}

/// [`photo_fit`] with the level at quantile `q` of the block ratios instead of their median: the window's quantile
/// (a share `2q − 1` of dark blocks, nodules, leaves the level on the seafloor).
pub fn photo_fit_at(
    low: &Raster,
    m_minus_s: &Raster,
    s_low: Option<&Raster>,
    deviation: f32,
    q: f32,
) -> PhotoFit {
    let (w, h) = (low.width, low.height);
    let mut a = vec![f32::NAN; w * h];
    let mut b = vec![f32::NAN; w * h];
    let mut ratios = Vec::with_capacity(w * h);
    for p in 0..w * h {
        if let Some(s) = block_sums(low, m_minus_s, s_low, p) {
            ratios.push(s.ratio());
            a[p] = s.i / s.channels as f32;
            b[p] = s.m / s.channels as f32;
        }
    }
    if ratios.is_empty() {
        return PhotoFit {
            level: 1.0,
            contamination: 0.0,
            texture_kept: 1.0,
        };
    }
    let mut sorted = ratios.clone();
    let mid = if q == 0.5 {
        sorted.len() / 2
    } else {
        ((sorted.len() - 1) as f32 * q.clamp(0.0, 1.0)).round() as usize
    };
    let level = *sorted.select_nth_unstable_by(mid, f32::total_cmp).1;
    let level_ok = level.is_finite() && level > 1e-6;
    let scale = if level_ok { level } else { 1.0 };
    let bad = ratios
        .iter()
        .filter(|&&r| (r / scale - 1.0).abs() > deviation)
        .count();
    PhotoFit {
        level: if level_ok { level } else { 1.0 },
        contamination: bad as f32 / ratios.len() as f32,
        texture_kept: texture_kept(&a, &b, w, h),
    }
}

/// Percentile of the fine structure compared (the median: a 90th percentile at 3×3 blocks was tried and did not
/// separate MBARI benthic from sound dives).
const TEXTURE_QUANTILE: usize = 50;

/// See [`PhotoFit::texture_kept`]; `a` and `b` are the means of `I − S` and `M − S` over the channels that
/// carry light (`NaN`: left out).
fn texture_kept(a: &[f32], b: &[f32], w: usize, h: usize) -> f32 {
    if w < MIN_ROUGHNESS_SIZE.0 || h < MIN_ROUGHNESS_SIZE.1 {
        return 1.0;
    }
    let floor = |v: &[f32]| {
        let mut f: Vec<f32> = v.iter().copied().filter(|x| x.is_finite()).collect();
        if f.is_empty() {
            return f32::INFINITY;
        }
        let at = (f.len() - 1) * 99 / 100;
        (0.1 * *f.select_nth_unstable_by(at, f32::total_cmp).1).max(1e-6)
    };
    let (fa, fb) = (floor(a), floor(b));
    let lit = |p: usize| a[p].is_finite() && b[p].is_finite() && a[p] >= fa && b[p] >= fb;
    let photo: Vec<f32> = (0..w * h)
        .map(|p| if lit(p) { a[p].ln() } else { f32::NAN })
        .collect();
    let corrected: Vec<f32> = (0..w * h)
        .map(|p| {
            if lit(p) {
                a[p].ln() - b[p].ln()
            } else {
                f32::NAN
            }
        })
        .collect();
    let fine = |v: &[f32]| -> f32 {
        let mut smooth = Vec::new();
        box_average_into(
            v,
            w,
            h,
            (w / 16).max(2),
            &mut Vec::new(),
            &mut Vec::new(),
            &mut smooth,
        );
        let mut dev: Vec<f32> = v
            .iter()
            .zip(&smooth)
            .filter(|(x, s)| x.is_finite() && s.is_finite())
            .map(|(x, s)| (x - s).abs())
            .collect();
        if dev.is_empty() {
            return 0.0;
        }
        let at = (dev.len() - 1) * TEXTURE_QUANTILE / 100;
        *dev.select_nth_unstable_by(at, f32::total_cmp).1
    };
    let own = fine(&photo);
    if own <= 1e-6 {
        return 1.0;
    }
    fine(&corrected) / own
}

/// Mean relative change between two factor images: `Σ|a − b| / Σ|b|`.
pub fn factor_change(a: &Raster, b: &Raster) -> f32 {
    let (mut d, mut s) = (0.0f64, 0.0f64);
    for (x, y) in a.data.iter().zip(&b.data) {
        if x.is_finite() && y.is_finite() {
            d += (x - y).abs() as f64;
            s += y.abs() as f64;
        }
    }
    if s > 0.0 {
        (d / s) as f32
    } else {
        0.0
    }
}

/// Colour balance of a factor image: each channel's mean divided by the mean over channels.
pub fn balance(f: &Raster) -> Vec<f32> {
    let means = f.channel_means();
    let all = means.iter().sum::<f64>() / means.len().max(1) as f64;
    means
        .iter()
        .map(|m| if all > 0.0 { (m / all) as f32 } else { 1.0 })
        .collect()
}

/// Smallest factor image (width, height) whose roughness is measured (photos of 256×192 at `--downsample 8`).
pub const MIN_ROUGHNESS_SIZE: (usize, usize) = (32, 24);

/// How much of the scene is left in a factor image: the median, over lit pixels, of `|ln F − ln F̄|`, where `F` is
/// the mean over channels and `F̄` its box average over a square of side `2r + 1`, `r = max(2, width / 16)`
/// (edges clamped). Lights, attenuation and vignetting make patterns that are smooth almost everywhere, so this
/// is small (≈ 0.02–0.07 on real dives whose window holds enough seafloor); when more than half of the window
/// shows objects at the same place, `F` takes on their outlines and texture (≈ 0.17 on the cluttered AQUALOC
/// amphora site). Contamination of the corrected photo cannot see that failure: dividing by a copy of the scene
/// makes the output look flat. Pixels below a tenth of the 99th percentile (unlit corners) are not counted.
/// Factor images smaller than [`MIN_ROUGHNESS_SIZE`] get 0: on a handful of pixels the curvature of the light
/// cone itself cannot be told from texture.
#[cfg(test)]
pub fn roughness(f: &Raster) -> f32 {
    Scratch::default().roughness(f)
}

/// Buffers for [`roughness`], kept by the [`Monitor`] from photo to photo: a few low-resolution images a photo,
/// allocated once instead of page-faulted in afresh every time.
#[derive(Debug, Default)]
struct Scratch {
    lum: Vec<f32>,
    selection: Vec<f32>,
    log: Vec<f32>,
    sums: Vec<f32>,
    counts: Vec<f32>,
    smooth: Vec<f32>,
}

impl Scratch {
    fn roughness(&mut self, f: &Raster) -> f32 {
        let (w, h, c) = (f.width, f.height, f.channels);
        if w < MIN_ROUGHNESS_SIZE.0 || h < MIN_ROUGHNESS_SIZE.1 {
            return 0.0;
        }
        let lum = &mut self.lum;
        lum.clear();
        lum.extend(
            f.data
                .chunks_exact(c)
                .map(|px| px.iter().sum::<f32>() / c as f32),
        );
        let finite = &mut self.selection;
        finite.clear();
        finite.extend(lum.iter().copied().filter(|v| v.is_finite()));
        if finite.is_empty() {
            return 0.0;
        }
        let at = (finite.len() - 1) * 99 / 100;
        let top = *finite.select_nth_unstable_by(at, f32::total_cmp).1;
        let dark = (0.1 * top).max(1e-6);
        let log = &mut self.log;
        log.clear();
        log.extend(lum.iter().map(|&v| {
            if v.is_finite() {
                v.max(dark).ln()
            } else {
                f32::NAN
            }
        }));
        let r = (w / 16).max(2);
        box_average_into(
            log,
            w,
            h,
            r,
            &mut self.sums,
            &mut self.counts,
            &mut self.smooth,
        );
        let dev = &mut self.selection;
        dev.clear();
        dev.extend(
            (0..w * h)
                .filter(|&p| lum[p].is_finite() && lum[p] >= dark && self.smooth[p].is_finite())
                .map(|p| (log[p] - self.smooth[p]).abs()),
        );
        if dev.is_empty() {
            return 0.0;
        }
        let mid = dev.len() / 2;
        *dev.select_nth_unstable_by(mid, f32::total_cmp).1
    }
}

/// Mean over the `(2r + 1)²` square around each pixel, coordinates clamped to the image; `NaN` values are left
/// out of the mean (`NaN` where all are).
#[cfg(test)]
fn box_average(v: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    let mut out = Vec::new();
    box_average_into(v, w, h, r, &mut Vec::new(), &mut Vec::new(), &mut out);
    out
}

/// [`box_average`] into `out`, with `sums` and `counts` as scratch. Along rows: window sums from prefix sums of
/// the line padded by clamping; down the columns: a running window sum over whole rows (`f64`), so every pass
/// reads memory in order and costs O(1) per pixel whatever `r`.
fn box_average_into(
    v: &[f32],
    w: usize,
    h: usize,
    r: usize,
    sums: &mut Vec<f32>,
    counts: &mut Vec<f32>,
    out: &mut Vec<f32>,
) {
    sums.clear();
    counts.clear();
    let mut prefix: Vec<(f64, f64)> = Vec::with_capacity(w + 2 * r + 1);
    for line in v.chunks_exact(w) {
        prefix.clear();
        prefix.push((0.0, 0.0));
        for i in 0..w + 2 * r {
            let x = line[(i as isize - r as isize).clamp(0, w as isize - 1) as usize];
            let (s, k) = if x.is_finite() {
                (x as f64, 1.0)
            } else {
                (0.0, 0.0)
            };
            let last = prefix[i];
            prefix.push((last.0 + s, last.1 + k));
        }
        for x in 0..w {
            let (a, b) = (prefix[x], prefix[x + 2 * r + 1]);
            sums.push((b.0 - a.0) as f32);
            counts.push((b.1 - a.1) as f32);
        }
    }
    let row = |y: isize| y.clamp(0, h as isize - 1) as usize * w;
    let mut acc_s = vec![0.0f64; w];
    let mut acc_n = vec![0.0f64; w];
    for y in -(r as isize)..=(r as isize) {
        let o = row(y);
        for x in 0..w {
            acc_s[x] += sums[o + x] as f64;
            acc_n[x] += counts[o + x] as f64;
        }
    }
    out.clear();
    out.reserve(w * h);
    for y in 0..h as isize {
        out.extend(
            acc_s
                .iter()
                .zip(&acc_n)
                .map(|(&s, &n)| if n > 0.0 { (s / n) as f32 } else { f32::NAN }),
        );
        let (add, sub) = (row(y + r as isize + 1), row(y - r as isize));
        for x in 0..w {
            acc_s[x] += sums[add + x] as f64 - sums[sub + x] as f64;
            acc_n[x] += counts[add + x] as f64 - counts[sub + x] as f64;
        }
    }
}

/// Follows the mission photo by photo and flags photos whose estimate is likely broken.
#[derive(Debug, Default)]
pub struct Monitor {
    /// The limits above which a photo is flagged.
    pub thresholds: Thresholds,
    previous: Option<Raster>,
    changes: Vec<f32>,
    /// Balances of the first photos, whose median is the mission's reference balance until the level fit
    /// takes over.
    start: Vec<Vec<f32>>,
    reference: Option<Vec<f32>>,
    /// Least-squares sums of `ln balance_c` against `ln level` over unflagged photos (see [`ColourFit`]).
    colour_fit: ColourFit,
    scratch: Scratch,
    sorted_changes: Vec<f32>,
    /// Texture image of the previous photo's block medians, for its motion (see [`Health::motion`]).
    previous_texture: Option<crate::method::matching::Texture>,
    /// Its spectrum, when it is large enough to be matched.
    previous_spectrum: Option<crate::method::matching::Spectrum>,
    /// Recent (motion, correlation) of consecutive photos, at most [`STILL_PHOTOS`].
    recent_motion: std::collections::VecDeque<(f32, f32)>,
    /// The last photo's own match with the one before it is trusted and moves the ground less than [`STILL_SPAN`]
    /// over the window (what [`Monitor::supports_few_views`] reads before [`STILL_PHOTOS`] matches are in).
    moved_little: bool,
    /// The window `n` (0: not told; [`STILL_DEFAULT_WINDOW`] is assumed).
    window: usize,
    /// The quantile of the next photo's window ([`Monitor::set_window`]).
    quantile: f32,
    /// Photos per independent view of the ground in the next photo's window, as the survey found them
    /// ([`Monitor::set_views`]; `None`: no survey).
    views: Option<f32>,
    /// A per-photo gain absorbs exposure changes ([`Monitor::with_gain`]).
    gain: bool,
    /// Exposure levelling runs ([`Monitor::with_levelling`]).
    levelling: bool,
}

/// Consecutive matches whose medians decide whether the camera hardly moves.
const STILL_PHOTOS: usize = 5;
/// Median correlation of those matches above which their shifts are trusted (below it, on Nephrops, the match
/// locks on to what stays in the frame: laser dots, the lamps' fine structure).
const STILL_NCC: f32 = 0.6;
/// The ground a window sees moves less than this share of the frame's short side: objects larger than that stay
/// at one place in most of the window, so the median keeps them in `F`.
const STILL_SPAN: f32 = 0.25;
/// Window assumed when the monitor is not told.
const STILL_DEFAULT_WINDOW: usize = crate::method::params::BASE_WINDOW;
/// Long side (block-median pixels) up to which photos are matched for the camera-still test without reduction;
/// larger ones are reduced by an integer factor (at most twice this side after reduction).
const STILL_MATCH_SIDE: usize = 192;

/// Photos whose balance makes up the mission's reference.
const REFERENCE_PHOTOS: usize = 5;

/// Spread of `ln level` (standard deviation) below which the slope of colour on level is shrunk towards 0: a
/// slope is only learnt from level changes the mission has actually shown (ridge regression).
const LEVEL_SPREAD: f64 = 0.05;

/// Running least-squares fit of each channel's log share of `F` (`ln balance_c`) on the log of `F`'s overall
/// level. Altitude changes move both together (the light falls off with distance and, through per-channel
/// attenuation, its colour changes), so the colour a photo's level predicts is not a colour change; what is
/// left over is (a seafloor or water colour change absorbed into `F`).
#[derive(Debug, Default, Clone)]
struct ColourFit {
    n: f64,
    sx: f64,
    sxx: f64,
    sy: Vec<f64>,
    sxy: Vec<f64>,
}

impl ColourFit {
    fn add(&mut self, x: f64, y: &[f64]) {
        if self.sy.len() != y.len() {
            *self = ColourFit {
                sy: vec![0.0; y.len()],
                sxy: vec![0.0; y.len()],
                ..ColourFit::default()
            };
        }
        self.n += 1.0;
        self.sx += x;
        self.sxx += x * x;
        for (c, &v) in y.iter().enumerate() {
            self.sy[c] += v;
            self.sxy[c] += x * v;
        }
    }

    /// Predicted `ln balance_c` at log level `x`.
    fn predict(&self, x: f64) -> Vec<f64> {
        let mx = self.sx / self.n;
        let var = (self.sxx - self.n * mx * mx).max(0.0);
        self.sy
            .iter()
            .zip(&self.sxy)
            .map(|(&sy, &sxy)| {
                let my = sy / self.n;
                let slope = (sxy - self.n * mx * my) / (var + self.n * LEVEL_SPREAD * LEVEL_SPREAD);
                my + slope * (x - mx)
            })
            .collect()
    }
}

/// Overall level of a factor image: the mean over channels of the channel means.
fn overall_level(f: &Raster) -> f64 {
    let m = f.channel_means();
    m.iter().sum::<f64>() / m.len().max(1) as f64
}

impl Monitor {
    /// A monitor with these thresholds and no photo seen yet.
    pub fn new(thresholds: Thresholds) -> Self {
        Monitor {
            thresholds,
            ..Monitor::default()
        }
    }

    /// Tell the monitor the window `n` (for the still-camera test of [`Monitor::observe_photo`]).
    pub fn with_window(mut self, n: usize) -> Self {
        self.window = n;
        self
    }

    /// Tell the monitor that a per-photo gain absorbs exposure changes: they are then reported as
    /// [`Health::exposure_absorbed`], not flagged.
    pub fn with_gain(mut self, gain: bool) -> Self {
        self.gain = gain;
        self
    }

    /// Tell the monitor whether exposure levelling runs (the advice of [`Flag::StructureAdded`] after a jump).
    pub fn with_levelling(mut self, levelling: bool) -> Self {
        self.levelling = levelling;
        self
    }

    /// The next photo's window `n` and the quantile its `M` takes: the level and contamination share are taken at
    /// that quantile, and the contamination flag's threshold moves with the quantile's breakdown (`q` instead of
    /// the median's 0.5).
    pub fn set_window(&mut self, n: usize, q: f32) {
        self.window = n;
        self.quantile = q;
    }

    /// Photos per independent view of the ground in the next photo's window, as `--window auto`'s survey found them
    /// ([`Choice::photos_per_sample`]; `None`: no survey). With a survey the texture kept alone does not flag
    /// `scene-in-factor`; below [`STILL_VIEWS`] a match of consecutive photos does not flag `camera-still`.
    ///
    /// [`Choice::photos_per_sample`]: crate::method::stretch::Choice::photos_per_sample
    pub fn set_views(&mut self, photos_per_sample: Option<f32>) {
        self.views = photos_per_sample;
    }

    /// Whether the photo last observed, of health `h`, supports the survey's reading that a window the do-no-harm
    /// check fell back to (`Rule::Unsteady`) holds too few views of the ground: `F`'s roughness or the photo's
    /// lights misfit past [`FEW_VIEWS_SUPPORT`] of its own threshold, or its match with the photo before it trusted
    /// and moving the ground less than a still camera's share of the frame over the window (Sparus' first photos,
    /// before `camera-still` has its matches). There the survey's longer choice was already overruled by the
    /// lights, and its count of views is the one a swing misleads (photos lit alike read as one view, while their
    /// match finds no trusted shift): the claim that `F` may hold the scene needs the photo to show something of
    /// it.
    pub fn supports_few_views(&self, h: &Health) -> bool {
        let t = self.thresholds;
        h.roughness > FEW_VIEWS_SUPPORT * t.roughness
            || h.lights_misfit > FEW_VIEWS_SUPPORT * t.lights_misfit
            || self.moved_little
    }

    /// Health of the next photo from everything the method knows about it: its own block medians `own`, its
    /// window's `M − S` (`m_minus_s`, before any per-photo adjustment), the scatter at block resolution and the
    /// factor image `f`. Adds the photo's level (exposure jumps) and the texture the correction kept (scene in
    /// `F`) to [`Monitor::observe`]'s figures.
    pub fn observe_photo(
        &mut self,
        own: &Raster,
        m_minus_s: &Raster,
        s_low: Option<&Raster>,
        f: &Raster,
    ) -> Health {
        let t = self.thresholds;
        let q = if self.quantile > 0.0 {
            self.quantile
        } else {
            0.5
        };
        let fit = photo_fit_at(own, m_minus_s, s_low, t.block_deviation, q);
        let mut h = self.observe_at(f, fit.contamination, q);
        h.level = fit.level;
        h.texture_kept = fit.texture_kept;
        // Below the size roughness and texture need, a part of the grid holds too few blocks for its bright side.
        h.lights_misfit = if own.width >= MIN_ROUGHNESS_SIZE.0 && own.height >= MIN_ROUGHNESS_SIZE.1
        {
            crate::method::stretch::lights_misfit(own, m_minus_s, s_low, q as f64)
        } else {
            f32::NAN
        };
        if h.lights_misfit > t.lights_misfit {
            h.flags.push(Flag::LightsMisfit {
                misfit: h.lights_misfit,
            });
        }
        self.observe_stillness(own, &mut h);
        let jumped = (fit.level - 1.0).abs() > t.exposure_jump;
        if jumped {
            match self.gain {
                true => h.exposure_absorbed = true,
                false => h.flags.push(Flag::ExposureJump { level: fit.level }),
            }
        }
        if fit.texture_kept > t.structure_added {
            let window = self.window.max(1);
            h.flags.push(Flag::StructureAdded {
                texture_kept: fit.texture_kept,
                window,
                longer: Some((2 * window + 1).min(crate::method::stretch::MAX_AUTO_WINDOW))
                    .filter(|&n| n > window),
                exposure: jumped.then_some(fit.level),
                levelled: self.levelling,
            });
        }
        // The fine structure a correction removes is a scene held in `F` only where the camera repeats its views.
        // Where a survey ran (`--window auto`), the views are counted and named by `few-samples`, and `F`'s own
        // roughness still flags a scene in it: the texture kept alone does not flag the photo. On smooth ground
        // the fine structure removed is the lights' (the cones' steep fall-off), whatever the survey read.
        let surveyed = self.views.is_some();
        if fit.texture_kept < t.texture_kept {
            match h
                .flags
                .iter_mut()
                .find(|f| matches!(f, Flag::SceneInFactor { .. }))
            {
                Some(Flag::SceneInFactor { texture_kept, .. }) => *texture_kept = fit.texture_kept,
                _ if surveyed => {}
                _ => h.flags.push(Flag::SceneInFactor {
                    roughness: h.roughness,
                    texture_kept: fit.texture_kept,
                }),
            }
        }
        h
    }

    /// Health of the next photo from its factor image and contamination estimate alone.
    #[cfg(test)]
    pub fn observe(&mut self, f: &Raster, contamination: f32) -> Health {
        self.observe_at(f, contamination, 0.5)
    }

    /// [`Monitor::observe`] for a window whose `M` is its `q` quantile.
    fn observe_at(&mut self, f: &Raster, contamination: f32, q: f32) -> Health {
        let t = self.thresholds;
        let mut h = Health {
            contamination,
            level: 1.0,
            texture_kept: 1.0,
            ..Health::default()
        };
        if contamination > t.contamination * q / 0.5 {
            h.flags.push(Flag::Contamination {
                share: contamination,
            });
        }
        self.observe_factor_change(f, &mut h);
        h.roughness = self.scratch.roughness(f);
        if h.roughness > t.roughness {
            h.flags.push(Flag::SceneInFactor {
                roughness: h.roughness,
                texture_kept: 1.0,
            });
        }
        let b = balance(f);
        let level = overall_level(f);
        let x = if level > 0.0 { level.ln() } else { 0.0 };
        let y: Vec<f64> = b.iter().map(|&v| (v.max(1e-6) as f64).ln()).collect();
        if self.reference.is_none() {
            self.start.push(b.clone());
            if self.start.len() == REFERENCE_PHOTOS {
                self.reference = Some(median_balance(&self.start));
            }
        }
        // Until the mission has shown a few photos, the reference is the median balance of the first ones;
        // then the colour the photo's level predicts from the photos so far.
        let expected: Vec<f32> = if self.colour_fit.n >= REFERENCE_PHOTOS as f64 {
            self.colour_fit
                .predict(x)
                .into_iter()
                .map(|v| v.exp() as f32)
                .collect()
        } else {
            self.reference
                .clone()
                .unwrap_or_else(|| median_balance(&self.start))
        };
        // Relative to the channel's own share, but never finer than the average channel's (the balances average
        // 1): a channel the water has nearly emptied (balance 0.05) moves by a third of itself from noise alone,
        // which is no colour change (a dark abyssal dive of the matrix: 19 of 30 photos flagged when each channel
        // was judged relative to itself).
        h.colour_shift = b
            .iter()
            .zip(&expected)
            .map(|(x, r)| (x - r).abs() / r.max(1.0))
            .fold(0.0, f32::max);
        if h.colour_shift > t.colour_shift {
            h.flags.push(Flag::ColourShift {
                shift: h.colour_shift,
            });
        }
        // Every photo teaches the fit, flagged or not (predicted before it is added). Learning from unflagged
        // photos only locked the fit to the first photos' narrow range of levels: a slow altitude drift then read
        // as a growing colour shift that was never learnt (a matrix dive: 17 of 30 photos flagged, up to 0.22,
        // while the true seafloor colour moved 2.5 %). A lasting colour change is still flagged for about as many
        // photos as came before it (the fit's intercept follows it at 1/n a photo).
        if level > 0.0 {
            self.colour_fit.add(x, &y);
        }
        match &mut self.previous {
            Some(p) if p.layout() == f.layout() => p.data.copy_from_slice(&f.data),
            p => *p = Some(f.clone()),
        }
        h
    }
    /// Match the photo's texture with the previous photo's (`h.motion`), and flag a camera that hardly moves.
    fn observe_stillness(&mut self, own: &Raster, h: &mut Health) {
        // Reduced so that its long side stays under 2·STILL_MATCH_SIDE: a 12 MP photo's 500×375 block medians are
        // matched at 250×187 (FFT 256×256 instead of 512×512, a quarter of the work); photos up to ~3000 px wide
        // are matched at full block resolution, as before.
        let scale = crate::method::matching::reduction_to(own.width, own.height, STILL_MATCH_SIDE);
        let texture = crate::method::matching::texture(own, scale);
        // The shift is in `own`'s pixels (match_pair scales it back), and so is the side it is compared with.
        let short_side = (texture.width.min(texture.height) * scale) as f32;
        let n = if self.window > 0 {
            self.window
        } else {
            STILL_DEFAULT_WINDOW
        };
        let span_of = |step: f32| step * (n.saturating_sub(1)) as f32 / short_side.max(1.0);
        self.moved_little = false;
        // Each photo's spectrum once: the next photo is matched against it.
        let spectrum = (texture.width >= MIN_ROUGHNESS_SIZE.0
            && texture.height >= MIN_ROUGHNESS_SIZE.1)
            .then(|| crate::method::matching::texture_spectrum(&texture));
        let pair = (&self.previous_texture, &self.previous_spectrum, &spectrum);
        if let (Some(prev), Some(prev_spectrum), Some(spectrum)) = pair {
            if (prev.width, prev.height) == (texture.width, texture.height) {
                let m =
                    crate::method::matching::match_spectra(prev, &texture, prev_spectrum, spectrum);
                h.motion = Some(m.shift.0.hypot(m.shift.1) as f32);
                h.motion_ncc = Some(m.ncc as f32);
                self.moved_little = m.ncc as f32 >= STILL_NCC
                    && span_of(m.shift.0.hypot(m.shift.1) as f32) < STILL_SPAN;
                if self.recent_motion.len() == STILL_PHOTOS {
                    self.recent_motion.pop_front();
                }
                self.recent_motion
                    .push_back((m.shift.0.hypot(m.shift.1) as f32, m.ncc as f32));
            }
        }
        self.previous_texture = Some(texture);
        self.previous_spectrum = spectrum;
        // A camera that hardly moves: the window's photos see the same ground, so F holds the scene (MBARI
        // benthic, Sparus). Judged on the median of the last few trusted matches.
        if self.recent_motion.len() == STILL_PHOTOS {
            let med = |v: &mut Vec<f32>| {
                v.sort_by(f32::total_cmp);
                v[v.len() / 2]
            };
            let ncc = med(&mut self.recent_motion.iter().map(|m| m.1).collect());
            let step = med(&mut self.recent_motion.iter().map(|m| m.0).collect());
            let span = span_of(step);
            h.window_span = Some(span);
            // Where the survey found the window's photos more than two views of the ground (its scenes are measured
            // against the neighbours' reference, the lights and what is fixed in the frame taken out), the match
            // locked onto the lights: under a swing the cones' edges and clipped beams stay put in the frame.
            let moves = self.views.is_some_and(|v| v < STILL_VIEWS);
            if ncc >= STILL_NCC && span < STILL_SPAN && !moves {
                h.flags.push(Flag::CameraStill { span });
            }
        }
    }

    /// The factor image's change from the previous photo's (`h.factor_change`), flagged when unusually large.
    fn observe_factor_change(&mut self, f: &Raster, h: &mut Health) {
        let t = self.thresholds;
        if let Some(prev) = &self.previous {
            let change = factor_change(f, prev);
            h.factor_change = change;
            // The median change so far, by selection (linear in the mission's length, not n log n a photo).
            let sorted = &mut self.sorted_changes;
            sorted.clear();
            sorted.extend_from_slice(&self.changes);
            let typical = if sorted.is_empty() {
                0.0
            } else {
                let mid = sorted.len() / 2;
                *sorted.select_nth_unstable_by(mid, f32::total_cmp).1
            };
            if change > t.factor_change && change > t.factor_change_ratio * typical {
                h.flags.push(Flag::FactorChange {
                    change,
                    altitude: None,
                });
            }
            self.changes.push(change);
        }
    }
}

fn median_balance(v: &[Vec<f32>]) -> Vec<f32> {
    let c = v.first().map_or(0, Vec::len);
    (0..c)
        .map(|ch| {
            let mut x: Vec<f32> = v.iter().map(|b| b[ch]).collect();
            x.sort_by(f32::total_cmp);
            x[x.len() / 2]
        })
        .collect()
}

/// Share of its own threshold at which `F`'s roughness or the photo's lights misfit supports a `few-samples` reading
/// of a window the do-no-harm check fell back to ([`Monitor::supports_few_views`]). On the randomized family's
/// simdive dives (docs/results.md) the flag was raised on 84 such photos, 78 of them good (their misfit 0.004,
/// roughness 0.03 at the median; the wrong ones' misfit 0.04–0.07); AQUALOC's, under a still ROV, have roughness
/// 0.15–0.19.
pub const FEW_VIEWS_SUPPORT: f32 = 0.5;

/// Photos per independent view of the window's ground ([`Monitor::set_views`]) below which the survey says the
/// camera moves and `camera-still` is not raised: more than two views in the window 7 (a still camera's window is
/// one view: 7 or more photos per view).
pub const STILL_VIEWS: f32 = 3.5;

/// What [`Health::lights_misfit`] reads back from a report written before it was measured.
fn not_measured() -> f32 {
    f32::NAN
}

/// Count of flagged photos per kind of reason, for the end-of-run summary.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Summary {
    /// Photos with at least one flag (a photo with several flags counts once here).
    pub flagged: usize,
    /// Photos flagged [`Flag::Contamination`].
    pub contamination: usize,
    /// Photos flagged [`Flag::FactorChange`].
    pub factor_change: usize,
    /// Photos flagged [`Flag::ColourShift`].
    pub colour_shift: usize,
    /// Photos flagged [`Flag::SceneInFactor`] (the name is kept for existing report readers).
    pub roughness: usize,
    /// Photos flagged [`Flag::ExposureJump`].
    pub exposure_jump: usize,
    /// Photos flagged [`Flag::CameraStill`].
    pub camera_still: usize,
    /// Photos flagged [`Flag::ShortMission`].
    pub short_mission: usize,
    /// Photos flagged [`Flag::FewSamples`].
    pub few_samples: usize,
    /// Photos flagged [`Flag::StructureAdded`].
    pub structure_added: usize,
    /// Photos flagged [`Flag::LightsMisfit`].
    #[serde(default)]
    pub lights_misfit: usize,
    /// Photos whose exposure change the per-photo gain absorbed ([`Health::exposure_absorbed`]; not flagged).
    pub exposure_absorbed: usize,
}

impl Summary {
    /// The summary of photos with these healths: the flags by kind, and the exposures absorbed.
    pub fn of<'a, F: FlagKind + 'a>(healths: impl IntoIterator<Item = &'a Health<F>>) -> Self {
        let mut s = Summary::default();
        for h in healths {
            s.add(&h.flags);
            s.exposure_absorbed += usize::from(h.exposure_absorbed);
        }
        s
    }

    /// Count one photo with these flags (nothing if it has none), by their kinds ([`Flag::kind`]).
    pub fn add<F: FlagKind>(&mut self, flags: &[F]) {
        if flags.is_empty() {
            return;
        }
        self.flagged += 1;
        for f in flags {
            match f.flag_kind() {
                "contamination" => self.contamination += 1,
                "factor-change" => self.factor_change += 1,
                "colour-shift" => self.colour_shift += 1,
                "scene-in-factor" => self.roughness += 1,
                "exposure-jump" => self.exposure_jump += 1,
                "camera-still" => self.camera_still += 1,
                "short-mission" => self.short_mission += 1,
                "few-samples" => self.few_samples += 1,
                "structure-added" => self.structure_added += 1,
                "lights-misfit" => self.lights_misfit += 1,
                _ => {}
            }
        }
    }

    /// One line for the user, naming every kind of flag raised (all fields taken apart, so that a kind added to
    /// the summary cannot be left out of the line).
    pub fn line(&self, photos: usize) -> String {
        let Summary {
            flagged,
            contamination,
            factor_change,
            colour_shift,
            roughness,
            exposure_jump,
            camera_still,
            short_mission,
            few_samples,
            structure_added,
            lights_misfit,
            exposure_absorbed,
        } = *self;
        let absorbed = match exposure_absorbed {
            0 => String::new(),
            n => format!("; {n} exposure change(s) absorbed by the per-photo gain"),
        };
        if flagged == 0 {
            return format!("no photo of {photos} flagged: the estimates look sound{absorbed}");
        }
        let mut parts = Vec::new();
        for (n, what) in [
            (contamination, "contamination near 50 %"),
            (factor_change, "sudden change of F"),
            (colour_shift, "colour change of F"),
            (roughness, "scene left in F"),
            (exposure_jump, "exposure jump"),
            (camera_still, "camera hardly moving"),
            (short_mission, "too few photos for the window"),
            (
                few_samples,
                "too few independent samples (F may hold the scene)",
            ),
            (structure_added, "structure added (ghosts)"),
            (lights_misfit, "lights unlike their window's"),
        ] {
            if n > 0 {
                parts.push(format!("{n} {what}"));
            }
        }
        format!(
            "{flagged} of {photos} photos flagged as likely wrong ({}); see the report and _abysslight/overview.png{absorbed}",
            parts.join(", ")
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether `flags` hold a flag of `kind` ([`Flag::kind`]).
    fn has(flags: &[Flag], kind: &str) -> bool {
        flags.iter().any(|f| f.kind() == kind)
    }

    #[test]
    fn pooled_is_the_median_of_each_group_without_masked_samples() {
        // Brute force: every group's values collected anew, sorted, the middle one (or the mean of the two).
        fn brute(r: &Raster, p: usize, bx: usize, by: usize, ch: usize) -> f32 {
            let mut v: Vec<f32> = (0..r.height)
                .flat_map(|y| (0..r.width).map(move |x| (x, y)))
                .filter(|&(x, y)| x / p == bx && y / p == by)
                .map(|(x, y)| r.get(x, y, ch))
                .filter(|s| !s.is_nan())
                .collect();
            v.sort_by(f32::total_cmp);
            match v.len() {
                0 => f32::NAN,
                n if n % 2 == 1 => v[n / 2],
                n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
            }
        }
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for (w, h, c, p) in [(9, 7, 3, 2), (10, 6, 1, 3), (5, 5, 2, 1), (3, 2, 3, 4)] {
            let mut r = Raster::filled(w, h, c, 0.0);
            for v in &mut r.data {
                let u = next();
                // A fifth of the samples masked, and a whole 2×2 corner group masked in the first raster.
                *v = if u < 0.2 { f32::NAN } else { next() };
            }
            if p == 2 {
                for (x, y) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    for ch in 0..c {
                        r.data[(y * w + x) * c + ch] = f32::NAN;
                    }
                }
            }
            let out = pooled(&r, p);
            assert_eq!((out.width, out.height), (w.div_ceil(p), h.div_ceil(p)));
            for by in 0..out.height {
                for bx in 0..out.width {
                    for ch in 0..c {
                        let (got, want) = (out.get(bx, by, ch), brute(&r, p, bx, by, ch));
                        assert!(
                            got == want || (got.is_nan() && want.is_nan()),
                            "{w}x{h} p {p} group ({bx}, {by}) channel {ch}: {got} against {want}"
                        );
                    }
                }
            }
            if p == 2 {
                assert!(
                    out.get(0, 0, 0).is_nan(),
                    "a group with every sample masked"
                );
            }
        }
        // Blocks of about 8 pixels for every block size.
        for k in 1..=16 {
            let judged = pool_factor(k) * k;
            assert!(
                (5..=12).contains(&judged) || k > 8,
                "K {k}: judged at {judged}"
            );
        }
        assert_eq!((pool_factor(4), pool_factor(8), pool_factor(2)), (2, 1, 4));
    }

    #[test]
    fn contamination_counts_blocks_off_the_seafloor() {
        let m = Raster::filled(10, 10, 3, 0.5);
        let mut low = m.clone();
        for p in 0..30 {
            for c in 0..3 {
                low.data[p * 3 + c] = 0.1; // dark nodule: ratio 0.2
            }
        }
        for c in 0..3 {
            low.data[50 * 3 + c] = 0.6; // ratio 1.2: texture, not contamination
            low.data[60 * 3 + c] = f32::NAN; // masked
        }
        let got = contamination(&low, &m, None, 0.5);
        assert!((got - 30.0 / 99.0).abs() < 1e-6, "{got}");
        // S is subtracted from the photo's blocks before the ratio.
        let s = Raster::filled(10, 10, 3, 0.1);
        let lifted = Raster::from_fn(10, 10, 3, |x, y, c| m.get(x, y, c) + 0.1);
        assert_eq!(contamination(&lifted, &m, Some(&s), 0.5), 0.0);
    }

    #[test]
    fn factor_change_and_balance_by_hand() {
        let a = Raster::filled(2, 1, 3, 1.0);
        let b = Raster::from_fn(2, 1, 3, |x, _, _| if x == 0 { 1.5 } else { 1.0 });
        // |1.5 - 1| * 3 / (6 * 1) = 0.25
        assert!((factor_change(&b, &a) - 0.25).abs() < 1e-6);
        let c = Raster::from_fn(1, 1, 3, |_, _, ch| [0.5, 1.0, 1.5][ch]);
        assert_eq!(balance(&c), vec![0.5, 1.0, 1.5]);
    }

    #[test]
    fn flags_jumps_and_colour_changes_but_not_steady_photos() {
        let mut mon = Monitor::new(Thresholds::default());
        let steady = |k: f32| {
            Raster::from_fn(4, 3, 3, |x, _, c| {
                (0.5 + 0.01 * x as f32) * [1.0, 0.9, 0.7][c] * k
            })
        };
        for i in 0..10 {
            let h = mon.observe(&steady(1.0 + 0.01 * i as f32), 0.2);
            assert!(h.flags.is_empty(), "photo {i}: {:?}", h.flags);
        }
        // Altitude jump: F halves.
        let h = mon.observe(&steady(0.5), 0.2);
        assert!(has(&h.flags, "factor-change"), "{:?}", h.flags);
        // Contamination near breakdown.
        let h = mon.observe(&steady(0.5), 0.45);
        assert!(has(&h.flags, "contamination"), "{:?}", h.flags);
        // Seafloor turns bluish: the balance of F shifts.
        let blue = Raster::from_fn(4, 3, 3, |x, _, c| {
            (0.5 + 0.01 * x as f32) * [0.7, 0.9, 1.0][c] * 0.5
        });
        let h = mon.observe(&blue, 0.2);
        assert!(has(&h.flags, "colour-shift"), "{:?}", h.flags);
        assert!(h.colour_shift > 0.2);
        let mut s = Summary::default();
        s.add(&h.flags);
        s.add::<Flag>(&[]);
        assert_eq!(s.flagged, 1);
        assert!(s.line(2).contains("1 of 2"));
    }

    #[test]
    fn added_structure_names_an_exposure_jump_as_its_cause() {
        let flag = |exposure, levelled| Flag::StructureAdded {
            texture_kept: 1.17,
            window: 11,
            longer: Some(23),
            exposure,
            levelled,
        };
        let slow = flag(None, true).to_string();
        assert!(
            slow.contains("a slow camera") && slow.contains("--window 23"),
            "{slow}"
        );
        let jump = flag(Some(1.54), false).to_string();
        assert!(jump.contains("exposure jump: 1.54×"), "{jump}");
        assert!(
            jump.contains("--no-level-exposures") && !jump.contains("--window"),
            "{jump}"
        );
        // Levelling ran and the jump still left structure: the longer window is the advice left.
        let levelled = flag(Some(1.54), true).to_string();
        assert!(
            levelled.contains("exposure jump") && levelled.contains("--window 23"),
            "{levelled}"
        );
    }

    #[test]
    fn the_summary_line_names_a_slow_cameras_few_samples() {
        // Every photo of a slow camera's mission flagged for few samples and nothing else: the line names them
        // (it once read "40 of 40 photos flagged as likely wrong ()").
        let few = Flag::FewSamples {
            samples: 1,
            needed: 15,
            window: 31,
            whole_mission: false,
        };
        let mut s = Summary::default();
        for _ in 0..40 {
            s.add(std::slice::from_ref(&few));
        }
        let line = s.line(40);
        assert!(line.contains("40 of 40"), "{line}");
        assert!(line.contains("40 too few independent samples"), "{line}");
        assert!(!line.contains("()"), "{line}");
    }

    /// Brute force: each pixel's mean over the clamped square, summed directly in two dimensions.
    fn box_brute(v: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
        let mut out = vec![0.0; w * h];
        for y in 0..h {
            for x in 0..w {
                let (mut s, mut n) = (0.0f64, 0.0f64);
                for dy in -(r as isize)..=r as isize {
                    for dx in -(r as isize)..=r as isize {
                        let sx = (x as isize + dx).clamp(0, w as isize - 1) as usize;
                        let sy = (y as isize + dy).clamp(0, h as isize - 1) as usize;
                        if v[sy * w + sx].is_finite() {
                            s += v[sy * w + sx] as f64;
                            n += 1.0;
                        }
                    }
                }
                out[y * w + x] = (s / n) as f32;
            }
        }
        out
    }

    #[test]
    fn box_average_matches_brute_force() {
        for (w, h) in [(13usize, 7usize), (40, 25), (5, 31), (1, 9)] {
            let mut v: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 11) as f32 * 0.3).collect();
            v[(w * h) / 3] = f32::NAN;
            v[w * h - 1] = f32::INFINITY;
            for r in [1, 2, 4, 9] {
                let got = box_average(&v, w, h, r);
                let want = box_brute(&v, w, h, r);
                for (g, e) in got.iter().zip(&want) {
                    assert!((g - e).abs() < 1e-5, "{w}x{h}, r={r}: {g} vs {e}");
                }
            }
        }
    }

    #[test]
    fn monitor_scratch_gives_a_fresh_roughness_whatever_came_before() {
        let a = Raster::from_fn(64, 40, 3, |x, y, c| {
            0.2 + 0.01 * ((x * 7 + y * 3 + c) % 13) as f32
        });
        let b = Raster::from_fn(48, 30, 3, |x, y, _| {
            0.1 + 0.05 * ((x / 4 + y / 4) % 2) as f32
        });
        let mut m = Monitor::new(Thresholds::default());
        for f in [&a, &b, &a, &b] {
            assert_eq!(m.observe(f, 0.0).roughness, roughness(f));
        }
    }

    #[test]
    fn roughness_tells_a_light_cone_from_the_scene() {
        // A smooth cone: well under the threshold.
        let cone = |x: usize, y: usize| {
            let (dx, dy) = (x as f32 - 40.0, y as f32 - 25.0);
            0.05 + 0.9 * (-(dx * dx + dy * dy) / 900.0).exp()
        };
        let smooth = Raster::from_fn(80, 50, 3, |x, y, _| cone(x, y));
        let r_smooth = roughness(&smooth);
        assert!(r_smooth < 0.03, "{r_smooth}");
        let tiny = Raster::from_fn(31, 50, 3, |x, y, _| 0.5 + 0.5 * ((x + y) % 2) as f32);
        assert_eq!(roughness(&tiny), 0.0, "too small to tell");
        // The same cone times objects (dark blobs on a 6-pixel grid): the scene is in F.
        let scene = Raster::from_fn(80, 50, 3, |x, y, _| {
            let blob = (x / 3 + y / 3) % 2 == 0;
            cone(x, y) * if blob { 0.5 } else { 1.0 }
        });
        let r_scene = roughness(&scene);
        assert!(r_scene > 0.25, "{r_scene}");
        // Independent check of the definition on the scene: ln 2 / 2 apart from the blurred mean, at most.
        assert!(r_scene <= std::f32::consts::LN_2 * 0.5 + 0.05, "{r_scene}");
        let h = Monitor::new(Thresholds::default()).observe(&smooth, 0.1);
        assert!(h.flags.is_empty(), "{:?}", h.flags);
        let h = Monitor::new(Thresholds::default()).observe(&scene, 0.1);
        assert!(has(&h.flags, "scene-in-factor"), "{:?}", h.flags);
        let mut s = Summary::default();
        s.add(&h.flags);
        assert_eq!((s.roughness, s.short_mission), (1, 0));
    }

    #[test]
    fn exposure_jump_is_named_as_such_and_not_contamination() {
        // The window's M − S: a cone; the photo: the same pattern 1.6 times brighter, with some texture.
        let lit = Raster::from_fn(40, 30, 3, |x, y, c| {
            let (dx, dy) = (x as f32 - 20.0, y as f32 - 15.0);
            (0.1 + (-(dx * dx + dy * dy) / 300.0).exp()) * [1.0, 0.9, 0.7][c]
        });
        let texture = |x: usize, y: usize| 1.0 + 0.05 * (((x * 7 + y * 13) % 5) as f32 - 2.0);
        let own = Raster::from_fn(40, 30, 3, |x, y, c| 1.6 * lit.get(x, y, c) * texture(x, y));
        let fit = photo_fit(&own, &lit, None, 0.5);
        assert!((fit.level - 1.6).abs() < 0.1, "{fit:?}");
        assert_eq!(fit.contamination, 0.0);
        // The old figure (ratio against 1) would have called every block contaminated.
        assert!(contamination(&own, &lit, None, 0.5) > 0.5);
        let f = lit.clone();
        let h = Monitor::new(Thresholds::default()).observe_photo(&own, &lit, None, &f);
        assert!(
            matches!(h.flags.as_slice(), [Flag::ExposureJump { .. }]),
            "{:?}",
            h.flags
        );
        // The same photo at the window's level: no flag.
        let own = Raster::from_fn(40, 30, 3, |x, y, c| lit.get(x, y, c) * texture(x, y));
        let h = Monitor::new(Thresholds::default()).observe_photo(&own, &lit, None, &f);
        assert!(h.flags.is_empty(), "{:?}", h.flags);
        assert!((h.level - 1.0).abs() < 0.05);
    }

    /// A photo lit from another height than its window (the cone wider and shifted, the level taken out): flagged
    /// `lights-misfit` with the figure [`crate::method::stretch::lights_misfit`] gives; the same photo under its
    /// window's lights, brighter, is not. The figure is in the health either way, and the summary counts the flag.
    #[test]
    fn lights_unlike_the_window_s_are_flagged_with_their_misfit() {
        let cone = |x: usize, y: usize, cx: f32, r: f32| {
            let (dx, dy) = (x as f32 - cx, y as f32 - 15.0);
            0.05 + (-(dx * dx + dy * dy) / (r * r)).exp()
        };
        let texture = |x: usize, y: usize| 1.0 + 0.05 * (((x * 7 + y * 13) % 5) as f32 - 2.0);
        let lit = Raster::from_fn(40, 30, 3, |x, y, c| {
            cone(x, y, 20.0, 14.0) * [1.0, 0.9, 0.7][c]
        });
        let f = lit.clone();
        let swung = Raster::from_fn(40, 30, 3, |x, y, c| {
            cone(x, y, 26.0, 9.0) * [1.0, 0.9, 0.7][c] * texture(x, y)
        });
        let h = Monitor::new(Thresholds::default()).observe_photo(&swung, &lit, None, &f);
        let want = crate::method::stretch::lights_misfit(&swung, &lit, None, 0.5);
        assert!(want > Thresholds::default().lights_misfit, "{want}");
        assert_eq!(h.lights_misfit, want);
        assert!(
            h.flags
                .iter()
                .any(|g| matches!(g, Flag::LightsMisfit { misfit } if *misfit == want)),
            "{:?}",
            h.flags
        );
        let mut s = Summary::default();
        s.add(&h.flags);
        assert_eq!(s.lights_misfit, 1);
        assert!(
            s.line(1).contains("lights unlike their window's"),
            "{}",
            s.line(1)
        );
        let brighter = Raster::from_fn(40, 30, 3, |x, y, c| 1.2 * lit.get(x, y, c) * texture(x, y));
        let h = Monitor::new(Thresholds::default()).observe_photo(&brighter, &lit, None, &f);
        assert!(h.lights_misfit < 0.03, "{}", h.lights_misfit);
        assert!(!has(&h.flags, "lights-misfit"), "{:?}", h.flags);
    }

    /// Deterministic noise in `[-1, 1]` for pixel `p` (a hash; no RNG crate in the library's tests).
    fn noise(p: usize) -> f32 {
        let h = (p as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        ((h >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    }

    #[test]
    fn a_channel_without_light_neither_contaminates_nor_shifts_the_colour() {
        // A dark abyssal photo: red's M − S is 10⁻⁵ (the water took it), its I − S is noise of ±0.004; green and
        // blue are lit and match the window's M − S within 5 %.
        let lit = Raster::from_fn(40, 30, 3, |x, _, c| {
            [1e-5, 0.3, 0.25][c] * (0.5 + x as f32 / 40.0)
        });
        let own = Raster::from_fn(40, 30, 3, |x, y, c| {
            let p = y * 40 + x;
            match c {
                0 => 0.004 * noise(p),
                _ => lit.get(x, y, c) * (1.0 + 0.05 * noise(p * 3 + c)),
            }
        });
        let fit = photo_fit(&own, &lit, None, 0.5);
        assert_eq!(fit.contamination, 0.0, "{fit:?}");
        assert!((fit.level - 1.0).abs() < 0.03, "{fit:?}");
        // Independent figure, the old one: the mean of the channels' own ratios sends nearly every block off.
        let old_bad = (0..40 * 30)
            .filter(|&p| {
                let r: f32 = (0..3)
                    .map(|c| own.data[p * 3 + c] / lit.data[p * 3 + c])
                    .sum::<f32>()
                    / 3.0;
                (r - 1.0).abs() > 0.5
            })
            .count();
        assert!(old_bad > 40 * 30 * 9 / 10, "{old_bad}");
        // A block where a lit channel is far off is still counted, starved red or not.
        let mut off = own.clone();
        for p in 0..300 {
            off.data[p * 3 + 1] *= 0.2;
            off.data[p * 3 + 2] *= 0.2;
        }
        let fit = photo_fit(&off, &lit, None, 0.5);
        assert!((fit.contamination - 0.25).abs() < 0.01, "{fit:?}");

        // F over a mission: red's share is 2 % of the level and jitters by a third of itself, green and blue are
        // steady: no colour shift. Then green grows by a quarter: flagged.
        let f_with = |k: usize, red: f32, green: f32| {
            Raster::from_fn(8, 6, 3, |x, _, c| {
                (0.5 + 0.02 * x as f32) * [red * (1.0 + 0.33 * noise(k)), green, 1.0][c]
            })
        };
        let mut mon = Monitor::new(Thresholds::default());
        for k in 0..30 {
            let h = mon.observe(&f_with(k, 0.03, 1.47), 0.1);
            assert!(h.flags.is_empty(), "photo {k}: {:?}", h.flags);
        }
        let h = mon.observe(&f_with(30, 0.03, 1.47 * 1.25), 0.1);
        assert!(has(&h.flags, "colour-shift"), "{:?}", h.flags);
    }

    #[test]
    fn texture_kept_tells_a_smooth_factor_from_a_copy_of_the_scene() {
        let cone = |x: usize, y: usize| {
            let (dx, dy) = (x as f32 - 32.0, y as f32 - 20.0);
            0.2 + (-(dx * dx + dy * dy) / 900.0).exp()
        };
        let scene = |x: usize, y: usize| {
            if (x / 3 + y / 3).is_multiple_of(2) {
                0.6
            } else {
                1.0
            }
        };
        let own = Raster::from_fn(64, 40, 3, |x, y, _| cone(x, y) * scene(x, y));
        let smooth = Raster::from_fn(64, 40, 3, |x, y, _| cone(x, y) * 0.8);
        let copy = own.clone();
        let good = photo_fit(&own, &smooth, None, 0.5).texture_kept;
        let bad = photo_fit(&own, &copy, None, 0.5).texture_kept;
        assert!(good > 0.9, "{good}");
        assert!(bad < 0.05, "{bad}");
    }

    /// The texture kept alone flags `scene-in-factor` only where no survey counted the views (a window given); with
    /// one, `few-samples` names too few views and `F`'s own roughness still flags a scene in it.
    #[test]
    fn the_texture_kept_alone_flags_only_without_a_survey() {
        let cone = |x: usize, y: usize| {
            let (dx, dy) = (x as f32 - 32.0, y as f32 - 20.0);
            0.2 + (-(dx * dx + dy * dy) / 900.0).exp()
        };
        let scene = |x: usize, y: usize| 0.8 + 0.2 * ((x / 3 + y / 3) % 2) as f32;
        let own = Raster::from_fn(64, 48, 3, |x, y, _| cone(x, y) * scene(x, y));
        let flat = Raster::filled(64, 48, 3, 0.8);
        let scene_in = |views: Option<f32>| {
            let mut mon = Monitor::new(Thresholds::default()).with_window(7);
            mon.set_views(views);
            // `M − S` a copy of the photo: nothing of its texture is kept; `F` itself smooth.
            let h = mon.observe_photo(&own, &own, None, &flat);
            assert!(h.texture_kept < 0.2 && h.roughness < 0.12, "{h:?}");
            has(&h.flags, "scene-in-factor")
        };
        assert!(scene_in(None));
        for views in [1.0, 2.0, 7.0] {
            assert!(!scene_in(Some(views)), "{views} photos per view");
        }
    }

    /// `few-samples` on a window the do-no-harm check fell back to needs the photo's support: `F`'s roughness or the
    /// lights' misfit past half its own flag's threshold.
    #[test]
    fn few_views_need_the_photo_s_support() {
        let mon = Monitor::new(Thresholds::default());
        let t = Thresholds::default();
        let with = |roughness: f32, lights_misfit: f32| Health {
            roughness,
            lights_misfit,
            ..Health::default()
        };
        assert!(!mon.supports_few_views(&with(0.03, 0.004)));
        assert!(!mon.supports_few_views(&with(0.03, f32::NAN)));
        assert!(!mon.supports_few_views(&with(0.059, 0.034)));
        assert!(mon.supports_few_views(&with(0.061, 0.0)));
        assert!(mon.supports_few_views(&with(0.0, 0.036)));
        assert!(mon.supports_few_views(&with(t.roughness, 0.0)));
        // A trusted match with the photo before that hardly moves the ground (a slow camera's first photos, before
        // `camera-still` has its five matches) supports it too; a first photo (no match) does not.
        let textured =
            |x: usize, y: usize| 0.6 + 0.4 * (((x / 3) * 7 + (y / 3) * 13) % 10) as f32 / 10.0;
        let own = Raster::from_fn(64, 48, 3, |x, y, _| textured(x, y));
        let lit = Raster::filled(64, 48, 3, 0.8);
        let mut mon = Monitor::new(Thresholds::default()).with_window(7);
        mon.set_views(Some(1.0));
        let first = mon.observe_photo(&own, &lit, None, &lit);
        assert!(!mon.supports_few_views(&with(0.0, 0.0)), "{first:?}");
        let second = mon.observe_photo(&own, &lit, None, &lit);
        assert!(second.motion_ncc.unwrap() >= STILL_NCC, "{second:?}");
        assert!(mon.supports_few_views(&with(0.0, 0.0)), "{second:?}");
    }

    #[test]
    fn colour_that_follows_the_level_is_not_a_colour_shift() {
        // F at altitude `alt` in water that takes red at `red` per metre: F's level changes and red falls off
        // faster than green and blue (attenuation).
        let f_at = |red: f32, alt: f32| {
            Raster::from_fn(8, 6, 3, |x, _, c| {
                let eta = [red, 0.07, 0.09][c];
                (0.5 + 0.02 * x as f32) * (-eta * 2.0 * alt).exp() / (alt * alt)
            })
        };
        // Two missions: altitude swings of ±0.6 m at 6 m, as slow as the simulator's (0.1 rad a photo); and a
        // steady climb from 5 m to 6.8 m in redder-absorbing water, whose first photos show too small a range of
        // levels to learn the slope from.
        let swings = |i: usize| 6.0 + 0.6 * (0.1 * i as f32).sin();
        let climb = |i: usize| 5.0 + 0.03 * i as f32;
        for (red, alt, photos) in [
            (0.25, &swings as &dyn Fn(usize) -> f32, 80),
            (0.4, &climb, 60),
        ] {
            let mut mon = Monitor::new(Thresholds::default());
            for i in 0..photos {
                let h = mon.observe(&f_at(red, alt(i)), 0.1);
                assert!(h.flags.is_empty(), "photo {i}: {:?}", h.flags);
            }
            // The same level with a bluer seafloor: flagged.
            let last = alt(photos - 1);
            let blue = Raster::from_fn(8, 6, 3, |x, y, c| {
                f_at(red, last).get(x, y, c) * [0.7, 1.0, 1.25][c]
            });
            let h = mon.observe(&blue, 0.1);
            assert!(has(&h.flags, "colour-shift"), "{:?}", h.flags);
        }
    }

    /// A share past the median's breakdown point is not "near" it.
    #[test]
    fn contamination_past_half_is_said_to_be_past_it() {
        let past = Flag::Contamination { share: 0.94 }.to_string();
        assert!(past.contains("94 % is past the 50 %"), "{past}");
        let near = Flag::Contamination { share: 0.42 }.to_string();
        assert!(near.contains("42 % is near the 50 %"), "{near}");
    }

    #[test]
    fn a_jump_of_f_says_the_altitudes_the_log_gives() {
        let m = |altitude| {
            Flag::FactorChange {
                change: 0.31,
                altitude,
            }
            .to_string()
        };
        assert!(m(None).contains("(altitude or attitude jump, or a seafloor change)"));
        let said = m(Some((3.70, 3.33)));
        assert!(
            said.contains("F changed 31 %")
                && said.contains("3.33 m, the previous at 3.70 m (-10 %)"),
            "{said}"
        );
        assert!(!said.contains("hardly"), "{said}");
        let level = m(Some((3.0, 3.05)));
        assert!(level.contains("(+2 %): hardly an altitude jump"), "{level}");
    }

    #[test]
    fn flags_serialise_as_kind_and_message() {
        let f = Flag::ExposureJump { level: 1.5 };
        let v = serde_json::to_value(f).unwrap();
        assert_eq!(v["kind"], "exposure-jump");
        assert_eq!(v["message"], f.to_string());
        assert!(f.to_string().contains("+50 %"), "{f}");
        let all = [
            Flag::Contamination { share: 0.5 },
            Flag::FactorChange {
                change: 0.5,
                altitude: None,
            },
            Flag::ColourShift { shift: 0.5 },
            Flag::SceneInFactor {
                roughness: 0.2,
                texture_kept: 0.3,
            },
            Flag::ExposureJump { level: 0.5 },
            Flag::CameraStill { span: 0.1 },
            Flag::ShortMission {
                photos: 3,
                window: 7,
            },
        ];
        let mut s = Summary::default();
        s.add(&all);
        assert_eq!(
            (
                s.flagged,
                s.contamination,
                s.factor_change,
                s.colour_shift,
                s.roughness,
                s.exposure_jump,
                s.camera_still,
                s.short_mission
            ),
            (1, 1, 1, 1, 1, 1, 1, 1)
        );
        let kinds: std::collections::BTreeSet<&str> = all.iter().map(Flag::kind).collect();
        assert_eq!(kinds.len(), all.len());
    }

    #[test]
    fn a_still_camera_is_flagged_a_moving_one_is_not() {
        // Block images of ground with blobs of a few blocks, seen from a camera that moves `step` blocks a photo.
        let ground = |x: f32, y: f32| {
            let h = |i: i64, j: i64| {
                let v = (i.wrapping_mul(73_856_093) ^ j.wrapping_mul(19_349_663)).rem_euclid(1000);
                v as f32 / 1000.0
            };
            let (i, j) = ((x / 3.0).floor() as i64, (y / 3.0).floor() as i64);
            0.6 + 0.4 * h(i, j)
        };
        let run = |step: f32| {
            let mut mon = Monitor::new(Thresholds::default()).with_window(7);
            let mut last = Health::default();
            for k in 0..10 {
                let own = Raster::from_fn(64, 48, 3, |x, y, _| {
                    ground(x as f32 + step * k as f32, y as f32)
                });
                let lit = Raster::filled(64, 48, 3, 0.8);
                last = mon.observe_photo(&own, &lit, None, &lit);
            }
            last
        };
        let still = run(1.0);
        assert!(
            still
                .flags
                .iter()
                .any(|f| matches!(f, Flag::CameraStill { .. })),
            "{still:?}"
        );
        assert!((still.motion.unwrap() - 1.0).abs() < 0.3, "{still:?}");
        let moving = run(9.0);
        assert!(
            !moving
                .flags
                .iter()
                .any(|f| matches!(f, Flag::CameraStill { .. })),
            "{moving:?}"
        );
        assert!((moving.motion.unwrap() - 9.0).abs() < 0.5, "{moving:?}");
    }

    /// The match of consecutive photos flags a still camera only where the survey, where one ran, agrees that the
    /// window's photos repeat their views: a pattern fixed in the frame (the lights' edges under a swing) matches
    /// at no shift while the survey sees the ground move on.
    #[test]
    fn camera_still_needs_the_survey_to_agree_where_one_ran() {
        let fixed =
            |x: usize, y: usize| 0.6 + 0.4 * (((x / 3) * 7 + (y / 3) * 13) % 10) as f32 / 10.0;
        let run = |views: Option<f32>| {
            let mut mon = Monitor::new(Thresholds::default()).with_window(7);
            let mut still = 0;
            for _ in 0..10 {
                mon.set_views(views);
                let own = Raster::from_fn(64, 48, 3, |x, y, _| fixed(x, y));
                let lit = Raster::filled(64, 48, 3, 0.8);
                let h = mon.observe_photo(&own, &lit, None, &lit);
                still += h
                    .flags
                    .iter()
                    .any(|f| matches!(f, Flag::CameraStill { .. }))
                    as usize;
            }
            still
        };
        // No survey (a window given), or one that found the window a single view: flagged once five matches are in.
        assert_eq!(run(None), 5);
        assert_eq!(run(Some(7.0)), 5);
        assert_eq!(run(Some(STILL_VIEWS)), 5);
        // The survey found more than two views in the window: not flagged.
        assert_eq!(run(Some(1.0)), 0);
        assert_eq!(run(Some(3.4)), 0);
    }
}
