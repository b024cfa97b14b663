//! The PLY file format itself: the header, and the body read into one column per property
//! (ASCII, binary little- and big-endian). `ply.rs` turns the columns into a mesh.
//!
//! Memory stays proportional to the file: a value takes 8 bytes here however few it takes in
//! the file (at least one), and an element's declared record count is checked against the
//! bytes left before anything is reserved for it. (A general-purpose reader that builds a map
//! per record took 1.45 GB for a 4 MB file of one-byte records.)

use std::str::FromStr;

/// A scalar type of the format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// The value of `bytes` (exactly [`Scalar::size`] of them).
    fn decode(self, b: &[u8], little: bool) -> f64 {
        macro_rules! num {
            ($t:ty) => {{
                let a = b.try_into().expect("invariant: the caller passes the type's size");
                (if little { <$t>::from_le_bytes(a) } else { <$t>::from_be_bytes(a) }) as f64
            }};
        }
        match self {
            Scalar::I8 => num!(i8),
            Scalar::U8 => num!(u8),
            Scalar::I16 => num!(i16),
            Scalar::U16 => num!(u16),
            Scalar::I32 => num!(i32),
            Scalar::U32 => num!(u32),
            Scalar::F32 => num!(f32),
            Scalar::F64 => num!(f64),
        }
    }

    /// The value of an ASCII token, which must fit the type.
    fn token(self, t: &str) -> Option<f64> {
        fn int<T: FromStr + Into<f64>>(t: &str) -> Option<f64> {
            t.parse::<T>().ok().map(Into::into)
        }
        match self {
            Scalar::I8 => int::<i8>(t),
            Scalar::U8 => int::<u8>(t),
            Scalar::I16 => int::<i16>(t),
            Scalar::U16 => int::<u16>(t),
            Scalar::I32 => int::<i32>(t),
            Scalar::U32 => int::<u32>(t),
            // the binary encoding can hold a NaN; the text one is refused it at the token
            Scalar::F32 | Scalar::F64 => t.parse().ok().filter(|x: &f64| x.is_finite()),
        }
    }

    fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        }
    }
}

/// What a property holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
    Scalar(Scalar),
    /// A count of type `count`, then that many items.
    List {
        count: Scalar,
        item: Scalar,
    },
}

/// A property of an element, in header order.
#[derive(Clone, Debug)]
pub(super) struct PropertyDef {
    pub name: String,
    pub kind: Kind,
}

/// An element of the header.
#[derive(Clone, Debug)]
pub(super) struct ElementDef {
    pub name: String,
    pub count: u64,
    pub properties: Vec<PropertyDef>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Encoding {
    Ascii,
    Binary { little: bool },
}

/// A property's values for every record of its element.
pub(super) enum Column {
    Scalar(Vec<f64>),
    /// Record k's items are `items[offsets[k]..offsets[k + 1]]`.
    List {
        offsets: Vec<usize>,
        items: Vec<f64>,
    },
}

/// An element's records, a column per property.
pub(super) struct ElementData {
    pub def: ElementDef,
    pub columns: Vec<Column>,
    /// ASCII: the line of each record (for messages); empty for binary files.
    pub lines: Vec<u32>,
}

impl ElementData {
    /// The column of property `name`.
    pub fn column(&self, name: &str) -> Option<&Column> {
        self.def.properties.iter().position(|p| p.name == name).map(|i| &self.columns[i])
    }

    /// The line of record `k`, 0 when the file is binary.
    pub fn line(&self, k: usize) -> u32 {
        self.lines.get(k).copied().unwrap_or(0)
    }
}

/// A format error, at a line (0: the whole file).
#[derive(Debug)]
pub(super) struct FormatError {
    pub line: u32,
    pub message: String,
}

fn error(line: u32, message: impl Into<String>) -> FormatError {
    FormatError { line, message: message.into() }
}

/// Reads every element of the file `bytes`; elements not named in `keep` are read past.
pub(super) fn read(bytes: &[u8], keep: &[&str]) -> Result<Vec<ElementData>, FormatError> {
    let (elements, encoding, mut pos, mut line) = header(bytes)?;
    let mut out = Vec::new();
    for def in elements {
        let store = keep.contains(&def.name.as_str());
        let data = match encoding {
            Encoding::Ascii => ascii_element(bytes, &mut pos, &mut line, def, store)?,
            Encoding::Binary { little } => binary_element(bytes, &mut pos, little, def, store)?,
        };
        if store {
            out.push(data);
        }
    }
    Ok(out)
}

/// The header's elements, encoding, and where the body starts (byte and line).
fn header(bytes: &[u8]) -> Result<(Vec<ElementDef>, Encoding, usize, u32), FormatError> {
    let mut lines = bytes.split_inclusive(|&b| b == b'\n');
    let mut pos = 0;
    let mut encoding = None;
    let mut elements: Vec<ElementDef> = Vec::new();
    for n in 1u32.. {
        let raw = lines.next().ok_or_else(|| error(0, "the header has no end_header line"))?;
        pos += raw.len();
        let text = std::str::from_utf8(raw).map_err(|_| error(n, "the header is not text"))?;
        let words: Vec<&str> = text.split_ascii_whitespace().collect();
        match words.as_slice() {
            ["ply"] if n == 1 => {}
            _ if n == 1 => return Err(error(1, "not a PLY file (it must start with \"ply\")")),
            ["format", f, _version] => encoding = Some(parse_encoding(f, n)?),
            ["comment", ..] | ["obj_info", ..] | [] => {}
            ["element", name, count] => {
                let count = count.parse().map_err(|_| error(n, format!("bad element count \"{count}\"")))?;
                elements.push(ElementDef { name: name.to_string(), count, properties: vec![] });
            }
            ["property", rest @ ..] => {
                let element = elements.last_mut().ok_or_else(|| error(n, "a property before any element"))?;
                element.properties.push(property(rest, n)?);
            }
            ["end_header"] => {
                let encoding = encoding.ok_or_else(|| error(n, "the header has no format line"))?;
                return Ok((elements, encoding, pos, n + 1));
            }
            _ => return Err(error(n, format!("unexpected header line \"{}\"", text.trim()))),
        }
    }
    unreachable!("invariant: the loop returns")
}

fn parse_encoding(f: &str, line: u32) -> Result<Encoding, FormatError> {
    match f {
        "ascii" => Ok(Encoding::Ascii),
        "binary_little_endian" => Ok(Encoding::Binary { little: true }),
        "binary_big_endian" => Ok(Encoding::Binary { little: false }),
        other => Err(error(line, format!("unknown format \"{other}\""))),
    }
}

fn property(words: &[&str], line: u32) -> Result<PropertyDef, FormatError> {
    let scalar = |t: &str| Scalar::parse(t).ok_or_else(|| error(line, format!("unknown property type \"{t}\"")));
    match words {
        ["list", count, item, name] => {
            let count = scalar(count)?;
            if !count.is_integer() {
                return Err(error(line, format!("list \"{name}\" has a non-integer count type")));
            }
            Ok(PropertyDef { name: name.to_string(), kind: Kind::List { count, item: scalar(item)? } })
        }
        [ty, name] => Ok(PropertyDef { name: name.to_string(), kind: Kind::Scalar(scalar(ty)?) }),
        _ => Err(error(line, "a property line is \"property TYPE NAME\" or \"property list COUNT ITEM NAME\"")),
    }
}

/// Empty columns for `def`, with room for at most `records`.
fn columns(def: &ElementDef, records: usize) -> Vec<Column> {
    def.properties
        .iter()
        .map(|p| match p.kind {
            Kind::Scalar(_) => Column::Scalar(Vec::with_capacity(records)),
            Kind::List { .. } => Column::List { offsets: vec![0], items: Vec::new() },
        })
        .collect()
}

/// Fails when `count` records of at least `least` bytes each cannot fit in `left` bytes.
fn check_count(def: &ElementDef, least: usize, left: usize, line: u32) -> Result<usize, FormatError> {
    let need = def.count.saturating_mul(least.max(1) as u64);
    if need > left as u64 {
        return Err(error(
            line,
            format!(
                "element \"{}\" declares {} records, more than the {left} bytes left can hold",
                def.name, def.count
            ),
        ));
    }
    Ok(def.count as usize)
}

fn binary_element(
    bytes: &[u8],
    pos: &mut usize,
    little: bool,
    def: ElementDef,
    store: bool,
) -> Result<ElementData, FormatError> {
    let least = def
        .properties
        .iter()
        .map(|p| match p.kind {
            Kind::Scalar(s) => s.size(),
            Kind::List { count, .. } => count.size(),
        })
        .sum();
    let count = check_count(&def, least, bytes.len() - *pos, 0)?;
    let mut cols = columns(&def, if store { count } else { 0 });
    let short = || error(0, format!("the file ends inside element \"{}\"", def.name));
    let mut take = |size: usize| -> Result<&[u8], FormatError> {
        let b = bytes.get(*pos..*pos + size).ok_or_else(short)?;
        *pos += size;
        Ok(b)
    };
    for _ in 0..count {
        for (p, col) in def.properties.iter().zip(&mut cols) {
            match (p.kind, col) {
                (Kind::Scalar(s), Column::Scalar(v)) => {
                    let x = s.decode(take(s.size())?, little);
                    if store {
                        v.push(x);
                    }
                }
                (Kind::List { count, item }, Column::List { offsets, items }) => {
                    let n = count.decode(take(count.size())?, little);
                    let n = usize::try_from(n as i64)
                        .map_err(|_| error(0, format!("list \"{}\" has a negative count", p.name)))?;
                    let raw = take(n.checked_mul(item.size()).ok_or_else(short)?)?;
                    if store {
                        items.extend(raw.chunks_exact(item.size()).map(|b| item.decode(b, little)));
                        offsets.push(items.len());
                    }
                }
                _ => unreachable!("invariant: columns follow the properties"),
            }
        }
    }
    Ok(ElementData { def, columns: cols, lines: vec![] })
}

fn ascii_element(
    bytes: &[u8],
    pos: &mut usize,
    line: &mut u32,
    def: ElementDef,
    store: bool,
) -> Result<ElementData, FormatError> {
    let count = check_count(&def, def.properties.len(), bytes.len() - *pos, *line)?;
    let mut cols = columns(&def, if store { count } else { 0 });
    let mut lines = Vec::with_capacity(if store { count } else { 0 });
    for _ in 0..count {
        let text = loop {
            let rest = bytes.get(*pos..).filter(|r| !r.is_empty());
            let rest = rest.ok_or_else(|| error(*line, format!("the file ends inside element \"{}\"", def.name)))?;
            let end = rest.iter().position(|&b| b == b'\n').map_or(rest.len(), |i| i + 1);
            *pos += end;
            *line += 1;
            let text = std::str::from_utf8(&rest[..end]).map_err(|_| error(*line - 1, "the line is not text"))?;
            if !text.trim().is_empty() {
                break text;
            }
        };
        let at = *line - 1;
        ascii_record(text, &def, &mut cols, store, at)?;
        if store {
            lines.push(at);
        }
    }
    Ok(ElementData { def, columns: cols, lines })
}

fn ascii_record(text: &str, def: &ElementDef, cols: &mut [Column], store: bool, line: u32) -> Result<(), FormatError> {
    let mut tokens = text.split_ascii_whitespace();
    let mut next = |p: &PropertyDef, s: Scalar| -> Result<f64, FormatError> {
        let t = tokens.next().ok_or_else(|| error(line, format!("the record ends before \"{}\"", p.name)))?;
        s.token(t).ok_or_else(|| error(line, format!("\"{t}\" is not a valid {} (property \"{}\")", s.name(), p.name)))
    };
    for (p, col) in def.properties.iter().zip(cols.iter_mut()) {
        match (p.kind, col) {
            (Kind::Scalar(s), Column::Scalar(v)) => {
                let x = next(p, s)?;
                if store {
                    v.push(x);
                }
            }
            (Kind::List { count, item }, Column::List { offsets, items }) => {
                let n = next(p, count)?;
                if n < 0.0 {
                    return Err(error(line, format!("list \"{}\" has a negative count", p.name)));
                }
                for _ in 0..n as u64 {
                    let x = next(p, item)?;
                    if store {
                        items.push(x);
                    }
                }
                if store {
                    offsets.push(items.len());
                }
            }
            _ => unreachable!("invariant: columns follow the properties"),
        }
    }
    match tokens.next() {
        Some(t) => Err(error(line, format!("unexpected value \"{t}\" after the element \"{}\"", def.name))),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "ply\nformat ascii 1.0\ncomment x\nelement vertex 2\nproperty float x\nproperty uchar r\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";

    #[test]
    fn ascii_columns_and_lines() {
        let text = format!("{HEAD}1.5 3\n\n-2 255\n3 0 1 1\n");
        let e = read(text.as_bytes(), &["vertex", "face"]).unwrap();
        assert!(matches!(e[0].column("x"), Some(Column::Scalar(v)) if v == &[1.5, -2.0]));
        assert_eq!(e[0].lines, [10, 12]);
        match e[1].column("vertex_indices") {
            Some(Column::List { offsets, items }) => {
                assert_eq!((offsets.as_slice(), items.as_slice()), (&[0, 3][..], &[0.0, 1.0, 1.0][..]))
            }
            _ => panic!("no list"),
        }
        let bad = format!("{HEAD}1.5 300\n-2 1\n3 0 1 1\n");
        let e = read(bad.as_bytes(), &["vertex"]).err().unwrap();
        assert_eq!(e.line, 10, "{}", e.message);
    }

    #[test]
    fn binary_big_and_little_endian() {
        for little in [true, false] {
            let mut b = format!(
                "ply\nformat {} 1.0\nelement vertex 1\nproperty float x\nproperty list uchar uint i\nend_header\n",
                if little { "binary_little_endian" } else { "binary_big_endian" }
            )
            .into_bytes();
            let f = 2.5f32;
            b.extend(if little { f.to_le_bytes() } else { f.to_be_bytes() });
            b.push(2);
            for i in [7u32, 9] {
                b.extend(if little { i.to_le_bytes() } else { i.to_be_bytes() });
            }
            let e = read(&b, &["vertex"]).unwrap();
            assert!(matches!(e[0].column("x"), Some(Column::Scalar(v)) if v == &[2.5]));
            assert!(matches!(e[0].column("i"), Some(Column::List { items, .. }) if items == &[7.0, 9.0]));
            let truncated = &b[..b.len() - 1];
            assert!(read(truncated, &["vertex"]).err().unwrap().message.contains("ends inside"));
        }
    }

    #[test]
    fn declared_counts_are_bounded_by_the_bytes_left() {
        let b =
            b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nend_header\n\0\0\0\0";
        let e = read(b, &["vertex"]).err().unwrap();
        assert!(e.message.contains("declares 4000000000 records"), "{}", e.message);
        let a = b"ply\nformat ascii 1.0\nelement vertex 99999999999\nproperty float x\nend_header\n1\n";
        assert!(read(a, &["vertex"]).err().unwrap().message.contains("declares"));
    }
}
