//! Pixel containers: [`Photo`] holds a decoded photo in its own sample type (8 or 16 bit), [`Raster`] holds the
//! method's estimates (S, M, F) as `f32` in the photo's normalised range `[0, 1]`.

/// A sample type a photo can be stored in (`u8` or `u16`).
pub trait Sample: Copy + Ord + Default + Send + Sync + 'static {
    /// The largest value, as `f32` (255 or 65535).
    const MAX: f32;
    /// Widen to `u16` without scaling (used for medians over mixed buffers).
    fn to_u16(self) -> u16;
    /// Round and clamp a value in sample units.
    fn from_f32(v: f32) -> Self;
    /// A code already in range (`0..=MAX`).
    fn from_code(c: u16) -> Self;
    /// The samples as bytes, for 8-bit samples (kernels specialised for them); `None` for wider ones.
    fn as_bytes(s: &[Self]) -> Option<&[u8]>;
    /// [`Sample::as_bytes`], mutable.
    fn as_bytes_mut(s: &mut [Self]) -> Option<&mut [u8]>;
}

impl Sample for u8 {
    const MAX: f32 = 255.0;
    #[inline]
    fn to_u16(self) -> u16 {
        self as u16
    }
    #[inline]
    fn from_f32(v: f32) -> Self {
        // `as` saturates and maps NaN to 0.
        (v + 0.5) as u8
    }
    #[inline]
    fn from_code(c: u16) -> Self {
        c as u8
    }
    fn as_bytes(s: &[Self]) -> Option<&[u8]> {
        Some(s)
    }
    fn as_bytes_mut(s: &mut [Self]) -> Option<&mut [u8]> {
        Some(s)
    }
}

impl Sample for u16 {
    const MAX: f32 = 65535.0;
    #[inline]
    fn to_u16(self) -> u16 {
        self
    }
    #[inline]
    fn from_f32(v: f32) -> Self {
        (v + 0.5) as u16
    }
    #[inline]
    fn from_code(c: u16) -> Self {
        c
    }
    fn as_bytes(_: &[Self]) -> Option<&[u8]> {
        None
    }
    fn as_bytes_mut(_: &mut [Self]) -> Option<&mut [u8]> {
        None
    }
}

/// Bit depth of a photo's samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum BitDepth {
    /// 8 bits a sample.
    Eight,
    /// 16 bits a sample.
    Sixteen,
}

impl BitDepth {
    /// Bits a sample.
    pub fn bits(self) -> u32 {
        match self {
            BitDepth::Eight => 8,
            BitDepth::Sixteen => 16,
        }
    }
}

/// Interleaved samples of one photo.
#[derive(Debug, Clone, PartialEq)]
pub enum Samples {
    /// 8-bit samples.
    U8(Vec<u8>),
    /// 16-bit samples.
    U16(Vec<u16>),
}

impl Samples {
    /// Number of samples.
    pub fn len(&self) -> usize {
        match self {
            Samples::U8(v) => v.len(),
            Samples::U16(v) => v.len(),
        }
    }
    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Bit depth of the samples.
    pub fn depth(&self) -> BitDepth {
        match self {
            Samples::U8(_) => BitDepth::Eight,
            Samples::U16(_) => BitDepth::Sixteen,
        }
    }
    /// Bytes held.
    pub fn bytes(&self) -> usize {
        match self {
            Samples::U8(v) => v.len(),
            Samples::U16(v) => v.len() * 2,
        }
    }
}

/// What must agree between all photos of one mission (and the scatter image).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Layout {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Colour channels: 1 (grey) or 3 (RGB). An alpha channel is carried separately and not corrected.
    pub channels: usize,
}

impl std::fmt::Display for Layout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let kind = if self.channels == 1 { "grey" } else { "RGB" };
        write!(f, "{}x{} {}", self.width, self.height, kind)
    }
}

/// A decoded photo: colour samples interleaved, in the file's own bit depth; alpha (if any) kept aside.
#[derive(Debug, Clone, PartialEq)]
pub struct Photo {
    /// Size and channel count.
    pub layout: Layout,
    /// Colour samples, interleaved, row by row.
    pub samples: Samples,
    /// Alpha plane, passed through untouched.
    pub alpha: Option<Samples>,
}

impl Photo {
    /// A caller's photo as the method needs it: a size of at least 1×1, 1 to 4 channels, as many samples as the
    /// layout says, and an alpha plane (if any) of one sample per pixel of the same depth. The engine and
    /// [`crate::Scatter::from_frames`] refuse other photos with this error rather than panic on them.
    pub fn check(&self) -> Result<(), crate::Error> {
        let l = self.layout;
        let pixels = l.width.checked_mul(l.height);
        let wanted = pixels.and_then(|p| p.checked_mul(l.channels));
        let problem = if l.width == 0 || l.height == 0 {
            Some(format!("the photo is {l}: no pixels"))
        } else if !(1..=4).contains(&l.channels) {
            Some(format!(
                "the photo has {} channels (1 to 4 are taken)",
                l.channels
            ))
        } else if wanted != Some(self.samples.len()) {
            Some(format!(
                "the photo is {l} but holds {} samples",
                self.samples.len()
            ))
        } else if let Some(a) = &self.alpha {
            (pixels != Some(a.len()) || a.depth() != self.depth()).then(|| {
                format!(
                    "its alpha plane holds {} {}-bit samples for {l}",
                    a.len(),
                    a.depth().bits()
                )
            })
        } else {
            None
        };
        match problem {
            Some(reason) => Err(crate::Error::Usage(reason)),
            None => Ok(()),
        }
    }

    /// Bit depth of the samples.
    pub fn depth(&self) -> BitDepth {
        self.samples.depth()
    }
    /// Memory held by the decoded samples.
    pub fn bytes(&self) -> usize {
        self.samples.bytes() + self.alpha.as_ref().map_or(0, Samples::bytes)
    }
}

/// An `f32` image with interleaved channels, values in the photo's normalised range (`1.0` = white).
#[derive(Debug, Clone, PartialEq)]
pub struct Raster {
    /// Width in samples.
    pub width: usize,
    /// Height in samples.
    pub height: usize,
    /// Channels per pixel.
    pub channels: usize,
    /// Samples, interleaved, row by row.
    pub data: Vec<f32>,
}

impl Raster {
    /// A raster filled with `value`.
    pub fn filled(width: usize, height: usize, channels: usize, value: f32) -> Self {
        Raster {
            width,
            height,
            channels,
            data: vec![value; width * height * channels],
        }
    }

    /// A raster whose sample `(x, y, c)` is `f(x, y, c)`.
    pub fn from_fn(
        width: usize,
        height: usize,
        channels: usize,
        mut f: impl FnMut(usize, usize, usize) -> f32,
    ) -> Self {
        let mut data = Vec::with_capacity(width * height * channels);
        for y in 0..height {
            for x in 0..width {
                for c in 0..channels {
                    data.push(f(x, y, c));
                }
            }
        }
        Raster {
            width,
            height,
            channels,
            data,
        }
    }

    /// Sample `c` of pixel `(x, y)`.
    #[inline]
    pub fn get(&self, x: usize, y: usize, c: usize) -> f32 {
        self.data[(y * self.width + x) * self.channels + c]
    }

    /// Samples of one row.
    #[inline]
    pub fn row(&self, y: usize) -> &[f32] {
        let n = self.width * self.channels;
        &self.data[y * n..(y + 1) * n]
    }

    /// Size and channel count.
    pub fn layout(&self) -> Layout {
        Layout {
            width: self.width,
            height: self.height,
            channels: self.channels,
        }
    }

    /// Per-channel mean.
    pub fn channel_means(&self) -> Vec<f64> {
        let mut sums = vec![0.0f64; self.channels];
        for px in self.data.chunks_exact(self.channels.max(1)) {
            for (s, v) in sums.iter_mut().zip(px) {
                *s += *v as f64;
            }
        }
        let n = (self.width * self.height).max(1) as f64;
        sums.iter().map(|s| s / n).collect()
    }

    /// Convert a photo's colour samples to a normalised raster.
    pub fn from_photo(photo: &Photo) -> Raster {
        let l = photo.layout;
        let data = match &photo.samples {
            Samples::U8(v) => v.iter().map(|&s| s as f32 / 255.0).collect(),
            Samples::U16(v) => v.iter().map(|&s| s as f32 / 65535.0).collect(),
        };
        Raster {
            width: l.width,
            height: l.height,
            channels: l.channels,
            data,
        }
    }

    /// [`Raster::from_photo`] in linear light: the photo's transfer curve (`transfer`, the one it was stored with)
    /// undone.
    pub fn from_photo_linear(photo: &Photo, transfer: crate::method::transfer::Transfer) -> Raster {
        let mut r = Raster::from_photo(photo);
        if !transfer.is_linear() {
            for v in &mut r.data {
                *v = transfer.to_linear(*v);
            }
        }
        r
    }

    /// Quantise to 16-bit samples (rounded, clamped to `[0, 1]`).
    pub fn to_u16(&self) -> Vec<u16> {
        self.data
            .iter()
            .map(|&v| u16::from_f32(v * 65535.0))
            .collect()
    }
}
