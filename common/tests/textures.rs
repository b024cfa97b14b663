//! Textures against Mitsuba 3.9.1: `bitmap` (every file format, wrap mode, filter, `raw`,
//! `to_uv`, padding), `checkerboard` (`eval` and its inverted `eval_1`) and `mesh_attribute`
//! lookups compared with golden values from Mitsuba's Python API, plus the loader's failure
//! modes and a check that lookups never allocate.
//!
//! The goldens in `data/texture-goldens.json` were computed from the same files as this test
//! uses (`common/tests/data/textures/`) by
//!
//! ```text
//! pip install mitsuba numpy
//! python3 scripts/texture-goldens.py > common/tests/data/texture-goldens.json
//! ```

use glam::{Mat3, Mat4, Vec2, Vec3};
use serde::Deserialize;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::{Path, PathBuf};
use tessera_common::math::Rgb;
use tessera_common::texture::{
    Bitmap, BitmapOptions, Checkerboard, FilterType, MeshAttribute, MeshAttributeTexture, MeshPoint, Storage, Texture,
    TextureError, TextureLimits, TexturePoint, Usage, UvTransform, WrapMode,
};

/// Lookups: (uv, eval, eval_1).
type Samples = Vec<([f32; 2], [f32; 3], f32)>;

/// (name, scale, face, vertices, barycentrics, eval, eval_1 or null where Mitsuba throws).
type MeshLookup = (String, f32, u32, [u32; 3], [f32; 3], [f32; 3], Option<f32>);

/// Everything `scripts/texture-goldens.py` computed with Mitsuba.
#[derive(Deserialize)]
struct Goldens {
    bitmap: Vec<BitmapCase>,
    checkerboard: Vec<BoardCase>,
    /// The quad's attributes: (name, components, data).
    mesh_attributes: Vec<(String, usize, Vec<f32>)>,
    mesh_lookups: Vec<MeshLookup>,
}

/// One `bitmap` configuration and its lookups.
#[derive(Deserialize)]
struct BitmapCase {
    file: String,
    wrap: String,
    filter: String,
    raw: bool,
    to_uv: Option<ToUv>,
    /// Stored as half floats decoded from 16-bit sRGB: see [`tolerance`].
    half_rounding: bool,
    mean: f32,
    samples: Samples,
}

/// One `checkerboard` configuration (`None` = Mitsuba's default colour) and its lookups.
#[derive(Deserialize)]
struct BoardCase {
    color0: Option<Color>,
    color1: Option<Color>,
    to_uv: Option<ToUv>,
    mean: f32,
    samples: Samples,
}

/// A checkerboard colour as the script gave it to Mitsuba.
#[derive(Deserialize)]
#[serde(rename_all = "lowercase")]
enum Color {
    Float(f32),
    Rgb([f32; 3]),
    Bitmap(String),
}

/// A `to_uv` matrix, rows as written.
#[derive(Deserialize)]
#[serde(rename_all = "lowercase")]
enum ToUv {
    Mat3([[f32; 3]; 3]),
    Mat4([[f32; 4]; 4]),
}

fn goldens() -> Goldens {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/texture-goldens.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn data(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/textures").join(file)
}

fn to_uv(m: &Option<ToUv>) -> UvTransform {
    match m {
        None => UvTransform::IDENTITY,
        // glam takes columns: the transpose of the rows
        Some(ToUv::Mat3(rows)) => UvTransform::from_mat3(Mat3::from_cols_array_2d(rows).transpose()),
        Some(ToUv::Mat4(rows)) => UvTransform::from_mat4(Mat4::from_cols_array_2d(rows).transpose()),
    }
}

fn options(case: &BitmapCase) -> BitmapOptions {
    let wrap = match case.wrap.as_str() {
        "repeat" => WrapMode::Repeat,
        "mirror" => WrapMode::Mirror,
        "clamp" => WrapMode::Clamp,
        other => panic!("unknown wrap mode {other}"),
    };
    let filter = match case.filter.as_str() {
        "bilinear" => FilterType::Bilinear,
        "nearest" => FilterType::Nearest,
        other => panic!("unknown filter {other}"),
    };
    BitmapOptions { raw: case.raw, filter, wrap, to_uv: to_uv(&case.to_uv) }
}

/// 1e-5, except where Mitsuba stores half floats that it rounded from its own sRGB curve (a
/// rational fit): for 46 of the 65536 16-bit codes that rounds to the neighbouring half, one
/// half ulp (2⁻¹⁰ relative) away from the correctly rounded value we store, and a blend of such
/// texels can be off by that much. The script sets `half_rounding` only for images that
/// contain such a code (the committed ones contain none).
fn tolerance(expected: f32, half_rounding: bool) -> f32 {
    1e-5 + if half_rounding { expected.abs() * (1.0 / 1024.0) } else { 0.0 }
}

fn close(got: f32, expected: f32, tol: f32) -> bool {
    (got - expected).abs() <= tol
}

fn load(file: &str, options: BitmapOptions) -> Bitmap {
    Bitmap::load(&data(file), options, &TextureLimits::default()).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn bitmap_matches_mitsuba_goldens() {
    let mut failures = Vec::new();
    let mut checked = 0;
    for case in &goldens().bitmap {
        let tex = Texture::from(load(&case.file, options(case)));
        let what = format!(
            "{} wrap={} filter={} raw={} to_uv={}",
            case.file,
            case.wrap,
            case.filter,
            case.raw,
            case.to_uv.is_some()
        );
        let mean = tex.mean().expect("bitmaps have a mean");
        if !close(mean, case.mean, tolerance(case.mean, case.half_rounding)) {
            failures.push(format!("{what}: mean {mean} != {}", case.mean));
        }
        for &(uv, rgb, y) in &case.samples {
            let p = TexturePoint::uv(Vec2::from(uv));
            let (got, got_y) = (tex.eval(&p), tex.eval_1(&p));
            let ok = (0..3).all(|c| close(got[c], rgb[c], tolerance(rgb[c], case.half_rounding)))
                && close(got_y, y, tolerance(y, case.half_rounding));
            if !ok {
                failures.push(format!("{what} uv={uv:?}: got {got:?} / {got_y}, mitsuba {rgb:?} / {y}"));
            }
            checked += 1;
        }
    }
    assert!(failures.is_empty(), "{} of {checked} lookups differ:\n{}", failures.len(), failures.join("\n"));
}

fn board_color(c: &Option<Color>, default: f32) -> Texture {
    match c {
        None => Texture::uniform(default),
        Some(Color::Float(v)) => Texture::uniform(*v),
        Some(Color::Rgb(v)) => Texture::rgb(Rgb::from_array(*v)),
        Some(Color::Bitmap(file)) => load(file, BitmapOptions::default()).into(),
    }
}

#[test]
fn checkerboard_matches_mitsuba_goldens() {
    for case in &goldens().checkerboard {
        let board =
            Checkerboard::new(board_color(&case.color0, 0.4), board_color(&case.color1, 0.2), to_uv(&case.to_uv));
        let tex = Texture::from(board);
        assert!(close(tex.mean().unwrap(), case.mean, 1e-6), "mean {:?} != {}", tex.mean(), case.mean);
        for &(uv, rgb, y) in &case.samples {
            let p = TexturePoint::uv(Vec2::from(uv));
            let got = tex.eval(&p);
            assert!((0..3).all(|c| close(got[c], rgb[c], 1e-5)), "uv {uv:?}: eval {got:?}, mitsuba {rgb:?}");
            assert!(close(tex.eval_1(&p), y, 1e-5), "uv {uv:?}: eval_1 {}, mitsuba {y}", tex.eval_1(&p));
        }
    }
}

#[test]
fn mesh_attribute_matches_mitsuba_goldens() {
    let goldens = goldens();
    let attrs: Vec<MeshAttribute> = goldens
        .mesh_attributes
        .iter()
        .map(|(name, components, values)| MeshAttribute::new(name, *components, values.clone()).unwrap())
        .collect();
    for (name, scale, face, vertices, b, rgb, y) in goldens.mesh_lookups {
        let name = name.as_str();
        let tex = Texture::from(MeshAttributeTexture::new(name, scale).unwrap());
        tex.check_attributes(&attrs, Usage::Color).unwrap();
        let hit = MeshPoint { attributes: &attrs, face, vertices, barycentric: Vec3::from(b) };
        let p = TexturePoint::on_mesh(Vec2::ZERO, hit);
        let got = tex.eval(&p);
        assert!((0..3).all(|c| close(got[c], rgb[c], 1e-6)), "{name} {b:?}: eval {got:?}, mitsuba {rgb:?}");
        match y {
            // Mitsuba throws for eval_1 of a 3-component attribute; the check refuses it up front
            None => assert!(tex.check_attributes(&attrs, Usage::Scalar).is_err()),
            Some(y) => {
                assert!(close(tex.eval_1(&p), y, 1e-6), "{name} {b:?}: eval_1 {}, mitsuba {y}", tex.eval_1(&p))
            }
        }
    }
}

#[test]
fn bitmap_storage_keeps_source_precision() {
    let d = BitmapOptions::default();
    let cases = [
        ("rgb8.png", BitmapOptions::default(), Storage::U8Srgb, 4 * 3 * 3),
        ("rgb8.png", BitmapOptions { raw: true, ..d }, Storage::U8Linear, 4 * 3 * 3),
        ("gray8.png", d, Storage::U8Srgb, 3 * 2),
        ("rgb16.png", d, Storage::F16, 4 * 3 * 3 * 2),
        ("ya16.png", d, Storage::F16, 3 * 2 * 2),
        ("rgba16.exr", d, Storage::F16, 3 * 2 * 3 * 2),
        ("rgb32.exr", d, Storage::F32, 4 * 3 * 3 * 4),
        ("rgb.hdr", d, Storage::F32, 4 * 3 * 3 * 4),
        ("tiny1x1.png", d, Storage::U8Srgb, 2 * 2 * 3),
        ("tiny1x3.png", d, Storage::U8Srgb, 2 * 3 * 3),
    ];
    for (file, opts, storage, bytes) in cases {
        let tex = load(file, opts);
        assert_eq!((tex.storage(), tex.decoded_bytes()), (storage, bytes), "{file}");
        assert_eq!(Texture::from(tex).decoded_bytes(), bytes);
    }
}

fn expect_err(path: &Path, limits: &TextureLimits) -> TextureError {
    match Bitmap::load(path, BitmapOptions::default(), limits) {
        Ok(_) => panic!("{} loaded", path.display()),
        Err(e) => e,
    }
}

/// A PNG declaring `w`×`h` RGBA8 whose pixel data is a bare zlib header: it can be measured
/// but not decoded.
fn png_header_only(w: u32, h: u32) -> Vec<u8> {
    let mut ihdr = b"IHDR".to_vec();
    ihdr.extend(w.to_be_bytes());
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([8, 6, 0, 0, 0]);
    let mut out = vec![0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];
    for chunk in [ihdr, b"IDAT\x78\x9c".to_vec()] {
        out.extend((chunk.len() as u32 - 4).to_be_bytes());
        out.extend(&chunk);
        out.extend(crc32(&chunk).to_be_bytes());
    }
    out
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

#[test]
fn bitmap_over_budget_is_refused_from_the_header() {
    let dir = tempfile::tempdir().unwrap();
    // 60000×50000 RGBA8 = 12 GB declared, and no pixel data: only the header can have been read,
    // or this would be a corrupt-file error
    let huge = dir.path().join("huge.png");
    std::fs::write(&huge, png_header_only(60_000, 50_000)).unwrap();
    match expect_err(&huge, &TextureLimits::default()) {
        TextureError::OverBudget { width, height, needed, limit, .. } => {
            assert_eq!((width, height, needed, limit), (60_000, 50_000, 12_000_000_000, 1 << 30));
        }
        e => panic!("expected over budget, got {e}"),
    }
    // the same file at a size within budget gets as far as decoding, and fails there
    let small = dir.path().join("small.png");
    std::fs::write(&small, png_header_only(4, 4)).unwrap();
    assert!(matches!(expect_err(&small, &TextureLimits::default()), TextureError::Corrupt { .. }));
    let hdr = dir.path().join("huge.hdr");
    std::fs::write(&hdr, b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 40000 +X 40000\n").unwrap();
    assert!(matches!(expect_err(&hdr, &TextureLimits::default()), TextureError::OverBudget { .. }));

    // a real file just over a small budget: the message names the file and both sizes
    let tight = TextureLimits::total(35);
    let e = expect_err(&data("rgb8.png"), &tight);
    let msg = e.to_string();
    assert!(msg.contains("rgb8.png") && msg.contains("36 bytes") && msg.contains("35 bytes"), "{msg}");
    assert!(Bitmap::load(&data("rgb8.png"), BitmapOptions::default(), &TextureLimits::total(36)).is_ok());
    let exr = expect_err(&data("rgb32.exr"), &TextureLimits::total(100));
    assert!(matches!(exr, TextureError::OverBudget { needed: 144, .. }), "{exr}");
}

#[test]
fn bitmap_missing_file_is_not_found() {
    let e = expect_err(Path::new("/nonexistent/wood.png"), &TextureLimits::default());
    assert!(matches!(e, TextureError::NotFound { .. }));
    assert!(e.to_string().contains("/nonexistent/wood.png"), "{e}");
}

#[test]
fn bitmap_unknown_extension_lists_supported_formats() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("leaf.webp");
    std::fs::write(&path, b"RIFF\0\0\0\0WEBPVP8 ").unwrap();
    let e = expect_err(&path, &TextureLimits::default());
    assert!(matches!(&e, TextureError::UnknownFormat { extension, .. } if extension == "webp"), "{e}");
    let msg = e.to_string();
    assert!(msg.contains("leaf.webp") && msg.contains("\"webp\"") && msg.contains("OpenEXR (.exr)"), "{msg}");
}

#[test]
fn bitmap_corrupt_files_are_errors_not_panics() {
    let dir = tempfile::tempdir().unwrap();
    let mut cases: Vec<(String, Vec<u8>)> = Vec::new();
    // every committed image cut short, and with its body overwritten by garbage
    for file in [
        "rgb8.png",
        "rgb16.png",
        "rgb32.exr",
        "rgba16.exr",
        "rgb.hdr",
        "rgb.jpg",
        "rgb.bmp",
        "rgb.tga",
        "gray.pfm",
        "rgb.ppm",
    ] {
        let bytes = std::fs::read(data(file)).unwrap();
        for cut in [bytes.len() / 2, 12.min(bytes.len())] {
            cases.push((format!("cut{cut}-{file}"), bytes[..cut].to_vec()));
        }
        let mut garbled = bytes.clone();
        for (i, b) in garbled.iter_mut().enumerate().skip(8) {
            *b = (i as u8).wrapping_mul(151).wrapping_add(7);
        }
        cases.push((format!("garbled-{file}"), garbled));
    }
    cases.push(("empty.png".into(), Vec::new()));
    cases.push(("zero.png".into(), png_header_only(0, 0)));
    cases.push(("notes.txt".into(), b"not an image".to_vec()));
    for (name, bytes) in cases {
        let path = dir.path().join(&name);
        std::fs::write(&path, bytes).unwrap();
        let e = expect_err(&path, &TextureLimits::default());
        assert!(
            matches!(
                e,
                TextureError::Corrupt { .. } | TextureError::Unsupported { .. } | TextureError::UnknownFormat { .. }
            ),
            "{name}: {e}"
        );
        assert!(e.to_string().contains(&name), "{e}");
    }
}

struct Counting;

thread_local! {
    /// Allocations made by this thread only (not the harness's other threads).
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn texture_lookups_do_not_allocate() {
    let attrs = vec![MeshAttribute::new("vertex_color", 3, vec![0.5; 9]).unwrap()];
    let textures: Vec<Texture> = vec![
        Texture::rgb(Rgb::new(0.1, 0.2, 0.3)),
        load("rgb8.png", BitmapOptions::default()).into(),
        load("rgb16.png", BitmapOptions { wrap: WrapMode::Mirror, ..Default::default() }).into(),
        load("rgb32.exr", BitmapOptions { filter: FilterType::Nearest, ..Default::default() }).into(),
        load("gray8.png", BitmapOptions { raw: true, wrap: WrapMode::Clamp, ..Default::default() }).into(),
        Checkerboard::new(
            load("rgba16.exr", BitmapOptions::default()).into(),
            Texture::uniform(0.2),
            UvTransform::IDENTITY,
        )
        .into(),
        MeshAttributeTexture::new("vertex_color", 2.0).unwrap().into(),
    ];
    let hit = MeshPoint { attributes: &attrs, face: 0, vertices: [0, 1, 2], barycentric: Vec3::splat(1.0 / 3.0) };
    let mut sum = 0.0;
    let mut run = |n: usize| {
        for i in 0..n {
            let uv = Vec2::new(i as f32 * 0.0137 - 3.0, i as f32 * -0.0071 + 2.0);
            let p = TexturePoint::on_mesh(uv, hit);
            for t in &textures {
                sum += t.eval(&p).x + t.eval_1(&p);
            }
        }
    };
    run(10); // first use initialises the sRGB table
    let before = ALLOCATIONS.with(|c| c.get());
    run(20_000);
    let after = ALLOCATIONS.with(|c| c.get());
    assert_eq!(after - before, 0, "lookups allocated");
    assert!(sum.is_finite());
}
