//! Mask images (`--mask`, `_abysslight/mask-auto.png`): white = not seafloor.

use std::path::Path;

use crate::error::Result;
use crate::method::mask::Mask;
use crate::method::raster::{Layout, Photo, Raster, Samples};

impl Mask {
    /// Load a mask image: white (brighter than mid-grey) = ignore.
    pub fn load(path: &Path) -> Result<Mask> {
        let photo = crate::io::decode(path)?;
        let r = Raster::from_photo(&photo);
        let ignore = r
            .data
            .chunks_exact(r.channels)
            .map(|px| px.iter().sum::<f32>() / px.len() as f32 > 0.5)
            .collect();
        Ok(Mask {
            width: r.width,
            height: r.height,
            ignore,
        })
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
