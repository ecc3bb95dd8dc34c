//! numpy arrays to and from the library's photos, rasters and masks.

use abysslight::Mask;
use abysslight::{Layout, Samples};
use abysslight::{Photo, Raster};
use numpy::ndarray::IxDyn;
use numpy::{PyArray1, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

/// What must agree between the arrays of one mission: size, channels, rank (HxW or HxWxC) and dtype.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shape {
    pub height: usize,
    pub width: usize,
    pub channels: usize,
    /// HxWxC (else HxW).
    pub rank3: bool,
    pub sixteen: bool,
}

impl Shape {
    /// The shape of a photo's samples as an array (`rank3`: keep a channel axis even for one channel).
    pub fn of(l: &Layout, rank3: bool, samples: &Samples) -> Shape {
        Shape {
            height: l.height,
            width: l.width,
            channels: l.channels,
            rank3: rank3 || l.channels != 1,
            sixteen: matches!(samples, Samples::U16(_)),
        }
    }

    /// `480x640x3 uint8`, as numpy writes shapes.
    pub fn describe(&self) -> String {
        let dtype = if self.sixteen { "uint16" } else { "uint8" };
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

/// The array's samples, without a copy when it is C-contiguous (the library then copies them once into its own
/// photo, which the engine keeps for the window).
fn samples<T: numpy::Element + Copy>(a: &Bound<'_, PyArrayDyn<T>>) -> Vec<T> {
    let r = a.readonly();
    // `as_slice` also accepts Fortran order, whose samples are not in row order: C order only.
    match r.as_slice() {
        Ok(s) if a.is_c_contiguous() => s.to_vec(),
        _ => r.as_array().iter().copied().collect(),
    }
}

/// A photo from an HxWx3, HxWx1 or HxW uint8/uint16 array; `what` names it in errors ("photo", "frame 3").
pub fn photo_from_array(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<(Photo, Shape)> {
    let Ok(untyped) = obj.downcast::<PyUntypedArray>() else {
        return Err(PyTypeError::new_err(format!(
            "{what} must be a numpy array (HxWx3 or HxW, uint8 or uint16), got {}",
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
    let layout = Layout {
        width,
        height,
        channels,
    };
    let (samples, sixteen) = if let Ok(a) = obj.downcast::<PyArrayDyn<u8>>() {
        (Samples::U8(samples(a)), false)
    } else if let Ok(a) = obj.downcast::<PyArrayDyn<u16>>() {
        (Samples::U16(samples(a)), true)
    } else {
        return Err(PyTypeError::new_err(format!(
            "{what} must be uint8 or uint16 (as the camera stored it), got {}",
            untyped.dtype().str()?
        )));
    };
    let shape = Shape {
        height,
        width,
        channels,
        rank3,
        sixteen,
    };
    let photo = Photo {
        layout,
        samples,
        alpha: None,
    };
    Ok((photo, shape))
}

/// A photo's samples as an array of `shape` (the photo's buffer becomes the array's: no copy).
pub fn array_from_photo<'py>(
    py: Python<'py>,
    photo: Photo,
    shape: Shape,
) -> PyResult<Bound<'py, PyAny>> {
    let dims = IxDyn(&shape.dims());
    Ok(match photo.samples {
        Samples::U8(v) => PyArray1::from_vec(py, v).reshape(dims)?.into_any(),
        Samples::U16(v) => PyArray1::from_vec(py, v).reshape(dims)?.into_any(),
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
    let ignore: Vec<bool> = if let Ok(a) = obj.downcast::<PyArrayDyn<bool>>() {
        samples(a)
    } else if let Ok(a) = obj.downcast::<PyArrayDyn<u8>>() {
        samples(a).into_iter().map(|v| v != 0).collect()
    } else {
        return Err(PyTypeError::new_err(format!(
            "the mask must be bool or uint8, got {}",
            untyped.dtype().str()?
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
