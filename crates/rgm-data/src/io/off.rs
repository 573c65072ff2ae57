//! OFF (Object File Format), vertices only.
//!
//! The first content line starts with the keyword (`OFF`, or a variant with the prefixes
//! `ST`, `C`, `N`: `COFF`, `NOFF`, `CNOFF`, `STOFF`, ...) and may carry the counts
//! `nv nf [ne]` itself; otherwise the next content line does. Then `nv` vertex lines, whose
//! first three numbers are x, y, z (colours, normals after them are ignored). Faces are not read.
//! Blank lines and `#` comments are skipped.

use std::io::Write;
use std::path::Path;

use rgm_geom::{Point3, PointCloud};

use super::{line_error, parse_xyz, text, PointFormat, Warning};
use crate::{DataError, Result};

/// OFF, vertices only.
pub struct Off;

impl PointFormat for Off {
    fn name(&self) -> &'static str {
        "OFF"
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["off"]
    }
    fn is_text(&self) -> bool {
        true
    }
    fn summary(&self) -> &'static str {
        "vertices (faces ignored); written as text"
    }
    fn parse(&self, bytes: &[u8], path: &Path, _: &mut Vec<Warning>) -> Result<Vec<Point3<f64>>> {
        parse(bytes, path)
    }
    fn write(&self, mut out: &mut dyn Write, cloud: &PointCloud) -> std::io::Result<()> {
        write(&mut out, cloud)
    }
}

/// The vertices of an OFF file.
pub fn parse(bytes: &[u8], path: &Path) -> Result<Vec<Point3<f64>>> {
    // (line number from 1, content without comment), blank lines dropped.
    let mut lines = text(bytes, path, "OFF")?
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.split('#').next().unwrap_or("").trim()))
        .filter(|(_, l)| !l.is_empty());

    let (header_line, header) = lines.next().ok_or_else(|| DataError::Empty {
        path: path.to_path_buf(),
    })?;
    let mut header_tokens = header.split_whitespace();
    let keyword = header_tokens.next().unwrap_or("");
    let prefix_ok = keyword
        .strip_suffix("OFF")
        .is_some_and(|p| p.chars().all(|c| "STCN".contains(c)));
    if !prefix_ok {
        return Err(line_error(
            path,
            header_line,
            header,
            "expected the OFF keyword (OFF, COFF, NOFF, ...)",
        ));
    }
    let inline_counts: Vec<&str> = header_tokens.collect();
    let (count_line, count_text, counts) = if inline_counts.is_empty() {
        let (n, l) = lines
            .next()
            .ok_or_else(|| line_error(path, header_line, header, "missing the vertex count"))?;
        (n, l, l.split_whitespace().collect())
    } else {
        (header_line, header, inline_counts)
    };
    let vertex_count: usize = counts[0].parse().map_err(|_| {
        line_error(
            path,
            count_line,
            count_text,
            format!("`{}` is not a vertex count", counts[0]),
        )
    })?;

    let mut points = Vec::with_capacity(vertex_count.min(bytes.len()));
    for _ in 0..vertex_count {
        let Some((n, line)) = lines.next() else {
            let why = format!(
                "the header says {vertex_count} vertices, the file ends after {}",
                points.len()
            );
            return Err(line_error(path, count_line, count_text, why));
        };
        points.push(parse_xyz(line.split_whitespace(), path, n, line)?);
    }
    Ok(points)
}

/// Writes `OFF`, the counts `N 0 0` and one vertex per line (no faces).
pub fn write(out: &mut impl Write, cloud: &PointCloud) -> std::io::Result<()> {
    writeln!(out, "OFF\n{} 0 0", cloud.len())?;
    for p in &cloud.points {
        writeln!(out, "{} {} {}", p.x, p.y, p.z)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_str(s: &str) -> Result<Vec<Point3<f64>>> {
        parse(s.as_bytes(), Path::new("m.off"))
    }

    #[test]
    fn reads_header_variants_and_ignores_faces() {
        let expected = vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.5),
        ];
        let separate = "OFF\n# a comment\n3 1 0\n0 0 0\n1 0 0\n0 1 0.5\n3 0 1 2\n";
        let same_line = "OFF 3 1 0\n0 0 0\n1 0 0\n\n0 1 0.5  # tip\n3 0 1 2\n";
        let coloured =
            "COFF\n3 1 3\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n0 1 0.5 0 0 255 255\n3 0 1 2\n";
        for text in [separate, same_line, coloured] {
            assert_eq!(parse_str(text).unwrap(), expected, "{text}");
        }
    }

    #[test]
    fn round_trip_is_exact() {
        let cloud = PointCloud::new(vec![
            Point3::new(0.1, 1.0 / 3.0, -5.5),
            Point3::new(7.0, 8.0, 9.0),
        ]);
        let mut bytes = Vec::new();
        write(&mut bytes, &cloud).unwrap();
        assert_eq!(parse(&bytes, Path::new("a.off")).unwrap(), cloud.points);
    }

    #[test]
    fn header_and_count_errors_are_named() {
        let err = parse_str("PLY\n3 1 0\n").unwrap_err().to_string();
        assert_eq!(
            err,
            "m.off:1: expected the OFF keyword (OFF, COFF, NOFF, ...): `PLY`"
        );
        let err = parse_str("OFF\nmany 1 0\n").unwrap_err().to_string();
        assert_eq!(err, "m.off:2: `many` is not a vertex count: `many 1 0`");
        let err = parse_str("OFF 3 0 0\n0 0 0\n1 1 1\n")
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "m.off:1: the header says 3 vertices, the file ends after 2: `OFF 3 0 0`"
        );
        let err = parse_str("OFF\n2 0 0\n0 0 0\n1 x 1\n")
            .unwrap_err()
            .to_string();
        assert_eq!(err, "m.off:4: `x` is not a number: `1 x 1`");
        let err = parse_str("OFF\n").unwrap_err().to_string();
        assert_eq!(err, "m.off:1: missing the vertex count: `OFF`");
    }

    #[test]
    fn garbage_is_an_error_not_a_panic() {
        assert!(parse(&[0x80, 0x81], Path::new("g.off")).is_err());
        assert!(parse_str("").is_err());
        assert!(parse_str("OFF 99999999999999999999 0 0\n").is_err());
        assert!(parse_str("OFF 18446744073709551615 0 0\n1 2 3\n").is_err());
    }
}
