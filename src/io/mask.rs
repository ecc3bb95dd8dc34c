//! Mask images (`--mask`, `_abysslight/mask-auto.png`): white = not seafloor.

use std::path::Path;

use crate::error::Result;
use crate::method::mask::Mask;
use crate::method::raster::{Layout, Photo, Raster, Samples};

impl Mask {
    /// Load a mask image: white (brighter than mid-grey) = ignore. A mask that ignores every pixel is refused
    /// here, whatever it is used for: nothing would be left to estimate the lighting from (a run without a water
    /// column would otherwise write its photos unchanged and call them sound).
    pub fn load(path: &Path) -> Result<Mask> {
        let photo = crate::io::decode(path)?;
        let r = Raster::from_photo(&photo);
        let ignore = r
            .data
            .chunks_exact(r.channels)
            .map(|px| px.iter().sum::<f32>() / px.len() as f32 > 0.5)
            .collect();
        let mask = Mask {
            width: r.width,
            height: r.height,
            ignore,
        };
        if mask.count() == mask.ignore.len() {
            return Err(crate::error::Error::Mismatch {
                path: path.to_owned(),
                reason: "mask ignores every pixel: nothing is left to estimate the lighting from (white marks \
                         what is not seafloor: is the mask inverted?)"
                    .into(),
            });
        }
        Ok(mask)
    }

    /// Save as an 8-bit grey PNG (white = ignored).
    pub fn save(&self, path: &Path) -> Result<()> {
        let photo = Photo {
            layout: Layout {
                width: self.width,
                height: self.height,
                channels: 1,
            },
            samples: Samples::U8(
                self.ignore
                    .iter()
                    .map(|&m| if m { 255 } else { 0 })
                    .collect(),
            ),
            alpha: None,
        };
        crate::io::write_atomic(&photo, path, Default::default())
    }
}
