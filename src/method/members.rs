//! [`Members`]: the photos whose median gave one photo's `F` (its window), and whether altitude chose them.
//!
//! One value from the [`Engine`](crate::method::engine::Engine) to the run report, the console and the merge of
//! shards: a window over time is the photos nearest the photo in time; a window chosen by altitude
//! ([`crate::method::altitude`]) is the photos lit from the nearest heights, which need not be consecutive. Both are
//! a list of photos; what differs is only whether altitude chose them.

use std::ops::Range;

use serde::{Deserialize, Serialize};

/// The photos (by their index in the mission, in order) whose median gave one photo's `F`, and whether altitude
/// chose them. Never empty.
///
/// In `report.json` a frame's window is written as `"window": [first, last]`, and where altitude chose it also as
/// `"window_by_altitude": [the photos it took]`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "Written", into = "Written")]
pub struct Members {
    photos: Vec<usize>,
    by_altitude: bool,
}

impl Members {
    /// The window over time: the photos of `span` (not empty).
    pub fn over_time(span: Range<usize>) -> Self {
        assert!(!span.is_empty(), "a window holds at least its photo");
        Members {
            photos: span.collect(),
            by_altitude: false,
        }
    }

    /// The photos `photos` (in increasing order, not empty), chosen by altitude or not.
    pub fn new(photos: Vec<usize>, by_altitude: bool) -> Self {
        assert!(
            !photos.is_empty() && photos.windows(2).all(|w| w[0] < w[1]),
            "a window's photos are in order, at least one: {photos:?}"
        );
        Members {
            photos,
            by_altitude,
        }
    }

    /// The photos, in order.
    pub fn photos(&self) -> &[usize] {
        &self.photos
    }

    /// How many photos.
    #[allow(clippy::len_without_is_empty)] // never empty
    pub fn len(&self) -> usize {
        self.photos.len()
    }

    /// The first photo.
    pub fn first(&self) -> usize {
        self.photos[0]
    }

    /// The last photo.
    pub fn last(&self) -> usize {
        self.photos[self.photos.len() - 1]
    }

    /// From the first photo to one past the last (for a window over time, its photos).
    pub fn span(&self) -> Range<usize> {
        self.first()..self.last() + 1
    }

    /// Altitude chose the photos (a navigation log's altitudes swung enough around the photo).
    pub fn by_altitude(&self) -> bool {
        self.by_altitude
    }

    /// The photos, where altitude chose them.
    pub fn chosen_by_altitude(&self) -> Option<&[usize]> {
        self.by_altitude.then_some(&self.photos[..])
    }

    /// The same photos counted from another origin: each index plus `to`, minus `from` (`None` if one would fall
    /// before 0). A shard counts its photos from the first one it read; the merge counts them from the mission's.
    pub fn renumbered(&self, from: usize, to: usize) -> Option<Self> {
        let photos = (self.photos.iter())
            .map(|&p| (p + to).checked_sub(from))
            .collect::<Option<Vec<usize>>>()?;
        Some(Members {
            photos,
            by_altitude: self.by_altitude,
        })
    }
}

/// How a window is written in `report.json` (the keys of a frame it stands for).
#[derive(Serialize, Deserialize)]
struct Written {
    window: [usize; 2],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    window_by_altitude: Option<Vec<usize>>,
}

impl From<Members> for Written {
    fn from(m: Members) -> Self {
        Written {
            window: [m.first(), m.last()],
            window_by_altitude: m.by_altitude.then_some(m.photos),
        }
    }
}

impl TryFrom<Written> for Members {
    type Error = String;

    fn try_from(w: Written) -> Result<Self, String> {
        let [first, last] = w.window;
        match w.window_by_altitude {
            None if first <= last => Ok(Members::over_time(first..last + 1)),
            None => Err(format!("window [{first}, {last}] ends before it starts")),
            Some(photos)
                if photos.windows(2).all(|p| p[0] < p[1])
                    && photos.first() == Some(&first)
                    && photos.last() == Some(&last) =>
            {
                Ok(Members::new(photos, true))
            }
            Some(photos) => Err(format!(
                "window_by_altitude {photos:?} is not the photos of window [{first}, {last}] in order"
            )),
        }
    }
}

/// A number of a record that is `NaN` where nothing was measured, as `serde_json` writes it: `null`, read back as
/// `NaN`. For `#[serde(deserialize_with = "...")]`.
pub(crate) fn null_is_nan<'de, D, F>(d: D) -> Result<F, D::Error>
where
    D: serde::Deserializer<'de>,
    F: Deserialize<'de> + Nan,
{
    Ok(Option::<F>::deserialize(d)?.unwrap_or(F::NAN))
}

/// A list of [`null_is_nan`] numbers.
pub(crate) fn nulls_are_nan<'de, D, F>(d: D) -> Result<Vec<F>, D::Error>
where
    D: serde::Deserializer<'de>,
    F: Deserialize<'de> + Nan,
{
    Ok(Vec::<Option<F>>::deserialize(d)?
        .into_iter()
        .map(|v| v.unwrap_or(F::NAN))
        .collect())
}

/// A float type's `NaN`.
pub(crate) trait Nan {
    /// `NaN`.
    const NAN: Self;
}

impl Nan for f32 {
    const NAN: f32 = f32::NAN;
}

impl Nan for f64 {
    const NAN: f64 = f64::NAN;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_is_written_as_the_report_wrote_it_and_read_back() {
        let time = Members::over_time(3..8);
        let json = serde_json::to_string(&time).unwrap();
        assert_eq!(json, r#"{"window":[3,7]}"#);
        assert_eq!(serde_json::from_str::<Members>(&json).unwrap(), time);
        assert_eq!(
            (time.len(), time.span(), time.chosen_by_altitude()),
            (5, 3..8, None)
        );

        let chosen = Members::new(vec![2, 4, 5, 9], true);
        let json = serde_json::to_string(&chosen).unwrap();
        assert_eq!(json, r#"{"window":[2,9],"window_by_altitude":[2,4,5,9]}"#);
        let back: Members = serde_json::from_str(&json).unwrap();
        assert_eq!(back, chosen);
        assert_eq!((back.len(), back.span()), (4, 2..10));
        assert_eq!(back.chosen_by_altitude(), Some(&[2, 4, 5, 9][..]));
        // Consecutive photos that altitude chose stay chosen by altitude.
        let consecutive = Members::new(vec![4, 5, 6], true);
        let back: Members =
            serde_json::from_str(&serde_json::to_string(&consecutive).unwrap()).unwrap();
        assert!(back.by_altitude() && back == consecutive);
    }

    #[test]
    fn a_window_that_contradicts_itself_is_refused() {
        for bad in [
            r#"{"window":[7,3]}"#,
            r#"{"window":[2,9],"window_by_altitude":[2,4,8]}"#,
            r#"{"window":[2,9],"window_by_altitude":[2,5,4,9]}"#,
            r#"{"window":[2,9],"window_by_altitude":[]}"#,
        ] {
            assert!(serde_json::from_str::<Members>(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn renumbering_shifts_every_photo() {
        let m = Members::new(vec![2, 4, 5, 9], true);
        assert_eq!(
            m.renumbered(2, 20).unwrap(),
            Members::new(vec![20, 22, 23, 27], true)
        );
        assert_eq!(
            Members::over_time(1..4).renumbered(1, 0).unwrap(),
            Members::over_time(0..3)
        );
        assert_eq!(m.renumbered(3, 0), None);
    }

    #[test]
    fn null_numbers_come_back_as_nan() {
        #[derive(Deserialize)]
        struct R {
            #[serde(deserialize_with = "null_is_nan")]
            a: f32,
            #[serde(deserialize_with = "nulls_are_nan")]
            b: Vec<f64>,
        }
        let r: R = serde_json::from_str(r#"{"a":null,"b":[1.5,null]}"#).unwrap();
        assert!(r.a.is_nan() && r.b[0] == 1.5 && r.b[1].is_nan());
        let r: R = serde_json::from_str(r#"{"a":0.25,"b":[]}"#).unwrap();
        assert_eq!(r.a, 0.25);
    }
}
