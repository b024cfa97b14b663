//! Fuzzes the image decoders behind `tessera_common::texture::Bitmap::load` (PNG, JPEG,
//! OpenEXR, Radiance HDR, BMP, TGA, PFM, PPM) within a 16 MiB decode budget. The format is
//! found from the file's magic bytes; the file is named `texture.tga`, so input without a known
//! magic goes to the TGA decoder (as a hostile scene can make happen by naming a file `.tga`).
//! The decoders' panics are caught by `Bitmap::load` itself and tolerated here, each reported
//! once (see `tessera_fuzz::tolerate_caught_panics`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use tessera_common::texture::{Bitmap, BitmapOptions};

fuzz_target!(|data: &[u8]| {
    let path = tessera_fuzz::write("texture.tga", data);
    tessera_fuzz::tolerate_caught_panics(data, || {
        let Ok(bitmap) = Bitmap::load(&path, BitmapOptions::default(), &tessera_fuzz::texture_limits()) else { return };
        // what a lookup reads must be in bounds and the budget kept
        let _ = bitmap.eval(glam::Vec2::new(0.5, 0.5));
        assert!(bitmap.decoded_bytes() as u64 <= tessera_fuzz::TEXTURE_BUDGET, "decoded past the budget");
    });
});
