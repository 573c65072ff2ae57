//! XYZ / CSV text: one point per line, the first three columns are x, y, z.
//!
//! Columns are separated by commas (when the line has one) or by whitespace; extra columns are
//! ignored; blank lines and lines starting with `#` are skipped; the first remaining line is a
//! header, and skipped, when none of its columns is a number (a first line with a number in it
//! is a point, and an error if it does not parse: a point is never dropped as a header). A
//! byte-order mark (spreadsheets' "CSV UTF-8") is skipped.

use std::io::Write;
use std::path::Path;

use rgm_geom::{Point3, PointCloud};

use super::{parse_xyz, text, PointFormat, Warning};
use crate::Result;

/// The column separator a file is written with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Separator {
    /// `x y z`, no header.
    Space,
    /// `x,y,z`, with an `x,y,z` header line.
    Comma,
}

/// Whitespace-separated text, written `x y z`.
pub struct Xyz;

/// Comma-separated text, written with an `x,y,z` header.
pub struct Csv;

impl PointFormat for Xyz {
    fn name(&self) -> &'static str {
        "XYZ"
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["xyz", "txt", "pts"]
    }
    fn is_text(&self) -> bool {
        true
    }
    fn summary(&self) -> &'static str {
        "text, x y z first on each line, extra columns ignored"
    }
    fn parse(&self, bytes: &[u8], path: &Path, _: &mut Vec<Warning>) -> Result<Vec<Point3<f64>>> {
        parse(bytes, path)
    }
    fn write(&self, mut out: &mut dyn Write, cloud: &PointCloud) -> std::io::Result<()> {
        write(&mut out, cloud, Separator::Space)
    }
}

impl PointFormat for Csv {
    fn name(&self) -> &'static str {
        "CSV"
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["csv"]
    }
    fn is_text(&self) -> bool {
        true
    }
    fn summary(&self) -> &'static str {
        "comma-separated text, optional header line; written with an x,y,z header"
    }
    fn parse(&self, bytes: &[u8], path: &Path, _: &mut Vec<Warning>) -> Result<Vec<Point3<f64>>> {
        parse(bytes, path)
    }
    fn write(&self, mut out: &mut dyn Write, cloud: &PointCloud) -> std::io::Result<()> {
        write(&mut out, cloud, Separator::Comma)
    }
}

/// The points of an XYZ or CSV file.
pub fn parse(bytes: &[u8], path: &Path) -> Result<Vec<Point3<f64>>> {
    let mut points = Vec::new();
    let mut first = true;
    for (i, line) in text(bytes, path, "XYZ/CSV")?.lines().enumerate() {
        let trimmed = line.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let columns: Vec<&str> = if trimmed.contains(',') {
            trimmed.split(',').collect()
        } else {
            trimmed.split_whitespace().collect()
        };
        let header = columns.iter().all(|c| c.trim().parse::<f64>().is_err());
        if std::mem::take(&mut first) && header {
            continue; // header line
        }
        points.push(parse_xyz(columns, path, i + 1, line)?);
    }
    Ok(points)
}

/// Writes one `x y z` (or `x,y,z`) line per point with Rust's shortest round-trip formatting.
pub fn write(
    out: &mut impl Write,
    cloud: &PointCloud,
    separator: Separator,
) -> std::io::Result<()> {
    let sep = match separator {
        Separator::Space => " ",
        Separator::Comma => {
            writeln!(out, "x,y,z")?;
            ","
        }
    };
    for p in &cloud.points {
        writeln!(out, "{}{sep}{}{sep}{}", p.x, p.y, p.z)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_str(s: &str) -> Result<Vec<Point3<f64>>> {
        parse(s.as_bytes(), Path::new("pts.csv"))
    }

    #[test]
    fn reads_whitespace_commas_headers_and_extra_columns() {
        let points =
            parse_str("x, y, z, intensity\n1, 2, 3, 9\n\n# comment\n4.5,-5,6e-1,0\n").unwrap();
        assert_eq!(
            points,
            vec![Point3::new(1.0, 2.0, 3.0), Point3::new(4.5, -5.0, 0.6)]
        );
        let points = parse_str("  1\t2 3 255 255 255\n-1 -2 -3\n").unwrap();
        assert_eq!(
            points,
            vec![Point3::new(1.0, 2.0, 3.0), Point3::new(-1.0, -2.0, -3.0)]
        );
    }

    #[test]
    fn round_trip_is_exact() {
        let cloud = PointCloud::new(vec![
            Point3::new(0.1, 1.0 / 3.0, -2e-17),
            Point3::new(7.0, 8.0, 9.0),
        ]);
        for sep in [Separator::Space, Separator::Comma] {
            let mut bytes = Vec::new();
            write(&mut bytes, &cloud, sep).unwrap();
            assert_eq!(parse(&bytes, Path::new("a.xyz")).unwrap(), cloud.points);
        }
    }

    #[test]
    fn bad_lines_are_named_with_their_text() {
        let err = parse_str("1 2 3\n4 five 6\n").unwrap_err().to_string();
        assert_eq!(err, "pts.csv:2: `five` is not a number: `4 five 6`");
        let err = parse_str("1 2 3\n\n4 5\n").unwrap_err().to_string();
        assert_eq!(err, "pts.csv:3: expected 3 coordinates, found 2: `4 5`");
        let err = parse_str("1,,3\n").unwrap_err().to_string();
        assert_eq!(err, "pts.csv:1: `` is not a number: `1,,3`");
    }

    #[test]
    fn a_byte_order_mark_is_skipped_and_a_first_line_with_a_number_is_a_point() {
        // Issue 27, case 6: both dropped the first point as a header.
        let points = parse_str("\u{feff}1,2,3\n4,5,6\n").unwrap();
        assert_eq!(points[0], Point3::new(1.0, 2.0, 3.0));
        assert_eq!(points.len(), 2);
        let points = parse_str("\u{feff}x,y,z\n4,5,6\n").unwrap();
        assert_eq!(points, vec![Point3::new(4.0, 5.0, 6.0)]);
        let err = parse_str("\u{2212}1.5 2 3\n4 5 6\n")
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "pts.csv:1: `\u{2212}1.5` is not a number (U+2212 is a minus sign; write -): \
             `\u{2212}1.5 2 3`"
        );
    }

    #[test]
    fn garbage_is_an_error_not_a_panic() {
        assert!(parse(&[0xff, 0xfe, 0x00, 0x41], Path::new("g.xyz")).is_err());
        assert!(parse_str("header only\n1 2\n").is_err());
        assert_eq!(parse_str("").unwrap(), vec![]);
    }
}
