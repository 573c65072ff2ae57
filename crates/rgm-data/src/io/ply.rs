//! Stanford PLY: reads x, y, z of the `vertex` element from ASCII, binary little-endian or
//! binary big-endian files, whatever their scalar type; other properties (normals, colours,
//! lists) and other elements (faces, ...) are skipped. Writes binary little-endian float32.
//!
//! The body is read as a stream of values, one property after the other, element after element
//! (the PLY definition; ASCII files are whitespace-separated tokens, binary files packed
//! values). Elements after `vertex` are not read.
//!
//! The file is long because its unit tests sit beside the code they check (as everywhere in
//! rgm); the code itself is one job, kept in one place.

use std::io::Write;
use std::path::Path;

use rgm_geom::{Point3, PointCloud, Vector3};

use super::{format_error, line_error, PointFormat, Warning};
use crate::{DataError, Result};

const FORMAT: &str = "PLY";

/// Stanford PLY.
pub struct Ply;

impl PointFormat for Ply {
    fn name(&self) -> &'static str {
        FORMAT
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["ply"]
    }
    fn summary(&self) -> &'static str {
        "ascii or binary; written binary float32 (float64 where float32 would lose precision)"
    }
    fn parse(
        &self,
        bytes: &[u8],
        path: &Path,
        warnings: &mut Vec<Warning>,
    ) -> Result<Vec<Point3<f64>>> {
        parse(bytes, path, warnings)
    }
    fn write(&self, mut out: &mut dyn Write, cloud: &PointCloud) -> std::io::Result<()> {
        write(&mut out, cloud)
    }
}

/// How the body is encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Encoding {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

/// A PLY scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
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
    fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    /// The value packed in `b` (exactly `self.size()` bytes).
    fn decode(self, b: &[u8], big_endian: bool) -> f64 {
        macro_rules! num {
            ($t:ty) => {{
                let a = b.try_into().expect("slice of the scalar's size");
                (if big_endian {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }) as f64
            }};
        }
        match self {
            Self::I8 => b[0] as i8 as f64,
            Self::U8 => b[0] as f64,
            Self::I16 => num!(i16),
            Self::U16 => num!(u16),
            Self::I32 => num!(i32),
            Self::U32 => num!(u32),
            Self::F32 => num!(f32),
            Self::F64 => num!(f64),
        }
    }
}

/// One property of an element.
#[derive(Clone, Debug, PartialEq)]
enum Property {
    Scalar {
        name: String,
        ty: Scalar,
    },
    List {
        name: String,
        count: Scalar,
        item: Scalar,
    },
}

impl Property {
    fn name(&self) -> &str {
        match self {
            Self::Scalar { name, .. } | Self::List { name, .. } => name,
        }
    }
}

/// One element declaration: `element NAME COUNT` and its properties.
#[derive(Clone, Debug, PartialEq)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

/// The parsed header.
#[derive(Debug)]
struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    /// Byte offset of the body.
    body_start: usize,
    /// Number of header lines (the body's first line is `lines + 1`).
    lines: usize,
}

/// The header of a PLY file. A line that starts with no keyword of the format (six of the
/// Stanford dragon's scans carry `bye` lines) is skipped with a warning in `warnings`; a
/// keyword line that is malformed is an error.
fn parse_header(bytes: &[u8], path: &Path, warnings: &mut Vec<Warning>) -> Result<Header> {
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut offset = 0;
    let mut line_no = 0;
    while offset < bytes.len() {
        let end = bytes[offset..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |e| offset + e);
        let raw = &bytes[offset..end];
        offset = (end + 1).min(bytes.len());
        line_no += 1;
        let line = std::str::from_utf8(raw)
            .map_err(|_| format_error(path, FORMAT, format!("header line {line_no} is not text")))?
            .trim();
        let tokens: Vec<&str> = line.split_whitespace().collect();
        let bad = |why: &str| line_error(path, line_no, line, why);
        if line_no == 1 {
            if line != "ply" {
                return Err(bad("a PLY file starts with the line `ply`"));
            }
            continue;
        }
        match tokens.as_slice() {
            [] | ["comment" | "obj_info", ..] => {}
            ["format", kind, _version] => {
                encoding = Some(match *kind {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::BinaryLittleEndian,
                    "binary_big_endian" => Encoding::BinaryBigEndian,
                    _ => return Err(bad(
                        "unknown format (expected ascii, binary_little_endian, binary_big_endian)",
                    )),
                });
            }
            ["element", name, count] => {
                let count = count.parse().map_err(|_| {
                    bad(if count.bytes().all(|b| b.is_ascii_digit()) {
                        "the element count is larger than any file can hold"
                    } else {
                        "the element count is not a whole number"
                    })
                })?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    properties: Vec::new(),
                });
            }
            ["property", rest @ ..] => {
                let property = match rest {
                    ["list", count, item, name] => {
                        let (Some(count), Some(item)) =
                            (Scalar::from_name(count), Scalar::from_name(item))
                        else {
                            return Err(bad("unknown list property type"));
                        };
                        Property::List {
                            name: name.to_string(),
                            count,
                            item,
                        }
                    }
                    [ty, name] => {
                        let ty =
                            Scalar::from_name(ty).ok_or_else(|| bad("unknown property type"))?;
                        Property::Scalar {
                            name: name.to_string(),
                            ty,
                        }
                    }
                    _ => return Err(bad("malformed property line")),
                };
                let element = elements
                    .last_mut()
                    .ok_or_else(|| bad("property before any element"))?;
                element.properties.push(property);
            }
            ["end_header"] => {
                let encoding = encoding
                    .ok_or_else(|| format_error(path, FORMAT, "the header has no `format` line"))?;
                return Ok(Header {
                    encoding,
                    elements,
                    body_start: offset,
                    lines: line_no,
                });
            }
            [keyword, ..]
                if !matches!(
                    *keyword,
                    "format" | "element" | "property" | "end_header" | "ply"
                ) =>
            {
                warnings.push(Warning {
                    path: path.to_path_buf(),
                    line: line_no,
                    text: line.to_string(),
                    why: format!("`{keyword}` is no PLY header keyword; line skipped"),
                });
            }
            _ => return Err(bad("malformed header line")),
        }
    }
    Err(format_error(
        path,
        FORMAT,
        "the header has no `end_header` line",
    ))
}

impl Element {
    /// The fewest bytes one row takes in `encoding`: every scalar and list length, lists empty.
    /// An ASCII value is at least one character and one separator.
    fn min_row_bytes(&self, encoding: Encoding) -> usize {
        self.properties
            .iter()
            .map(|p| match (encoding, p) {
                (Encoding::Ascii, _) => 2,
                (_, Property::Scalar { ty, .. }) => ty.size(),
                (_, Property::List { count, .. }) => count.size(),
            })
            .sum()
    }
}

/// Checks, before any row is read, that the rows `elements` declare fit in `body_len` bytes,
/// so a huge count in a small file is an error and not a long loop or a huge allocation.
fn check_counts(
    elements: &[Element],
    encoding: Encoding,
    body_len: usize,
    path: &Path,
) -> Result<()> {
    let mut needed = 0usize;
    for element in elements {
        let bytes = element
            .count
            .saturating_mul(element.min_row_bytes(encoding));
        needed = needed.saturating_add(bytes);
        // The last ASCII value may end the file without a separator.
        let room = body_len + usize::from(encoding == Encoding::Ascii);
        if needed > room {
            let why = format!(
                "element `{}` declares {} rows of at least {} bytes, more than the {body_len} \
                 bytes of data the file holds",
                element.name,
                element.count,
                element.min_row_bytes(encoding)
            );
            return Err(format_error(path, FORMAT, why));
        }
    }
    Ok(())
}

/// The body as a stream of rows of values.
trait Values {
    /// The next value of the current row, read as `ty`; `Ok(None)` at the end of the data.
    fn next(&mut self, ty: Scalar) -> Result<Option<f64>>;
    /// Ends the current row of `element`: an ASCII row must hold exactly its values.
    fn end_row(&mut self, element: &Element) -> Result<()>;
}

/// An ASCII body: one row per line (blank lines skipped), whitespace-separated values.
struct AsciiValues<'a> {
    path: &'a Path,
    lines: std::str::Lines<'a>,
    /// Number (from 1, counting the header) and text of the current line.
    line_no: usize,
    line: &'a str,
    tokens: std::str::SplitWhitespace<'a>,
    /// Whether a row has begun on `line`.
    in_row: bool,
    /// Values read from the current row.
    read: usize,
}

impl<'a> AsciiValues<'a> {
    fn new(path: &'a Path, text: &'a str, header_lines: usize) -> Self {
        Self {
            path,
            lines: text.lines(),
            line_no: header_lines,
            line: "",
            tokens: "".split_whitespace(),
            in_row: false,
            read: 0,
        }
    }
}

impl Values for AsciiValues<'_> {
    fn next(&mut self, _ty: Scalar) -> Result<Option<f64>> {
        while !self.in_row {
            let Some(line) = self.lines.next() else {
                return Ok(None);
            };
            self.line_no += 1;
            self.line = line;
            self.tokens = line.split_whitespace();
            self.in_row = !line.trim().is_empty();
            self.read = 0;
        }
        let Some(token) = self.tokens.next() else {
            let why = format!(
                "the row ends after {} values; the header declares more",
                self.read
            );
            return Err(line_error(self.path, self.line_no, self.line, why));
        };
        let value = token.parse().map_err(|_| {
            line_error(
                self.path,
                self.line_no,
                self.line,
                format!("`{token}` is not a number"),
            )
        })?;
        self.read += 1;
        Ok(Some(value))
    }

    fn end_row(&mut self, element: &Element) -> Result<()> {
        if self.in_row && self.tokens.next().is_some() {
            let why = format!(
                "the row holds more than the {} values of a `{}` row",
                self.read, element.name
            );
            return Err(line_error(self.path, self.line_no, self.line, why));
        }
        self.in_row = false;
        Ok(())
    }
}

/// A binary body: packed values.
struct BinaryValues<'a> {
    bytes: &'a [u8],
    big_endian: bool,
}

impl Values for BinaryValues<'_> {
    fn next(&mut self, ty: Scalar) -> Result<Option<f64>> {
        if self.bytes.len() < ty.size() {
            return Ok(None);
        }
        let (value, rest) = self.bytes.split_at(ty.size());
        self.bytes = rest;
        Ok(Some(ty.decode(value, self.big_endian)))
    }

    fn end_row(&mut self, _element: &Element) -> Result<()> {
        Ok(())
    }
}

/// The x, y, z of every vertex of a PLY file; what is odd but readable goes to `warnings`.
pub fn parse(bytes: &[u8], path: &Path, warnings: &mut Vec<Warning>) -> Result<Vec<Point3<f64>>> {
    let header = parse_header(bytes, path, warnings)?;
    let vertex_index = header
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| format_error(path, FORMAT, "the header declares no `vertex` element"))?;
    let vertex = &header.elements[vertex_index];
    // Position of x, y, z among the vertex properties.
    let mut axes = [0usize; 3];
    for (axis, name) in axes.iter_mut().zip(["x", "y", "z"]) {
        *axis = match vertex.properties.iter().position(|p| p.name() == name) {
            Some(i) if matches!(vertex.properties[i], Property::Scalar { .. }) => i,
            Some(_) => {
                return Err(format_error(
                    path,
                    FORMAT,
                    format!("vertex property `{name}` is a list"),
                ))
            }
            None => {
                return Err(format_error(
                    path,
                    FORMAT,
                    format!("the vertex element has no `{name}` property"),
                ))
            }
        };
    }
    let body = &bytes[header.body_start..];
    let elements = &header.elements[..=vertex_index];
    check_counts(elements, header.encoding, body.len(), path)?;
    match header.encoding {
        Encoding::Ascii => {
            let text = std::str::from_utf8(body)
                .map_err(|_| format_error(path, FORMAT, "the ASCII body is not text"))?;
            let values = AsciiValues::new(path, text, header.lines);
            read_vertices(elements, &axes, values, path)
        }
        Encoding::BinaryLittleEndian | Encoding::BinaryBigEndian => {
            let big_endian = header.encoding == Encoding::BinaryBigEndian;
            let values = BinaryValues {
                bytes: body,
                big_endian,
            };
            read_vertices(elements, &axes, values, path)
        }
    }
}

/// Skips every element but the last of `elements`, then reads the last (the vertices), keeping
/// the properties at `axes`. [`check_counts`] has bounded the counts by the file's size.
fn read_vertices(
    elements: &[Element],
    axes: &[usize; 3],
    mut values: impl Values,
    path: &Path,
) -> Result<Vec<Point3<f64>>> {
    let (vertex, before) = elements
        .split_last()
        .expect("the vertex element is included");
    let mut row = Vec::with_capacity(vertex.properties.len());
    // An element without properties takes no bytes: nothing to skip.
    for element in before.iter().filter(|e| !e.properties.is_empty()) {
        for r in 0..element.count {
            read_row(element, r, &mut values, &mut row, path)?;
        }
    }
    let mut points = super::room_for_points(path, vertex.count as u64, 0)?;
    for r in 0..vertex.count {
        read_row(vertex, r, &mut values, &mut row, path)?;
        points.push(Point3::new(row[axes[0]], row[axes[1]], row[axes[2]]));
    }
    Ok(points)
}

/// Reads row `r` of `element` into `row` (one value per property; lists give their length).
fn read_row(
    element: &Element,
    r: usize,
    values: &mut impl Values,
    row: &mut Vec<f64>,
    path: &Path,
) -> Result<()> {
    let truncated = || {
        let why = format!(
            "the data ends in element `{}` at row {r} of {}",
            element.name, element.count
        );
        format_error(path, FORMAT, why)
    };
    row.clear();
    for property in &element.properties {
        match *property {
            Property::Scalar { ty, .. } => row.push(values.next(ty)?.ok_or_else(truncated)?),
            Property::List {
                count,
                item,
                ref name,
            } => {
                let n = values.next(count)?.ok_or_else(truncated)?;
                if n < 0.0 || n.fract() != 0.0 {
                    let why = format!(
                        "list `{name}` of element `{}` row {r} has length {n}",
                        element.name
                    );
                    return Err(DataError::Format {
                        path: path.to_path_buf(),
                        format: FORMAT,
                        why,
                    });
                }
                for _ in 0..n as u64 {
                    values.next(item)?.ok_or_else(truncated)?;
                }
                row.push(n);
            }
        }
    }
    values.end_row(element)
}

/// The largest loss, relative to the cloud's size, that float32 output may cause: about 16
/// times float32's own rounding of a cloud about the origin, so that clouds read from float32
/// files, or in a unit frame, stay float32, and clouds far from the origin (map coordinates at
/// 1e6, where float32's steps are 1/16) are written in double precision.
const FLOAT32_LOSS: f64 = 1e-6;

/// Whether float32 holds `cloud` to within [`FLOAT32_LOSS`] of its bounding box's diagonal.
pub(crate) fn float32_suffices(cloud: &PointCloud) -> bool {
    let (mut low, mut high) = (
        Vector3::repeat(f64::INFINITY),
        Vector3::repeat(f64::NEG_INFINITY),
    );
    let mut loss: f64 = 0.0;
    for p in &cloud.points {
        low = low.inf(&p.coords);
        high = high.sup(&p.coords);
        for v in [p.x, p.y, p.z] {
            loss = loss.max((v - (v as f32) as f64).abs());
        }
    }
    let size = rgm_geom::length(&(high - low));
    loss <= FLOAT32_LOSS * size || cloud.is_empty()
}

/// Writes a binary little-endian PLY with float32 x, y, z, or double where float32 would move
/// the points by more than `FLOAT32_LOSS` (a millionth) of the cloud's size.
pub fn write(out: &mut impl Write, cloud: &PointCloud) -> std::io::Result<()> {
    write_labelled(out, cloud, None)
}

/// [`fn@write`], each point followed by a `uint` property `name` from `labels` (`rgm merge`'s
/// scan index) when given. // labels: (N,)
pub fn write_labelled(
    out: &mut (impl Write + ?Sized),
    cloud: &PointCloud,
    labels: Option<(&str, &[u32])>,
) -> std::io::Result<()> {
    if let Some((_, labels)) = labels {
        assert_eq!(labels.len(), cloud.len(), "one label per point");
    }
    let float = if float32_suffices(cloud) {
        "float"
    } else {
        "double"
    };
    let label = labels.map_or(String::new(), |(name, _)| format!("property uint {name}\n"));
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\n\
         property {float} x\nproperty {float} y\nproperty {float} z\n{label}end_header\n",
        cloud.len()
    )?;
    for (i, p) in cloud.points.iter().enumerate() {
        for v in [p.x, p.y, p.z] {
            if float == "float" {
                out.write_all(&(v as f32).to_le_bytes())?;
            } else {
                out.write_all(&v.to_le_bytes())?;
            }
        }
        if let Some((_, labels)) = labels {
            out.write_all(&labels[i].to_le_bytes())?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
