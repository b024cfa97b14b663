//! What image decoders really allocate, against what they reserve from the decode budget
//! (`texture/decode/budget.rs`): a counting allocator watches each decode's peak, which must
//! stay within the reservation (samples the header declares × the decoder's peak factor).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use tessera_common::texture::{Bitmap, BitmapOptions, TextureLimits};

struct Counting;
static CURRENT: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let now = CURRENT.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
        PEAK.fetch_max(now, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        CURRENT.fetch_sub(layout.size(), Ordering::Relaxed);
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size > layout.size() {
            let now = CURRENT.fetch_add(new_size - layout.size(), Ordering::Relaxed) + new_size - layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        } else {
            CURRENT.fetch_sub(layout.size() - new_size, Ordering::Relaxed);
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Bytes allocated at the peak of `f` beyond what was allocated before it, and what it kept.
fn peak_of(f: impl FnOnce() -> Bitmap) -> (usize, Bitmap) {
    let before = CURRENT.load(Ordering::Relaxed);
    PEAK.store(before, Ordering::Relaxed);
    let bitmap = f();
    (PEAK.load(Ordering::Relaxed) - before, bitmap)
}

fn png(w: u32, h: u32, color: image::ExtendedColorType, bytes_per_pixel: usize) -> Vec<u8> {
    use image::ImageEncoder;
    let data: Vec<u8> = (0..w as usize * h as usize * bytes_per_pixel).map(|i| (i * 7919 % 251) as u8).collect();
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out).write_image(&data, w, h, color).expect("png");
    out
}

fn exr(w: usize, h: usize) -> Vec<u8> {
    use exr::prelude::*;
    let channels = SpecificChannels::rgb(|p: Vec2<usize>| (p.x() as f32, p.y() as f32, 0.5f32));
    let layer = Layer::new((w, h), LayerAttributes::default(), Encoding::SMALL_LOSSLESS, channels);
    let mut out = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer).write().to_buffered(&mut out).expect("exr");
    out.into_inner()
}

fn pfm(w: usize, h: usize) -> Vec<u8> {
    let mut out = format!("PF\n{w} {h}\n-1\n").into_bytes();
    (0..w * h * 3).for_each(|i| out.extend((i as f32).to_le_bytes()));
    out
}

/// One test, since the allocator's counters are the process's.
#[test]
fn decoders_stay_within_what_they_reserve() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (w, h) = (512u32, 384u32);
    // (file, bytes per pixel as the decoder reads it, its peak factor in texture/decode)
    let cases = [
        ("rgba16.png", png(w, h, image::ExtendedColorType::Rgba16, 8), 8, 4),
        ("rgb8.png", png(w, h, image::ExtendedColorType::Rgb8, 3), 3, 4),
        ("rgba8.png", png(w, h, image::ExtendedColorType::Rgba8, 4), 4, 4),
        ("rgb.exr", exr(w as usize, h as usize), 12, 6),
        ("rgb.pfm", pfm(w as usize, h as usize), 12, 4),
    ];
    for (name, bytes, bytes_per_pixel, factor) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).expect("write");
        let (peak, bitmap) =
            peak_of(|| Bitmap::load(&path, BitmapOptions::default(), &TextureLimits::DEFAULT).expect(name));
        let samples = (w * h) as usize * bytes_per_pixel;
        // the reservation, with a little room for the decoders' own state
        let reserved = samples * factor + (256 << 10);
        assert!(peak <= reserved, "{name}: peak {peak} bytes over the {reserved} reserved");
        assert!(bitmap.decoded_bytes() <= samples, "{name}");
        eprintln!("{name}: peak {:.2} × the samples (reserved {factor})", peak as f64 / samples as f64);
    }
}
