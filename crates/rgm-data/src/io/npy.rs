//! NumPy `.npy` (format versions 1, 2, 3): little-endian float32 or float64, C order, shape
//! (N, 3). The header is the Python dict literal
//! `{'descr': '<f4', 'fortran_order': False, 'shape': (N, 3), }` padded with spaces to a
//! multiple of 64 bytes and ended by `\n`.

use std::io::Write;
use std::path::Path;

use rgm_geom::{Point3, PointCloud};

use super::{format_error, PointFormat, Warning};
use crate::Result;

const FORMAT: &str = "npy";
pub(crate) const MAGIC: &[u8] = b"\x93NUMPY";

/// NumPy `.npy`.
pub struct Npy;

impl PointFormat for Npy {
    fn name(&self) -> &'static str {
        FORMAT
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["npy"]
    }
    fn summary(&self) -> &'static str {
        "NumPy (N, 3) float32 or float64; written float64"
    }
    fn magic(&self) -> Option<&'static [u8]> {
        Some(MAGIC)
    }
    fn parse(&self, bytes: &[u8], path: &Path, _: &mut Vec<Warning>) -> Result<Vec<Point3<f64>>> {
        parse(bytes, path)
    }
    fn write(&self, mut out: &mut dyn Write, cloud: &PointCloud) -> std::io::Result<()> {
        write(&mut out, cloud, Dtype::F64)
    }
}

/// The element type of an array.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dtype {
    /// `<f4`.
    F32,
    /// `<f8`.
    F64,
}

impl Dtype {
    fn descr(self) -> &'static str {
        match self {
            Self::F32 => "<f4",
            Self::F64 => "<f8",
        }
    }

    fn size(self) -> usize {
        match self {
            Self::F32 => 4,
            Self::F64 => 8,
        }
    }
}

/// The value after `'key':` in a header dict, with surrounding spaces removed.
fn dict_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let start = header
        .find(&format!("'{key}'"))
        .or_else(|| header.find(&format!("\"{key}\"")))?;
    let rest = header[start + key.len() + 2..].trim_start();
    Some(rest.strip_prefix(':')?.trim_start())
}

/// The points of a `.npy` file.
pub fn parse(bytes: &[u8], path: &Path) -> Result<Vec<Point3<f64>>> {
    let fail = |why: String| format_error(path, FORMAT, why);
    super::check_magic(&Npy, bytes, path)?;
    // Magic (6), version (2), header length (2 bytes in version 1, 4 in versions 2 and 3).
    let (len_size, major) = match bytes.get(6) {
        Some(1) => (2, 1),
        Some(&v @ (2 | 3)) => (4, v),
        Some(v) => return Err(fail(format!("unsupported format version {v}"))),
        None => return Err(fail("the file ends inside the preamble".into())),
    };
    let header_start = 8 + len_size;
    let len_bytes = bytes
        .get(8..header_start)
        .ok_or_else(|| fail("the file ends inside the preamble".into()))?;
    let header_len = len_bytes
        .iter()
        .rev()
        .fold(0usize, |acc, &b| (acc << 8) | b as usize);
    let data_start = header_start + header_len;
    let header = bytes.get(header_start..data_start).ok_or_else(|| {
        fail(format!(
            "the header of {header_len} bytes (version {major}) runs past the end of the file"
        ))
    })?;
    let header = std::str::from_utf8(header).map_err(|_| fail("the header is not text".into()))?;

    let descr = dict_value(header, "descr")
        .ok_or_else(|| fail(format!("the header has no 'descr': {header}")))?;
    let dtype = if descr.starts_with("'<f4'") || descr.starts_with("\"<f4\"") {
        Dtype::F32
    } else if descr.starts_with("'<f8'") || descr.starts_with("\"<f8\"") {
        Dtype::F64
    } else {
        let shown: String = descr.chars().take_while(|&c| c != ',').collect();
        return Err(fail(format!(
            "dtype {shown} is not supported (expected '<f4' or '<f8')"
        )));
    };
    match dict_value(header, "fortran_order") {
        Some(v) if v.starts_with("False") => {}
        Some(v) if v.starts_with("True") => {
            return Err(fail("Fortran-order arrays are not supported".into()))
        }
        _ => {
            return Err(fail(format!(
                "the header has no valid 'fortran_order': {header}"
            )))
        }
    }
    let shape_text = dict_value(header, "shape")
        .and_then(|v| v.strip_prefix('('))
        .and_then(|v| v.split(')').next())
        .ok_or_else(|| fail(format!("the header has no valid 'shape': {header}")))?;
    let shape: Vec<usize> = shape_text
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse()
                .map_err(|_| fail(format!("shape ({shape_text}) is not a tuple of integers")))
        })
        .collect::<Result<_>>()?;
    let &[n, 3] = shape.as_slice() else {
        return Err(fail(format!("shape ({shape_text}) is not (N, 3)")));
    };

    let data = &bytes[data_start..];
    let needed = n.checked_mul(3 * dtype.size());
    if needed != Some(data.len()) {
        let needed = needed.map_or("more than memory".to_string(), |b| format!("{b} bytes"));
        return Err(fail(format!(
            "shape ({n}, 3) of {} needs {needed} of data, the file has {}",
            dtype.descr(),
            data.len()
        )));
    }
    let values: Vec<f64> = match dtype {
        Dtype::F32 => data
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()) as f64)
            .collect(),
        Dtype::F64 => data
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
            .collect(),
    };
    Ok(values
        .chunks_exact(3)
        .map(|c| Point3::new(c[0], c[1], c[2]))
        .collect())
}

/// Writes a version-1 `.npy` of shape (N, 3) with element type `dtype`.
pub fn write(out: &mut impl Write, cloud: &PointCloud, dtype: Dtype) -> std::io::Result<()> {
    let dict = format!(
        "{{'descr': '{}', 'fortran_order': False, 'shape': ({}, 3), }}",
        dtype.descr(),
        cloud.len()
    );
    // Magic (6) + version (2) + length (2) + dict + padding + '\n' is a multiple of 64.
    let unpadded = MAGIC.len() + 4 + dict.len() + 1;
    let header_len = dict.len() + 1 + (64 - unpadded % 64) % 64;
    out.write_all(MAGIC)?;
    out.write_all(&[1, 0])?;
    out.write_all(&(header_len as u16).to_le_bytes())?;
    writeln!(out, "{dict:<width$}", width = header_len - 1)?;
    for p in &cloud.points {
        for v in [p.x, p.y, p.z] {
            match dtype {
                Dtype::F32 => out.write_all(&(v as f32).to_le_bytes())?,
                Dtype::F64 => out.write_all(&v.to_le_bytes())?,
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::random_bytes;

    fn parse_bytes(b: &[u8]) -> Result<Vec<Point3<f64>>> {
        parse(b, Path::new("a.npy"))
    }

    fn with_header(dict: &str, data: &[u8]) -> Vec<u8> {
        let mut b = MAGIC.to_vec();
        b.extend([1, 0]);
        b.extend((dict.len() as u16).to_le_bytes());
        b.extend(dict.as_bytes());
        b.extend(data);
        b
    }

    #[test]
    fn round_trips_both_dtypes_with_aligned_header() {
        let cloud = PointCloud::new(vec![
            Point3::new(0.1, -2.0, 3.5),
            Point3::new(1.0 / 3.0, 0.0, 4.0),
        ]);
        for dtype in [Dtype::F32, Dtype::F64] {
            let mut bytes = Vec::new();
            write(&mut bytes, &cloud, dtype).unwrap();
            assert_eq!((bytes.len() - 2 * 3 * dtype.size()) % 64, 0);
            let back = parse_bytes(&bytes).unwrap();
            let round = |v: f64| {
                if dtype == Dtype::F32 {
                    v as f32 as f64
                } else {
                    v
                }
            };
            let expected: Vec<_> = cloud
                .points
                .iter()
                .map(|p| Point3::new(round(p.x), round(p.y), round(p.z)))
                .collect();
            assert_eq!(back, expected);
        }
    }

    #[test]
    fn reads_what_numpy_writes() {
        // python3 -c "import numpy as np, sys; np.save(sys.stdout.buffer, np.array([[1, 2, 3]], '<f4'))" | xxd
        let mut bytes = with_header(
            "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 3), }",
            &[],
        );
        let padded = bytes.len() + (64 - (bytes.len() + 1) % 64) % 64;
        bytes.resize(padded, b' ');
        bytes.push(b'\n');
        bytes[8..10].copy_from_slice(&((padded + 1 - 10) as u16).to_le_bytes());
        for v in [1.0f32, 2.0, 3.0] {
            bytes.extend(v.to_le_bytes());
        }
        assert_eq!(
            parse_bytes(&bytes).unwrap(),
            vec![Point3::new(1.0, 2.0, 3.0)]
        );
    }

    #[test]
    fn header_problems_are_named() {
        let err = |b: &[u8]| parse_bytes(b).unwrap_err().to_string();
        assert_eq!(
            err(b"NUMPY"),
            "a.npy: npy: missing the magic string \\x93NUMPY"
        );
        let big = with_header(
            "{'descr': '>f4', 'fortran_order': False, 'shape': (1, 3), }",
            &[0; 12],
        );
        assert_eq!(
            err(&big),
            "a.npy: npy: dtype '>f4' is not supported (expected '<f4' or '<f8')"
        );
        let fortran = with_header(
            "{'descr': '<f4', 'fortran_order': True, 'shape': (1, 3), }",
            &[0; 12],
        );
        assert_eq!(
            err(&fortran),
            "a.npy: npy: Fortran-order arrays are not supported"
        );
        let wide = with_header(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 4), }",
            &[0; 64],
        );
        assert_eq!(err(&wide), "a.npy: npy: shape (2, 4) is not (N, 3)");
        let short = with_header(
            "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }",
            &[0; 20],
        );
        assert_eq!(
            err(&short),
            "a.npy: npy: shape (2, 3) of <f4 needs 24 bytes of data, the file has 20"
        );
        let mut cut = with_header("{'descr': '<f4'}", &[]);
        cut.truncate(15);
        assert!(
            err(&cut).contains("runs past the end of the file"),
            "{}",
            err(&cut)
        );
    }

    #[test]
    fn garbage_is_an_error_not_a_panic() {
        for len in 0..300 {
            let mut bytes = MAGIC.to_vec();
            bytes.extend(random_bytes(len as u64, len));
            assert!(parse_bytes(&bytes).is_err());
        }
        let huge = with_header(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (18446744073709551615, 3), }",
            &[],
        );
        assert!(parse_bytes(&huge).is_err());
    }
}
