use super::*;
use crate::io::random_bytes;

fn parse_bytes(b: &[u8]) -> Result<Vec<Point3<f64>>> {
    let mut warnings = Vec::new();
    let points = parse(b, Path::new("s.ply"), &mut warnings)?;
    assert_eq!(warnings, []);
    Ok(points)
}

fn err(b: &[u8]) -> String {
    parse_bytes(b).unwrap_err().to_string()
}

#[test]
fn a_labelled_cloud_reads_back_with_its_labels_after_each_point() {
    let cloud = PointCloud::new(vec![
        Point3::new(0.1, -0.2, 0.3),
        Point3::new(1.0, 2.0, 3.0),
    ]);
    let mut bytes = Vec::new();
    write_labelled(&mut bytes, &cloud, Some(("scan", &[7, 4_000_000_000]))).unwrap();
    let points = parse_bytes(&bytes).unwrap();
    for (read, written) in points.iter().zip(&cloud.points) {
        assert!((read - written).norm() < 1e-6, "{read} {written}");
    }
    let body = bytes.len() - 2 * (3 * 4 + 4);
    assert!(std::str::from_utf8(&bytes[..body])
        .unwrap()
        .ends_with("property uint scan\nend_header\n"));
    let label = |k: usize| {
        let at = body + k * 16 + 12;
        u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
    };
    assert_eq!((label(0), label(1)), (7, 4_000_000_000));
}

#[test]
fn clouds_far_from_the_origin_are_written_in_double_precision() {
    // Issue 27, case 9: map coordinates near 1e6 lost up to 0.25 in float32.
    let near = PointCloud::new(vec![
        Point3::new(0.1, -0.7, 1.0 / 3.0),
        Point3::new(1.0, 0.5, 0.0),
    ]);
    let far = PointCloud::new(
        near.points
            .iter()
            .map(|p| p + Vector3::new(1e6 + 0.123456789, 4e6, -2e6))
            .collect(),
    );
    for (cloud, exact, kind) in [(&near, false, "float"), (&far, true, "double")] {
        let mut bytes = Vec::new();
        write(&mut bytes, cloud).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        assert!(text.contains(&format!("property {kind} x\n")), "{text}");
        let back = parse_bytes(&bytes).unwrap();
        let error = back
            .iter()
            .zip(&cloud.points)
            .map(|(a, b)| (a - b).abs().max())
            .fold(0.0, f64::max);
        if exact {
            assert_eq!(error, 0.0);
        } else {
            assert!(error > 0.0 && error < 1e-7, "{error}");
        }
    }
}

#[test]
fn reads_ascii_with_extra_properties_and_faces() {
    let text = "ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 3\nproperty float x\n\
                property float y\nproperty float z\nproperty uchar red\nproperty list uchar int extra\n\
                element face 1\nproperty list uchar int vertex_indices\nend_header\n\
                0 0 0 255 2 7 8\n1 0.5 -2 0 0\n0 1 3e-1 9 1 4\n3 0 1 2\n";
    let expected = vec![
        Point3::new(0.0, 0.0, 0.0),
        Point3::new(1.0, 0.5, -2.0),
        Point3::new(0.0, 1.0, 0.3),
    ];
    assert_eq!(parse_bytes(text.as_bytes()).unwrap(), expected);
}

/// A binary PLY whose vertices are (nx: float, y: double, x: short, z: int) after a face
/// element, in either byte order.
fn mixed_binary(big_endian: bool) -> Vec<u8> {
    let order = if big_endian {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let mut b = format!(
        "ply\r\nformat {order} 1.0\nelement face 2\nproperty list uchar int vertex_indices\nelement vertex 2\n\
         property float nx\nproperty double y\nproperty short x\nproperty int z\nend_header\n"
    )
    .into_bytes();
    let mut put = |bytes: &[u8]| {
        if big_endian {
            b.extend(bytes.iter().rev())
        } else {
            b.extend(bytes)
        }
    };
    // Faces: [3: 0 1 2], [0].
    put(&[3]);
    for i in [0i32, 1, 2] {
        put(&i.to_le_bytes());
    }
    put(&[0]);
    for (nx, y, x, z) in [(9.0f32, 0.25f64, -3i16, 7i32), (1.0, -1.5, 4, -2)] {
        put(&nx.to_le_bytes());
        put(&y.to_le_bytes());
        put(&x.to_le_bytes());
        put(&z.to_le_bytes());
    }
    b
}

#[test]
fn reads_binary_of_any_type_and_byte_order() {
    let expected = vec![Point3::new(-3.0, 0.25, 7.0), Point3::new(4.0, -1.5, -2.0)];
    assert_eq!(parse_bytes(&mixed_binary(false)).unwrap(), expected);
    assert_eq!(parse_bytes(&mixed_binary(true)).unwrap(), expected);
}

#[test]
fn binary_round_trip_is_float32() {
    let cloud = PointCloud::new(vec![
        Point3::new(0.1, -2.5, 3.0),
        Point3::new(1.0 / 3.0, 0.0, -1e-3),
    ]);
    let mut bytes = Vec::new();
    write(&mut bytes, &cloud).unwrap();
    let back = parse_bytes(&bytes).unwrap();
    for (a, b) in back.iter().zip(&cloud.points) {
        assert_eq!(
            [a.x, a.y, a.z],
            [b.x as f32 as f64, b.y as f32 as f64, b.z as f32 as f64]
        );
    }
}

#[test]
fn header_errors_are_named() {
    assert_eq!(
        err(b"plx\n"),
        "s.ply:1: a PLY file starts with the line `ply`: `plx`"
    );
    assert_eq!(
        err(b"ply\nformat ascii 1.0\nelement vertex 1\n"),
        "s.ply: PLY: the header has no `end_header` line"
    );
    let no_z = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n";
    assert_eq!(
        err(no_z),
        "s.ply: PLY: the vertex element has no `z` property"
    );
    let no_vertex = b"ply\nformat ascii 1.0\nelement face 0\nend_header\n";
    assert_eq!(
        err(no_vertex),
        "s.ply: PLY: the header declares no `vertex` element"
    );
    let bad_type = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n";
    assert_eq!(
        err(bad_type),
        "s.ply:4: unknown property type: `property float128 x`"
    );
    let no_format = b"ply\nelement vertex 0\nend_header\n";
    assert_eq!(
        err(no_format),
        "s.ply: PLY: the header has no `format` line"
    );
}

/// The Stanford dragon's scans: `bye` lines in the header, between `obj_info` lines.
#[test]
fn a_header_line_of_no_keyword_is_skipped_with_a_warning() {
    let text = "ply\nformat ascii 1.0\nobj_info num_cols 2\nbye\nbye now\nelement vertex 2\n\
                property float x\nproperty float y\nproperty float z\nend_header\n0 1 2\n3 4 5\n";
    let mut warnings = Vec::new();
    let points = parse(text.as_bytes(), Path::new("d.ply"), &mut warnings).unwrap();
    assert_eq!(
        points,
        vec![Point3::new(0.0, 1.0, 2.0), Point3::new(3.0, 4.0, 5.0)]
    );
    let shown: Vec<String> = warnings.iter().map(ToString::to_string).collect();
    assert_eq!(
        shown,
        [
            "d.ply:4: warning: `bye` is no PLY header keyword; line skipped: `bye`",
            "d.ply:5: warning: `bye` is no PLY header keyword; line skipped: `bye now`"
        ]
    );
    // A malformed line of a keyword the format has is still refused.
    for bad in [
        "element vertex",
        "format ascii",
        "end_header now",
        "ply again",
    ] {
        let text = format!("ply\nformat ascii 1.0\n{bad}\nend_header\n");
        assert_eq!(
            err(text.as_bytes()),
            format!("s.ply:3: malformed header line: `{bad}`")
        );
    }
}

#[test]
fn truncated_and_wrong_count_data_are_named() {
    let header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    let short = format!("{header}0 0 0\n1 1 1\n");
    assert_eq!(
        err(short.as_bytes()),
        "s.ply: PLY: element `vertex` declares 3 rows of at least 6 bytes, more than the 12 \
         bytes of data the file holds"
    );
    let short_list = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
                      property float z\nproperty list uchar int i\nend_header\n0 0 0 3 1 2 3\n1 1 1 2 5\n";
    assert_eq!(
        err(short_list.as_bytes()),
        "s.ply:10: the row ends after 5 values; the header declares more: `1 1 1 2 5`"
    );
    // Issue 27, case 13: a count too large for memory was called "not a number".
    let huge = "ply\nformat ascii 1.0\nelement vertex 99999999999999999999999\nend_header\n";
    assert_eq!(
        err(huge.as_bytes()),
        "s.ply:3: the element count is larger than any file can hold: \
         `element vertex 99999999999999999999999`"
    );
    let bad_number = format!("{header}0 0 0\n1 one 1\n2 2 2\n");
    assert_eq!(
        err(bad_number.as_bytes()),
        "s.ply:9: `one` is not a number: `1 one 1`"
    );
    let mut binary = Vec::new();
    write(
        &mut binary,
        &PointCloud::new(vec![Point3::new(1.0, 2.0, 3.0); 4]),
    )
    .unwrap();
    binary.truncate(binary.len() - 5);
    assert_eq!(
        err(&binary),
        "s.ply: PLY: element `vertex` declares 4 rows of at least 12 bytes, more than the 43 \
         bytes of data the file holds"
    );
    let mut faces = b"ply\nformat binary_little_endian 1.0\nelement face 1\n\
                      property list uchar int i\nelement vertex 0\nproperty float x\n\
                      property float y\nproperty float z\nend_header\n"
        .to_vec();
    faces.extend([200, 0, 0, 0, 0]);
    assert_eq!(
        err(&faces),
        "s.ply: PLY: the data ends in element `face` at row 0 of 1"
    );
}

/// Issue 14, case 6: a row with more or fewer values than the vertex has properties was
/// read across rows (90 rows of 2 values as 60 points).
#[test]
fn an_ascii_row_must_hold_exactly_its_values() {
    let header = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    let long = format!("{header}0 0 0 7\n1 1 1\n");
    assert_eq!(
        err(long.as_bytes()),
        "s.ply:8: the row holds more than the 3 values of a `vertex` row: `0 0 0 7`"
    );
    let pairs = format!("{header}0 0\n1 1\n2 2\n");
    assert_eq!(
        err(pairs.as_bytes()),
        "s.ply:8: the row ends after 2 values; the header declares more: `0 0`"
    );
    // Blank lines between rows are allowed.
    let blank = format!("{header}0 0 0\n\n1 1 1\n");
    assert_eq!(parse_bytes(blank.as_bytes()).unwrap().len(), 2);
}

/// Issue 14, case 1: an element without properties and a huge count before `vertex` was
/// looped through (10^18 rows), and counts the file cannot hold were believed.
#[test]
fn counts_are_checked_against_the_file_before_any_loop() {
    let junk = "ply\nformat ascii 1.0\nelement junk 1000000000000000000\nelement vertex 3\n\
                property float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n";
    assert_eq!(parse_bytes(junk.as_bytes()).unwrap().len(), 3);
    for encoding in ["ascii", "binary_little_endian", "binary_big_endian"] {
        let huge = format!(
            "ply\nformat {encoding} 1.0\nelement face 1000000000000000000\nproperty uchar n\n\
             element vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n"
        );
        let e = err(huge.as_bytes());
        assert!(
            e.starts_with("s.ply: PLY: element `face` declares 1000000000000000000 rows"),
            "{e}"
        );
        let max = huge.replace("1000000000000000000", &usize::MAX.to_string());
        assert!(err(max.as_bytes()).contains("element `face` declares"));
    }
}

#[test]
fn garbage_is_an_error_not_a_panic() {
    for len in 0..200 {
        let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement face 3\nproperty list int int vertex_indices\nelement vertex 99999999999\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
        bytes.extend(random_bytes(len as u64, len));
        assert!(parse_bytes(&bytes).is_err());
        assert!(parse_bytes(&bytes[len.min(bytes.len())..]).is_err());
    }
    let huge = b"ply\nformat binary_little_endian 1.0\nelement vertex 99999999999\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    assert!(parse_bytes(huge).is_err());
}
