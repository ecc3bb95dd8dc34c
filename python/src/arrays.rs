//! numpy arrays to and from the library's photos, rasters and masks.
//!
//! Photos are uint8 or uint16 as the camera stored them, or float32/float64 light levels in 0..1 (held as 16-bit
//! inside, and given back as the float type they came in). Big-endian arrays are read by their values. An array
//! larger than the decoders decode ([`abysslight::io::MAX_PIXELS`], [`abysslight::io::MAX_SIDE`]) is refused
//! before anything is allocated for it, and a copy that cannot be allocated is a `MemoryError`.

use abysslight::io::{MAX_PIXELS, MAX_SIDE};
use abysslight::Mask;
use abysslight::{Layout, Samples};
use abysslight::{Photo, Raster};
use numpy::ndarray::IxDyn;
use numpy::{
    PyArray1, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyMemoryError, PyTypeError, PyValueError};
use pyo3::prelude::*;

/// The sample type of a mission's arrays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dtype {
    U8,
    U16,
    /// Light levels in 0..1, held as 16-bit.
    F32,
    F64,
}

impl Dtype {
    fn name(self) -> &'static str {
        match self {
            Dtype::U8 => "uint8",
            Dtype::U16 => "uint16",
            Dtype::F32 => "float32",
            Dtype::F64 => "float64",
        }
    }
}

/// What must agree between the arrays of one mission: size, channels, rank (HxW or HxWxC) and dtype.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shape {
    pub height: usize,
    pub width: usize,
    pub channels: usize,
    /// HxWxC (else HxW).
    pub rank3: bool,
    pub dtype: Dtype,
}

impl Shape {
    /// The shape of a photo's samples as an array (`rank3`: keep a channel axis even for one channel).
    pub fn of(l: &Layout, rank3: bool, samples: &Samples) -> Shape {
        Shape {
            height: l.height,
            width: l.width,
            channels: l.channels,
            rank3: rank3 || l.channels != 1,
            dtype: match samples {
                Samples::U8(_) => Dtype::U8,
                Samples::U16(_) => Dtype::U16,
            },
        }
    }

    /// `480x640x3 uint8`, as numpy writes shapes.
    pub fn describe(&self) -> String {
        let dtype = self.dtype.name();
        if self.rank3 {
            format!("{}x{}x{} {dtype}", self.height, self.width, self.channels)
        } else {
            format!("{}x{} {dtype}", self.height, self.width)
        }
    }

    fn dims(&self) -> Vec<usize> {
        if self.rank3 {
            vec![self.height, self.width, self.channels]
        } else {
            vec![self.height, self.width]
        }
    }
}

/// A buffer of `n` samples, or a `MemoryError` instead of an abort when it cannot be had.
fn buffer<T>(n: usize, what: &str) -> PyResult<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| {
        PyMemoryError::new_err(format!(
            "{what}: cannot allocate {} bytes for a copy of its samples",
            n.saturating_mul(std::mem::size_of::<T>())
        ))
    })?;
    Ok(v)
}

/// The array's samples, mapped by `f`, in row order (C order; other layouts are read element by element).
fn samples<T: numpy::Element + Copy, U>(
    a: &Bound<'_, PyArrayDyn<T>>,
    what: &str,
    mut f: impl FnMut(T) -> U,
) -> PyResult<Vec<U>> {
    let r = a.readonly();
    let mut v = buffer(a.len(), what)?;
    // `as_slice` also accepts Fortran order, whose samples are not in row order: C order only.
    match r.as_slice() {
        Ok(s) if a.is_c_contiguous() => v.extend(s.iter().map(|&x| f(x))),
        _ => v.extend(r.as_array().iter().map(|&x| f(x))),
    }
    Ok(v)
}

/// Refuse an array of more pixels (or a longer side) than the decoders decode, before anything is allocated.
fn check_size(height: usize, width: usize, what: &str) -> PyResult<()> {
    if (height as u64).saturating_mul(width as u64) > MAX_PIXELS {
        return Err(PyValueError::new_err(format!(
            "{what} is {height}x{width} pixels, more than the {MAX_PIXELS} abysslight decodes"
        )));
    }
    if height.max(width) > MAX_SIDE {
        return Err(PyValueError::new_err(format!(
            "{what} is {height}x{width} pixels: a side longer than the {MAX_SIDE} pixels abysslight decodes"
        )));
    }
    Ok(())
}

/// The array in native byte order: a big-endian array (`>u2`) is converted (a copy), a native one returned as is.
fn native<'py>(
    obj: &Bound<'py, PyAny>,
    untyped: &Bound<'py, PyUntypedArray>,
) -> PyResult<Bound<'py, PyAny>> {
    let dtype = untyped.dtype();
    if dtype.is_native_byteorder() == Some(false) {
        let code = format!("={}{}", dtype.kind() as char, dtype.itemsize());
        return obj.call_method1("astype", (code,));
    }
    Ok(obj.clone())
}

/// A float light level in 0..1 as a 16-bit sample, or the value that is not one.
fn level(x: f64) -> Result<u16, f64> {
    if (0.0..=1.0).contains(&x) {
        Ok((x * 65535.0).round() as u16)
    } else {
        Err(x)
    }
}

/// 16-bit samples of float light levels, or a ValueError naming a value outside 0..1.
fn levels<T: numpy::Element + Copy + Into<f64>>(
    a: &Bound<'_, PyArrayDyn<T>>,
    what: &str,
) -> PyResult<Vec<u16>> {
    let mut bad = None;
    let v = samples(a, what, |x| {
        level(x.into()).unwrap_or_else(|x| {
            bad.get_or_insert(x);
            0
        })
    })?;
    match bad {
        None => Ok(v),
        Some(x) => Err(PyValueError::new_err(format!(
            "{what} has a float sample outside 0..1 ({x}): float photos hold light levels from 0 to 1"
        ))),
    }
}

/// A photo from an HxWx3, HxWx1 or HxW array of uint8/uint16 (as stored) or float32/float64 (light levels in
/// 0..1); `what` names it in errors ("photo", "frame 3").
pub fn photo_from_array(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<(Photo, Shape)> {
    let Ok(untyped) = obj.downcast::<PyUntypedArray>() else {
        return Err(PyTypeError::new_err(format!(
            "{what} must be a numpy array (HxWx3 or HxW; uint8, uint16, or float32/float64 in 0..1), got {}",
            obj.get_type().name()?
        )));
    };
    let dims = untyped.shape().to_vec();
    let (height, width, channels, rank3) = match dims[..] {
        [h, w] => (h, w, 1, false),
        [h, w, c] if c == 1 || c == 3 => (h, w, c, true),
        _ => {
            return Err(PyValueError::new_err(format!(
                "{what} must be HxWx3 (RGB) or HxW (grey), got shape {dims:?}"
            )))
        }
    };
    if height == 0 || width == 0 {
        return Err(PyValueError::new_err(format!(
            "{what} is empty (shape {dims:?})"
        )));
    }
    check_size(height, width, what)?;
    let dtype = untyped.dtype();
    let kind = (dtype.kind(), dtype.itemsize());
    if !matches!(kind, (b'u', 1) | (b'u', 2) | (b'f', 4) | (b'f', 8)) {
        return Err(PyTypeError::new_err(format!(
            "{what} must be uint8 or uint16 (as the camera stored it) or float32/float64 (light levels in 0..1), \
             got {}",
            untyped.dtype()
        )));
    }
    let obj = native(obj, untyped)?;
    let (samples, dtype) = if let Ok(a) = obj.downcast::<PyArrayDyn<u8>>() {
        (Samples::U8(samples(a, what, |x| x)?), Dtype::U8)
    } else if let Ok(a) = obj.downcast::<PyArrayDyn<u16>>() {
        (Samples::U16(samples(a, what, |x| x)?), Dtype::U16)
    } else if let Ok(a) = obj.downcast::<PyArrayDyn<f32>>() {
        (Samples::U16(levels(a, what)?), Dtype::F32)
    } else if let Ok(a) = obj.downcast::<PyArrayDyn<f64>>() {
        (Samples::U16(levels(a, what)?), Dtype::F64)
    } else {
        return Err(PyTypeError::new_err(format!(
            "{what} must be uint8, uint16, float32 or float64, got {}",
            untyped.dtype()
        )));
    };
    let shape = Shape {
        height,
        width,
        channels,
        rank3,
        dtype,
    };
    let photo = Photo {
        layout: Layout {
            width,
            height,
            channels,
        },
        samples,
        alpha: None,
    };
    Ok((photo, shape))
}

/// A photo's samples as an array of `shape` (the photo's buffer becomes the array's: no copy; float arrays are
/// the 16-bit samples as light levels in 0..1).
pub fn array_from_photo<'py>(
    py: Python<'py>,
    photo: Photo,
    shape: Shape,
) -> PyResult<Bound<'py, PyAny>> {
    let dims = IxDyn(&shape.dims());
    Ok(match (photo.samples, shape.dtype) {
        (Samples::U16(v), Dtype::F32) => {
            let f: Vec<f32> = v.into_iter().map(|x| x as f32 / 65535.0).collect();
            PyArray1::from_vec(py, f).reshape(dims)?.into_any()
        }
        (Samples::U16(v), Dtype::F64) => {
            let f: Vec<f64> = v.into_iter().map(|x| x as f64 / 65535.0).collect();
            PyArray1::from_vec(py, f).reshape(dims)?.into_any()
        }
        (Samples::U8(v), _) => PyArray1::from_vec(py, v).reshape(dims)?.into_any(),
        (Samples::U16(v), _) => PyArray1::from_vec(py, v).reshape(dims)?.into_any(),
    })
}

/// A raster as a float32 HxWxC array.
pub fn array_from_raster<'py>(py: Python<'py>, r: &Raster) -> PyResult<Bound<'py, PyAny>> {
    let dims = IxDyn(&[r.height, r.width, r.channels]);
    Ok(PyArray1::from_slice(py, &r.data).reshape(dims)?.into_any())
}

/// A mask from an HxW array, true or non-zero where pixels are ignored.
pub fn mask_from_array(obj: &Bound<'_, PyAny>) -> PyResult<Mask> {
    let Ok(untyped) = obj.downcast::<PyUntypedArray>() else {
        return Err(PyTypeError::new_err(format!(
            "the mask must be a numpy array (HxW, bool or uint8), got {}",
            obj.get_type().name()?
        )));
    };
    let dims = untyped.shape().to_vec();
    let [height, width] = dims[..] else {
        return Err(PyValueError::new_err(format!(
            "the mask must be HxW, got shape {dims:?}"
        )));
    };
    check_size(height, width, "the mask")?;
    let ignore: Vec<bool> = if let Ok(a) = obj.downcast::<PyArrayDyn<bool>>() {
        samples(a, "the mask", |v| v)?
    } else if let Ok(a) = obj.downcast::<PyArrayDyn<u8>>() {
        samples(a, "the mask", |v| v != 0)?
    } else {
        return Err(PyTypeError::new_err(format!(
            "the mask must be bool or uint8, got {}",
            untyped.dtype()
        )));
    };
    if !ignore.iter().any(|&v| !v) {
        return Err(PyValueError::new_err(
            "the mask ignores every pixel: nothing would be left to estimate the lighting from",
        ));
    }
    Ok(Mask {
        width,
        height,
        ignore,
    })
}

/// A mask as an HxW bool array.
pub fn array_from_mask<'py>(py: Python<'py>, m: &Mask) -> PyResult<Bound<'py, PyAny>> {
    let dims = IxDyn(&[m.height, m.width]);
    Ok(PyArray1::from_slice(py, &m.ignore)
        .reshape(dims)?
        .into_any())
}
