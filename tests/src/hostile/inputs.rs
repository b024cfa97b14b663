//! The hostile files the cases send: scenes, meshes and images made small on purpose, each
//! asking for far more than its bytes.

use std::io::Write;

/// A valid scene's head: a 64² film, a sensor, a light.
pub const HEAD: &str = r#"<scene version="3.0.0">
<sensor type="perspective"><transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
<film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="64"/><rfilter type="box"/></film></sensor>
<emitter type="point"><point name="position" x="0" y="0" z="4"/><rgb name="intensity" value="10"/></emitter>
"#;

/// A scene: [`HEAD`], `body`, the end.
pub fn scene(body: &str) -> Vec<u8> {
    format!("{HEAD}{body}</scene>\n").into_bytes()
}

/// A shape naming mesh `file` of `format`.
pub fn mesh_shape(format: &str, file: &str) -> String {
    format!("<shape type=\"{format}\"><string name=\"filename\" value=\"{file}\"/></shape>\n")
}

/// `depth` nested `<bsdf type="twosided">` elements (25 KB at 600).
pub fn nested(depth: usize) -> Vec<u8> {
    let open = "<bsdf type=\"twosided\">\n".repeat(depth);
    let close = "</bsdf>".repeat(depth);
    scene(&format!("{open}{close}\n"))
}

/// A 1 MiB string in a BSDF referenced by `shapes` spheres.
pub fn ref_bomb(shapes: usize) -> Vec<u8> {
    let big = "x".repeat(1 << 20);
    let mut body = format!("<bsdf type=\"diffuse\" id=\"b\"><string name=\"note\" value=\"{big}\"/></bsdf>\n");
    body += &"<shape type=\"sphere\"><ref id=\"b\"/></shape>\n".repeat(shapes);
    scene(&body)
}

/// `n` elements, the last of them malformed: every element's location is computed.
pub fn many_elements(n: usize) -> Vec<u8> {
    let mut body = "<shape type=\"sphere\"><float name=\"radius\" value=\"0.001\"/></shape>\n".repeat(n - 1);
    body += "<shape type=\"sphere\"><float name=\"radius\" value=\"oops\"/></shape>\n";
    scene(&body)
}

/// `n` `<path>` elements.
pub fn many_paths(n: usize) -> Vec<u8> {
    scene(&"<path value=\".\"/>\n".repeat(n))
}

/// A binary PLY grid of `side`² vertices and 2(`side`−1)² triangles.
pub fn ply_grid(side: u32) -> Vec<u8> {
    let faces = 2 * (side - 1) * (side - 1);
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {faces}\nproperty list uchar int vertex_indices\nend_header\n",
        side * side
    )
    .into_bytes();
    for y in 0..side {
        for x in 0..side {
            for v in [x as f32 / side as f32 - 0.5, y as f32 / side as f32 - 0.5, 0.0] {
                out.extend(v.to_le_bytes());
            }
        }
    }
    for y in 0..side - 1 {
        for x in 0..side - 1 {
            let i = y * side + x;
            for tri in [[i, i + 1, i + side], [i + 1, i + side + 1, i + side]] {
                out.push(3);
                tri.iter().for_each(|v| out.extend(v.to_le_bytes()));
            }
        }
    }
    out
}

/// A PLY with one triangle and `records` one-byte records of an element nobody reads.
pub fn ply_one_byte_records(records: usize) -> Vec<u8> {
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nelement junk {records}\nproperty uchar j\nend_header\n"
    )
    .into_bytes();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        out.extend(v.to_le_bytes());
    }
    out.push(3);
    [0i32, 1, 2].iter().for_each(|v| out.extend(v.to_le_bytes()));
    out.resize(out.len() + records, 7);
    out
}

/// A Mitsuba `.serialized` mesh of zeros claiming `triangles` triangles: it compresses about
/// a thousandfold.
pub fn serialized_bomb(triangles: u64) -> Vec<u8> {
    let vertices = 3u64;
    let mut body = Vec::new();
    body.extend(0x1000u32.to_le_bytes());
    body.extend(b"bomb\0");
    body.extend(vertices.to_le_bytes());
    body.extend(triangles.to_le_bytes());
    body.resize(body.len() + 36 + 12 * triangles as usize, 0);
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    z.write_all(&body).expect("in memory");
    let mut out = vec![0x1C, 0x04, 4, 0];
    out.extend(z.finish().expect("in memory"));
    out
}

/// A PNG whose header claims `side`² RGB pixels, with almost no data behind it.
pub fn png_claiming(side: u32) -> Vec<u8> {
    fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
        out.extend((data.len() as u32).to_be_bytes());
        let mut crc = flate2::Crc::new();
        crc.update(kind);
        crc.update(data);
        out.extend(kind);
        out.extend(data);
        out.extend(crc.sum().to_be_bytes());
    }
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend(side.to_be_bytes());
    ihdr.extend(side.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &ihdr);
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    z.write_all(&[0u8; 4096]).expect("in memory");
    chunk(&mut out, b"IDAT", &z.finish().expect("in memory"));
    chunk(&mut out, b"IEND", &[]);
    out
}

/// An OpenEXR file of one flat `side`² RGB float image, ZIP-compressed to a few hundred KB.
pub fn flat_exr(side: usize) -> Vec<u8> {
    use exr::prelude::*;
    let channels = SpecificChannels::rgb(|_: Vec2<usize>| (0.5f32, 0.5f32, 0.5f32));
    let mut layer = Layer::new((side, side), LayerAttributes::default(), Encoding::SMALL_LOSSLESS, channels);
    layer.encoding.compression = Compression::ZIP16;
    let mut out = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer).write().to_buffered(&mut out).expect("in memory");
    out.into_inner()
}

/// A diffuse BSDF textured with `file`, on a rectangle.
pub fn textured(file: &str) -> String {
    format!(
        "<shape type=\"rectangle\"><bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\"><string name=\"filename\" value=\"{file}\"/></texture></bsdf></shape>\n"
    )
}

/// The boundary of [`multipart`].
pub const BOUNDARY: &str = "hostile-suite-boundary";

/// A multipart submission of an empty scene and `parts` one-byte files.
pub fn multipart(parts: usize) -> Vec<u8> {
    let part = |disposition: &str, data: &str| {
        format!("--{BOUNDARY}\r\nContent-Disposition: form-data; {disposition}\r\n\r\n{data}\r\n")
    };
    let mut out = part("name=\"settings\"", "{\"spp\": 1}");
    out += &part("name=\"scene\"; filename=\"scene.xml\"", &String::from_utf8_lossy(&scene("")));
    for i in 0..parts {
        out += &part(&format!("name=\"asset\"; filename=\"f/{i}\""), "x");
    }
    out += &format!("--{BOUNDARY}--\r\n");
    out.into_bytes()
}
