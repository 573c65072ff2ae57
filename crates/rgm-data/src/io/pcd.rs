//! PCD (the Point Cloud Library's format, versions 0.6 and 0.7): reads x, y, z from `ascii`,
//! `binary` and `binary_compressed` (LZF, one field after the other) data, whatever the other
//! fields and the coordinates' numeric type; writes `binary` float32 x, y, z (float64 where
//! float32 would lose precision, as the PLY writer decides).
//!
//! Points with a NaN coordinate are skipped, with one warning: PCL marks the invalid pixels of
//! an organised cloud (a depth camera's, `is_dense` false) so, and Open3D skips them too when
//! asked. An infinite coordinate is an error, as in every format.
//!
//! The header's counts are checked against the bytes present before anything is allocated.

use std::io::Write;
use std::path::Path;

use rgm_geom::{Point3, PointCloud};

use super::{format_error, line_error, lzf, room_for_points, PointFormat, Warning};
use crate::Result;

const FORMAT: &str = "PCD";

/// PCL's Point Cloud Data.
pub struct Pcd;

impl PointFormat for Pcd {
    fn name(&self) -> &'static str {
        FORMAT
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["pcd"]
    }
    fn summary(&self) -> &'static str {
        "ascii, binary or binary_compressed (points with NaN skipped); written binary float32 \
         (float64 where float32 would lose precision)"
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

/// How the data after the header is encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Data {
    Ascii,
    Binary,
    BinaryCompressed,
}

/// One field: `FIELDS` name, `SIZE` bytes, `TYPE` (I, U or F) and `COUNT` values.
#[derive(Clone, Debug, PartialEq, Eq)]
struct Field {
    name: String,
    size: usize,
    kind: u8,
    count: usize,
}

impl Field {
    /// Bytes the field takes in one point.
    fn bytes(&self) -> usize {
        self.size * self.count
    }

    /// The value packed little-endian in `b` (exactly `self.size` bytes).
    fn decode(&self, b: &[u8]) -> f64 {
        macro_rules! le {
            ($t:ty) => {
                <$t>::from_le_bytes(b.try_into().expect("a slice of the field's size")) as f64
            };
        }
        match (self.kind, self.size) {
            (b'I', 1) => b[0] as i8 as f64,
            (b'U', 1) => b[0] as f64,
            (b'I', 2) => le!(i16),
            (b'U', 2) => le!(u16),
            (b'I', 4) => le!(i32),
            (b'U', 4) => le!(u32),
            (b'I', 8) => le!(i64),
            (b'U', 8) => le!(u64),
            (b'F', 4) => le!(f32),
            (b'F', 8) => le!(f64),
            _ => unreachable!("checked when the header is read"),
        }
    }
}

/// The parsed header.
#[derive(Debug)]
struct Header {
    fields: Vec<Field>,
    points: usize,
    data: Data,
    /// Byte offset of the data.
    data_start: usize,
    /// Number of header lines, the `DATA` line last.
    lines: usize,
    /// The `DATA` line's text.
    data_line: String,
}

/// The header, up to its `DATA` line. Keywords may come in any order; an unknown one is skipped
/// with a warning.
fn parse_header(bytes: &[u8], path: &Path, warnings: &mut Vec<Warning>) -> Result<Header> {
    let (mut names, mut sizes, mut kinds, mut counts) = (None, None, None, None);
    let (mut width, mut height, mut points) = (None, None, None);
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
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let bad = |why: String| line_error(path, line_no, line, why);
        let mut tokens = line.split_whitespace();
        let keyword = tokens.next().unwrap_or_default();
        let values: Vec<&str> = tokens.collect();
        let one_number = || -> Result<usize> {
            match values.as_slice() {
                [v] => v
                    .parse()
                    .map_err(|_| bad(format!("`{v}` is not a whole number"))),
                _ => Err(bad(format!("{keyword} takes one number"))),
            }
        };
        let numbers = || -> Result<Vec<usize>> {
            values
                .iter()
                .map(|v| {
                    v.parse()
                        .map_err(|_| bad(format!("`{v}` is not a whole number")))
                })
                .collect()
        };
        match keyword.to_ascii_uppercase().as_str() {
            "VERSION" | "VIEWPOINT" => {}
            "FIELDS" | "COLUMNS" => {
                names = Some(values.iter().map(|s| s.to_string()).collect::<Vec<_>>())
            }
            "SIZE" => sizes = Some((line_no, line.to_string(), numbers()?)),
            "TYPE" => {
                let parsed = values
                    .iter()
                    .map(|v| match *v {
                        "I" | "U" | "F" => Ok(v.as_bytes()[0]),
                        _ => Err(bad(format!("`{v}` is not a type (I, U or F)"))),
                    })
                    .collect::<Result<Vec<u8>>>()?;
                kinds = Some((line_no, line.to_string(), parsed));
            }
            "COUNT" => counts = Some((line_no, line.to_string(), numbers()?)),
            "WIDTH" => width = Some((line_no, line.to_string(), one_number()?)),
            "HEIGHT" => height = Some(one_number()?),
            "POINTS" => points = Some((line_no, line.to_string(), one_number()?)),
            "DATA" => {
                let data =
                    match values.as_slice() {
                        ["ascii"] => Data::Ascii,
                        ["binary"] => Data::Binary,
                        ["binary_compressed"] => Data::BinaryCompressed,
                        _ => return Err(bad(
                            "unknown data encoding (expected ascii, binary or binary_compressed)"
                                .into(),
                        )),
                    };
                let fields = fields(names, sizes, kinds, counts, path, line_no, line)?;
                let (width_line, width_text, width) = width
                    .ok_or_else(|| format_error(path, FORMAT, "the header has no WIDTH line"))?;
                let height = height.unwrap_or(1);
                let product = width.checked_mul(height);
                let points = match points {
                    Some((_, _, n)) if Some(n) == product => n,
                    Some((n_line, n_text, n)) => {
                        let why = format!("POINTS {n} is not WIDTH {width} × HEIGHT {height}");
                        return Err(line_error(path, n_line, &n_text, why));
                    }
                    None => product.ok_or_else(|| {
                        let why = format!("WIDTH {width} × HEIGHT {height} is too large");
                        line_error(path, width_line, &width_text, why)
                    })?,
                };
                return Ok(Header {
                    fields,
                    points,
                    data,
                    data_start: offset,
                    lines: line_no,
                    data_line: line.to_string(),
                });
            }
            _ => warnings.push(Warning {
                path: path.to_path_buf(),
                line: line_no,
                text: line.to_string(),
                why: format!("`{keyword}` is no PCD header keyword; line skipped"),
            }),
        }
    }
    Err(format_error(path, FORMAT, "the header has no DATA line"))
}

/// A header line's number, text and values.
type Numbered<T> = Option<(usize, String, Vec<T>)>;

/// The fields that the FIELDS, SIZE, TYPE and COUNT lines declare (COUNT 1 each when absent).
fn fields(
    names: Option<Vec<String>>,
    sizes: Numbered<usize>,
    kinds: Numbered<u8>,
    counts: Numbered<usize>,
    path: &Path,
    data_line: usize,
    data_text: &str,
) -> Result<Vec<Field>> {
    let missing = |what: &str| {
        let why = format!("the header has no {what} line before DATA");
        line_error(path, data_line, data_text, why)
    };
    let names = names.ok_or_else(|| missing("FIELDS"))?;
    let (size_line, size_text, sizes) = sizes.ok_or_else(|| missing("SIZE"))?;
    let (kind_line, kind_text, kinds) = kinds.ok_or_else(|| missing("TYPE"))?;
    let counts = counts.unwrap_or_else(|| (0, String::new(), vec![1; names.len()]));
    let (count_line, count_text, counts) = counts;
    for (line, text, n) in [
        (size_line, &size_text, sizes.len()),
        (kind_line, &kind_text, kinds.len()),
        (count_line, &count_text, counts.len()),
    ] {
        if n != names.len() {
            let why = format!("{n} values for the {} FIELDS", names.len());
            return Err(line_error(path, line, text, why));
        }
    }
    let mut fields = Vec::with_capacity(names.len());
    for (((name, size), kind), count) in names.into_iter().zip(sizes).zip(kinds).zip(counts) {
        let valid = matches!((kind, size), (b'I' | b'U', 1 | 2 | 4 | 8) | (b'F', 4 | 8));
        if !valid {
            let why = format!(
                "field `{name}` has TYPE {} and SIZE {size} (I and U take 1, 2, 4 or 8 bytes, \
                 F 4 or 8)",
                kind as char
            );
            return Err(line_error(path, size_line, &size_text, why));
        }
        if count == 0 {
            let why = format!("field `{name}` has COUNT 0");
            return Err(line_error(path, count_line, &count_text, why));
        }
        fields.push(Field {
            name,
            size,
            kind,
            count,
        });
    }
    Ok(fields)
}

/// The x, y, z of every point of a PCD file but those with a NaN coordinate; the number skipped
/// and header lines of no keyword go to `warnings`.
pub fn parse(bytes: &[u8], path: &Path, warnings: &mut Vec<Warning>) -> Result<Vec<Point3<f64>>> {
    let header = parse_header(bytes, path, warnings)?;
    let fields = &header.fields;
    let too_large = || {
        let why = "the FIELDS' SIZE × COUNT add up to more bytes than any file holds";
        line_error(path, header.lines, &header.data_line, why)
    };
    // Checked once here: every later sum over the fields is at most these.
    let point_bytes = fields
        .iter()
        .try_fold(0usize, |sum, f| {
            sum.checked_add(f.size.checked_mul(f.count)?)
        })
        .ok_or_else(too_large)?;
    // For each axis, the field's index and its first value's index among a point's values.
    let mut axes = [(0usize, 0usize); 3];
    for (axis, name) in axes.iter_mut().zip(["x", "y", "z"]) {
        let index = fields.iter().position(|f| f.name == name).ok_or_else(|| {
            let why = format!("the header declares no `{name}` field");
            line_error(path, header.lines, &header.data_line, why)
        })?;
        *axis = (index, fields[..index].iter().map(|f| f.count).sum());
    }
    let body = &bytes[header.data_start..];
    let data_error = |why: String| format_error(path, FORMAT, why);
    let mut points = match header.data {
        Data::Ascii => read_ascii(&header, body, &axes, path)?,
        Data::Binary => {
            let needed = header.points.checked_mul(point_bytes);
            if needed.is_none_or(|n| n > body.len()) {
                return Err(data_error(format!(
                    "{} points of {point_bytes} bytes need more than the {} bytes of data the \
                     file holds",
                    header.points,
                    body.len()
                )));
            }
            let offsets: Vec<usize> = axes
                .iter()
                .map(|&(i, _)| fields[..i].iter().map(Field::bytes).sum())
                .collect();
            let mut points = room_for_points(path, header.points as u64, 0)?;
            points.extend(
                body.chunks_exact(point_bytes.max(1))
                    .take(header.points)
                    .map(|p| {
                        let value = |a: usize| {
                            let field = &fields[axes[a].0];
                            field.decode(&p[offsets[a]..offsets[a] + field.size])
                        };
                        Point3::new(value(0), value(1), value(2))
                    }),
            );
            points
        }
        Data::BinaryCompressed => {
            let word = |at: usize| {
                body.get(at..at + 4)
                    .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")) as usize)
                    .ok_or_else(|| data_error("the data ends inside its two sizes".into()))
            };
            let (compressed, size) = (word(0)?, word(4)?);
            let data = body.get(8..8 + compressed).ok_or_else(|| {
                data_error(format!(
                    "{compressed} compressed bytes declared, {} present",
                    body.len() - 8
                ))
            })?;
            if header.points.checked_mul(point_bytes) != Some(size) {
                return Err(data_error(format!(
                    "{} points of {point_bytes} bytes are not the {size} bytes of the \
                     decompressed data",
                    header.points
                )));
            }
            // Sized before decompressing: LZF may expand 88 times, and the points take more.
            let mut points = room_for_points(path, header.points as u64, size as u64)?;
            let data =
                lzf::decompress(data, size).map_err(|why| data_error(format!("LZF: {why}")))?;
            // Field after field: all the points' values of the first field, then the second's.
            let starts: Vec<usize> = axes
                .iter()
                .map(|&(i, _)| header.points * fields[..i].iter().map(Field::bytes).sum::<usize>())
                .collect();
            points.extend((0..header.points).map(|p| {
                let value = |a: usize| {
                    let field = &fields[axes[a].0];
                    let at = starts[a] + p * field.bytes();
                    field.decode(&data[at..at + field.size])
                };
                Point3::new(value(0), value(1), value(2))
            }));
            points
        }
    };
    let before = points.len();
    points.retain(|p| !(p.x.is_nan() || p.y.is_nan() || p.z.is_nan()));
    if points.is_empty() && before > 0 {
        // Said here: "the file holds no point" alone would hide why.
        let why = format!(
            "every one of its {before} points has a NaN coordinate (PCL's invalid points): no \
             point to register"
        );
        return Err(format_error(path, FORMAT, why));
    }
    if points.len() < before {
        warnings.push(Warning {
            path: path.to_path_buf(),
            line: header.lines,
            text: header.data_line.clone(),
            why: format!(
                "{} of {before} points have a NaN coordinate (PCL's invalid points); skipped",
                before - points.len()
            ),
        });
    }
    Ok(points)
}

/// The points of ascii data: one point per line, its values whitespace-separated.
fn read_ascii(
    header: &Header,
    body: &[u8],
    axes: &[(usize, usize); 3],
    path: &Path,
) -> Result<Vec<Point3<f64>>> {
    let text = std::str::from_utf8(body).map_err(|e| {
        format_error(
            path,
            FORMAT,
            format!(
                "the ascii data is not text (bad byte at offset {})",
                header.data_start + e.valid_up_to()
            ),
        )
    })?;
    // At most the point's bytes (a value takes at least one).
    let values: usize = header.fields.iter().map(|f| f.count).sum();
    // A point takes at least two bytes a value ("0 ... 0\n"): the count is bounded before use.
    let mut points = Vec::with_capacity(header.points.min(text.len() / values.saturating_mul(2)));
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (header.lines + 1 + i, l))
        .filter(|(_, l)| !l.trim().is_empty());
    for _ in 0..header.points {
        let Some((n, line)) = lines.next() else {
            let why = format!(
                "the header declares {} points, the data ends after {}",
                header.points,
                points.len()
            );
            return Err(format_error(path, FORMAT, why));
        };
        let tokens: Vec<&str> = line.split_whitespace().collect();
        if tokens.len() != values {
            let why = format!("expected {values} values, found {}", tokens.len());
            return Err(line_error(path, n, line, why));
        }
        let mut xyz = [0.0; 3];
        for (v, &(_, at)) in xyz.iter_mut().zip(axes) {
            *v = tokens[at].parse().map_err(|_| {
                line_error(path, n, line, format!("`{}` is not a number", tokens[at]))
            })?;
        }
        points.push(Point3::new(xyz[0], xyz[1], xyz[2]));
    }
    if let Some((n, line)) = lines.next() {
        let why = format!(
            "more lines than the {} points the header declares",
            header.points
        );
        return Err(line_error(path, n, line, why));
    }
    Ok(points)
}

/// Writes a binary PCD of the fields x, y, z: float32, or float64 where float32 would move the
/// points by more than the PLY writer allows.
pub fn write(out: &mut impl Write, cloud: &PointCloud) -> std::io::Result<()> {
    let single = super::ply::float32_suffices(cloud);
    let size = if single { 4 } else { 8 };
    let n = cloud.len();
    write!(
        out,
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\n\
         SIZE {size} {size} {size}\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\n\
         VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary\n"
    )?;
    let mut bytes = Vec::with_capacity(n * 3 * size);
    for p in &cloud.points {
        for v in [p.x, p.y, p.z] {
            if single {
                bytes.extend((v as f32).to_le_bytes());
            } else {
                bytes.extend(v.to_le_bytes());
            }
        }
    }
    out.write_all(&bytes)
}
