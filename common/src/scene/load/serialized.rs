//! Mitsuba's `serialized` meshes (`src/shapes/serialized.cpp`): a little-endian file of one or
//! more meshes, each a 4-byte header (0x041C, version 3 or 4) and a zlib stream holding flags,
//! (version 4) a NUL-terminated name, the vertex and face counts, positions, optional normals,
//! uvs and colours (f32 or f64) and 32-bit triangle indices. Several meshes are followed by a
//! table of their offsets and their count; `shape_index` picks one.
//!
//! Counts come from the file, so nothing is allocated for them up front: data is read as it
//! decompresses and a file that ends early is an error, whatever counts it claims. A mesh
//! inflates to at most [`MAX_INFLATE_RATIO`] times the compressed bytes it starts at, and
//! counts that need more are refused before anything is read.

use crate::scene::error::SceneError;
use crate::scene::shape::Mesh;
use flate2::read::ZlibDecoder;
use glam::{Vec2, Vec3};
use std::io::Read;
use std::path::Path;

const HEADER: u16 = 0x041C;
const HAS_NORMALS: u32 = 0x0001;
const HAS_TEXCOORDS: u32 = 0x0002;
const HAS_COLORS: u32 = 0x0008;
const DOUBLE_PRECISION: u32 = 0x2000;

/// Loads mesh `shape_index` of a serialized file: positions, normals (if stored) and uvs (if
/// stored, unflipped, as Mitsuba reads them); colours are skipped, as Mitsuba skips them.
pub fn load_serialized(path: &Path, shape_index: u32) -> Result<Mesh, SceneError> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::file(path, format!("cannot read mesh: {e}")))?;
    load_serialized_bytes(path, &bytes, shape_index)
}

/// Loads mesh `shape_index` of serialized data; `path` names it in messages.
pub fn load_serialized_bytes(path: &Path, bytes: &[u8], shape_index: u32) -> Result<Mesh, SceneError> {
    let bad = |why: String| SceneError::file(path, format!("invalid serialized mesh: {why}"));
    let u16_at = |at: usize| bytes.get(at..at + 2).map(|b| u16::from_le_bytes([b[0], b[1]]));
    let (format, version) = (u16_at(0).ok_or_else(|| bad("too short".into()))?, u16_at(2).unwrap_or(0));
    if format != HEADER {
        return Err(bad(format!("the file starts with {format:#06x}, not {HEADER:#06x}")));
    }
    if version != 3 && version != 4 {
        return Err(bad(format!("version {version} (3 and 4 are supported)")));
    }
    let start = if shape_index == 0 { 4 } else { substream_offset(&bytes, version, shape_index).map_err(bad)? + 4 };
    let stream = bytes.get(start..).ok_or_else(|| bad("mesh offset past the end of the file".into()))?;
    let limit = (stream.len() as u64).saturating_mul(MAX_INFLATE_RATIO).max(MIN_INFLATE_LIMIT);
    // buffered: the name is read a byte at a time
    let inner = std::io::BufReader::new(ZlibDecoder::new(stream));
    read_mesh(&mut Inflated { inner, left: limit, limit }, version).map_err(bad)
}

/// How much a mesh may inflate: zlib can reach about 1000:1, but vertex positions hardly
/// compress and real meshes shrink to a half or a third; a mesh that claims more is refused
/// before it costs memory out of proportion to the file.
const MAX_INFLATE_RATIO: u64 = 64;
/// The longest mesh name read (and dropped).
const MAX_NAME_BYTES: usize = 4096;
/// What any mesh may inflate to, however small its file.
const MIN_INFLATE_LIMIT: u64 = 1 << 20;

/// A reader that fails once more than `limit` bytes have come out of `inner`.
struct Inflated<R> {
    inner: R,
    left: u64,
    limit: u64,
}

impl<R: Read> Inflated<R> {
    /// Fails if `bytes` more cannot come out (a declared size, checked before it is read).
    fn expect(&self, bytes: u64, what: &str) -> Result<(), String> {
        if bytes > self.left {
            return Err(format!(
                "the {what} need {bytes} bytes, more than the file can inflate to ({} bytes: {MAX_INFLATE_RATIO} times its compressed size)",
                self.limit
            ));
        }
        Ok(())
    }
}

impl<R: Read> Read for Inflated<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.left = self
            .left
            .checked_sub(n as u64)
            .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::InvalidData, "the data inflates past its limit"))?;
        Ok(n)
    }
}

/// Where mesh `index` (> 0) starts: read from the offset table at the end of the file.
fn substream_offset(bytes: &[u8], version: u16, index: u32) -> Result<usize, String> {
    let n = bytes.len();
    let count =
        bytes.get(n.wrapping_sub(4)..).filter(|_| n >= 8).map(|b| u32::from_le_bytes(b.try_into().unwrap_or([0; 4])));
    let count = count.ok_or("too short for an offset table")?;
    if index >= count {
        return Err(format!("shape_index {index} is out of range: the file holds {count} meshes"));
    }
    let from_end = |k: usize| n.checked_sub(k).ok_or_else(|| "the offset table is longer than the file".to_string());
    let offset = if version == 4 {
        let at = from_end(8 * (count - index) as usize + 4)?;
        u64::from_le_bytes(bytes[at..at + 8].try_into().expect("invariant: 8 bytes")) as usize
    } else {
        let at = from_end(4 * (count - index + 1) as usize)?;
        u32::from_le_bytes(bytes[at..at + 4].try_into().expect("invariant: 4 bytes")) as usize
    };
    if offset.checked_add(4).is_none_or(|end| end > n) {
        return Err(format!("mesh {index}'s offset {offset} lies past the end of the file"));
    }
    Ok(offset)
}

/// Exactly `len` decompressed bytes (growing as they arrive, so a lying count costs nothing).
fn take(r: &mut impl Read, len: u64, what: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    r.take(len).read_to_end(&mut out).map_err(|e| format!("corrupt compressed data in {what}: {e}"))?;
    if (out.len() as u64) < len {
        return Err(format!("the data ends inside the {what}"));
    }
    Ok(out)
}

/// `count` vectors of `dim` reals, stored as f32 or f64.
fn reals(r: &mut impl Read, count: u64, dim: u64, double: bool, what: &str) -> Result<Vec<f32>, String> {
    let size = if double { 8 } else { 4 };
    let len = count.checked_mul(dim * size).ok_or_else(|| format!("{what}: count too large"))?;
    let raw = take(r, len, what)?;
    let values: Vec<f32> = if double {
        raw.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("invariant: 8 bytes")) as f32).collect()
    } else {
        raw.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("invariant: 4 bytes"))).collect()
    };
    if values.iter().any(|v| !v.is_finite()) {
        return Err(format!("non-finite value among the {what}"));
    }
    Ok(values)
}

fn read_mesh<R: Read>(r: &mut Inflated<R>, version: u16) -> Result<Mesh, String> {
    let word = |b: Vec<u8>| u32::from_le_bytes(b.try_into().expect("invariant: 4 bytes"));
    let flags = word(take(r, 4, "header")?);
    if version == 4 {
        // the mesh's name: read and dropped, as Tessera names shapes by their XML id
        let mut byte = [0u8; 1];
        for read in 0.. {
            r.read_exact(&mut byte).map_err(|_| "the data ends inside the mesh name".to_string())?;
            if byte[0] == 0 {
                break;
            }
            if read >= MAX_NAME_BYTES {
                return Err(format!("the mesh name is longer than {MAX_NAME_BYTES} bytes"));
            }
        }
    }
    let counts = take(r, 16, "counts")?;
    let vertices = u64::from_le_bytes(counts[0..8].try_into().expect("invariant: 8 bytes"));
    let faces = u64::from_le_bytes(counts[8..16].try_into().expect("invariant: 8 bytes"));
    if vertices == 0 || faces == 0 || vertices > u32::MAX as u64 {
        return Err(format!("{vertices} vertices and {faces} faces"));
    }
    let double = flags & DOUBLE_PRECISION != 0;
    let per_vertex = [true, flags & HAS_NORMALS != 0, flags & HAS_COLORS != 0].iter().filter(|&&b| b).count() as u64
        * 3
        + if flags & HAS_TEXCOORDS != 0 { 2 } else { 0 };
    let declared =
        vertices.saturating_mul(per_vertex * if double { 8 } else { 4 }).saturating_add(faces.saturating_mul(12));
    r.expect(declared, &format!("{vertices} vertices and {faces} faces"))?;
    let positions = reals(r, vertices, 3, double, "vertex positions")?;
    let normals = (flags & HAS_NORMALS != 0).then(|| reals(r, vertices, 3, double, "vertex normals")).transpose()?;
    let uvs = (flags & HAS_TEXCOORDS != 0).then(|| reals(r, vertices, 2, double, "texture coordinates")).transpose()?;
    if flags & HAS_COLORS != 0 {
        // Mitsuba 3.9.1 skips them too (`advance_helper`, marked TODO): no vertex_color
        reals(r, vertices, 3, double, "vertex colours")?;
    }
    let index_bytes = faces.checked_mul(12).ok_or("face count too large")?;
    let raw = take(r, index_bytes, "triangle indices")?;
    let triangles: Vec<[u32; 3]> = raw
        .chunks_exact(12)
        .map(|c| {
            std::array::from_fn(|k| u32::from_le_bytes(c[4 * k..4 * k + 4].try_into().expect("invariant: 4 bytes")))
        })
        .collect();
    if let Some((i, t)) = triangles.iter().enumerate().find(|(_, t)| t.iter().any(|&v| v as u64 >= vertices)) {
        return Err(format!(
            "triangle {i} has vertex index {} of only {vertices} vertices",
            t.iter().max().unwrap_or(&0)
        ));
    }
    let v3 = |v: &[f32]| v.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect::<Vec<Vec3>>();
    Ok(Mesh {
        positions: v3(&positions),
        normals: normals.map(|n| v3(&n).into_iter().map(|n| n.normalize_or_zero()).collect()),
        uvs: uvs.map(|uv| uv.chunks_exact(2).map(|c| Vec2::new(c[0], c[1])).collect()),
        triangles,
        attributes: vec![],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/meshes").join(name)
    }

    /// What Mitsuba 3.9.1 loads from the fixtures (`scripts/serialized-fixture.py`).
    #[test]
    fn both_meshes_of_both_versions_load_as_mitsuba_loads_them() {
        for file in ["two-meshes.serialized", "two-meshes-v3.serialized"] {
            let quad = load_serialized(&data(file), 0).unwrap();
            assert_eq!(quad.positions[2], Vec3::new(1.0, 1.0, 0.0));
            assert_eq!(quad.triangles, vec![[0, 1, 2], [0, 2, 3]]);
            assert_eq!(quad.uvs.as_ref().unwrap()[3], Vec2::new(0.25, 0.75));
            assert_eq!(quad.normals.as_ref().unwrap()[0], Vec3::Z);
            let tri = load_serialized(&data(file), 1).unwrap();
            assert_eq!(
                tri.positions,
                vec![Vec3::new(0.0, 0.0, 2.0), Vec3::new(2.0, 0.0, 2.0), Vec3::new(0.0, 3.0, 2.0)]
            );
            assert_eq!(tri.triangles, vec![[0, 2, 1]]);
            assert!(tri.uvs.is_none() && tri.normals.is_none());
            let e = load_serialized(&data(file), 2).unwrap_err().to_string();
            assert!(e.contains("shape_index 2 is out of range"), "{e}");
        }
    }

    #[test]
    fn truncated_lying_and_foreign_files_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let good = std::fs::read(data("two-meshes.serialized")).unwrap();
        let write = |name: &str, bytes: &[u8]| {
            let p = dir.path().join(name);
            std::fs::write(&p, bytes).unwrap();
            p
        };
        assert!(load_serialized(&write("short", &good[..40]), 0).is_err());
        assert!(
            load_serialized(&write("foreign", b"PK\x03\x04 not a mesh"), 0).unwrap_err().to_string().contains("0x041c")
        );
        // a stream claiming 2^32 - 1 vertices and nothing behind them fails without allocating them
        let mut body = Vec::new();
        body.extend_from_slice(&0x1000u32.to_le_bytes());
        body.extend_from_slice(b"x\0");
        body.extend_from_slice(&(u32::MAX as u64).to_le_bytes());
        body.extend_from_slice(&1u64.to_le_bytes());
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        std::io::Write::write_all(&mut z, &body).unwrap();
        let mut file = vec![0x1C, 0x04, 4, 0];
        file.extend(z.finish().unwrap());
        let e = load_serialized(&write("lying", &file), 0).unwrap_err().to_string();
        assert!(
            e.contains("4294967295 vertices and 1 faces need") && e.contains("more than the file can inflate to"),
            "{e}"
        );
        // counts within the bound with too little data behind them
        let mut small = body[..6].to_vec();
        small.extend_from_slice(&1000u64.to_le_bytes());
        small.extend_from_slice(&1u64.to_le_bytes());
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        std::io::Write::write_all(&mut z, &small).unwrap();
        let mut file = vec![0x1C, 0x04, 4, 0];
        file.extend(z.finish().unwrap());
        let e = load_serialized(&write("short", &file), 0).unwrap_err().to_string();
        assert!(e.contains("ends inside the vertex positions"), "{e}");
    }

    /// A stream of zeros inflates about a thousandfold; it is cut off at 64 times the file.
    #[test]
    fn inflation_is_bounded_by_the_file_size() {
        let mut body = Vec::new();
        body.extend_from_slice(&0x1000u32.to_le_bytes());
        body.extend_from_slice(b"x\0");
        let (vertices, faces) = (2_000_000u64, 1u64);
        body.extend_from_slice(&vertices.to_le_bytes());
        body.extend_from_slice(&faces.to_le_bytes());
        body.resize(body.len() + 12 * vertices as usize + 12, 0);
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
        std::io::Write::write_all(&mut z, &body).unwrap();
        let compressed = z.finish().unwrap();
        assert!(compressed.len() * 64 < body.len() && body.len() < (1 << 20) * 64, "{}", compressed.len());
        let e =
            load_serialized_bytes(Path::new("zeros.serialized"), &[&[0x1C, 0x04, 4, 0][..], &compressed].concat(), 0);
        let e = e.unwrap_err().to_string();
        assert!(e.contains("more than the file can inflate to"), "{e}");
    }
}
