//! PCD, LAS and LAZ files written by other tools (Open3D, laspy; `fixtures/formats/`, made by
//! `fixtures/make_format_fixtures.py`) and by PCL (a 3DMatch scan in `../shared`, skipped when
//! absent), read back with the coordinates their writers were given.

use std::path::{Path, PathBuf};

use rgm_data::io::{format_of, FORMATS};
use rgm_data::{read_point_cloud, read_point_cloud_warned, write_point_cloud};
use rgm_geom::{Point3, PointCloud};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/formats")
        .join(name)
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("rgm-formats-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// The points the fixture script gave Open3D, its NaN point (the fourth) left out.
fn open3d_points() -> Vec<Point3<f64>> {
    vec![
        Point3::new(0.5, -1.25, 2.0),
        Point3::new(1024.125, 3.0, -0.0078125),
        Point3::new(-7.5, 0.25, 100.0),
        Point3::new(1.0, 2.0, 3.0),
    ]
}

#[test]
fn open3d_pcd_in_its_three_encodings_is_read_exactly() {
    for name in [
        "open3d_ascii.pcd",
        "open3d_binary.pcd",
        "open3d_binary_compressed.pcd",
    ] {
        let path = fixture(name);
        let (cloud, warnings) = read_point_cloud_warned(&path).unwrap();
        assert_eq!(cloud.points, open3d_points(), "{name}");
        // The NaN point is skipped, and said so at the DATA line.
        assert_eq!(warnings.len(), 1, "{name}: {warnings:?}");
        assert_eq!(warnings[0].line, 11, "{name}");
        assert!(
            warnings[0]
                .to_string()
                .contains("1 of 5 points have a NaN coordinate"),
            "{}",
            warnings[0]
        );
    }
}

#[test]
fn an_open3d_compressed_grid_decompresses_with_its_back_references() {
    let cloud = read_point_cloud(fixture("open3d_grid_compressed.pcd")).unwrap();
    assert_eq!(cloud.len(), 256);
    // Open3D writes the points in the order it was given them: i major, j minor.
    for (k, p) in cloud.points.iter().enumerate() {
        let (i, j) = ((k / 16) as f64, (k % 16) as f64);
        assert_eq!(*p, Point3::new(i * 0.25, j * -0.5, 8.0), "point {k}");
    }
    // 256 points × 3 floats, compressed to less than half: LZF's back references were used.
    let size = std::fs::metadata(fixture("open3d_grid_compressed.pcd"))
        .unwrap()
        .len();
    assert!(size < 256 * 12 / 2, "{size} bytes");
}

/// `X · 0.001 + offset` as f64, as the LAS definition and laspy compute it.
fn las_points() -> Vec<Point3<f64>> {
    let ints = [
        [123456, -654321, 1500],
        [0, 0, 0],
        [2000000000, -2000000000, -1],
        [7, 8, 9],
    ];
    let offsets = [500000.0, 4000000.0, 100.0];
    ints.iter()
        .map(|x| {
            let c = |a: usize| 0.001 * x[a] as f64 + offsets[a];
            Point3::new(c(0), c(1), c(2))
        })
        .collect()
}

#[test]
fn laspy_las_and_laz_keep_large_offsets_exact() {
    let expected = las_points();
    // The digits that float32 would lose are there.
    assert_eq!(expected[0], Point3::new(500123.456, 3999345.679, 101.5));
    assert_ne!(expected[0].x as f32 as f64, expected[0].x);
    for name in ["laspy.las", "laspy.laz"] {
        let (cloud, warnings) = read_point_cloud_warned(fixture(name)).unwrap();
        assert_eq!(cloud.points, expected, "{name}");
        assert_eq!(warnings, [], "{name}");
    }
    // Layered LAZ (LAS 1.4 point formats 6 to 10) is refused: its decoder allocates from sizes
    // it does not check.
    let err = read_point_cloud(fixture("laspy_14_pf6.laz"))
        .unwrap_err()
        .to_string();
    assert!(
        err.ends_with(
            "LAZ: point format 6 in LAZ (layered compression, formats 6 to 10) is not \
                       read yet; LAS of that format is, and LAZ of formats 0 to 5"
        ),
        "{err}"
    );
}

#[test]
fn las_and_laz_written_by_rgm_round_trip_within_the_stated_bound() {
    // A survey-sized cloud at UTM coordinates, and a unit one.
    let far: Vec<Point3<f64>> = (0..50)
        .map(|k| {
            let k = k as f64;
            Point3::new(
                512345.678 + 3.1 * k,
                4123456.789 - 1.7 * k,
                250.0 + 0.01 * k * k,
            )
        })
        .collect();
    let unit: Vec<Point3<f64>> = (0..50)
        .map(|k| {
            let t = k as f64 * 0.37;
            Point3::new(t.sin(), t.cos() * 0.5, (t * 0.1).tanh())
        })
        .collect();
    // Issue 59, E12: a cloud a tenth of a nanometre across collapsed to one point (the scale
    // had a floor of 1e-9); the bound is the extent's alone.
    let tiny: Vec<Point3<f64>> = (0..50)
        .map(|k| {
            let t = k as f64 * 0.37;
            Point3::new(
                3.0 + 1e-10 * t.sin(),
                1e-10 * t.cos(),
                -1e-10 * (t * 0.1).tanh(),
            )
        })
        .collect();
    for points in [far, unit, tiny] {
        let cloud = PointCloud::new(points);
        let extent = {
            let (lo, hi) = cloud.points.iter().fold(
                (
                    Point3::from([f64::INFINITY; 3]),
                    Point3::from([f64::NEG_INFINITY; 3]),
                ),
                |(lo, hi), p| (lo.inf(p), hi.sup(p)),
            );
            (hi - lo).amax()
        };
        for ext in ["las", "laz", "laz.gz"] {
            let path = scratch(&format!("round_trip.{ext}"));
            write_point_cloud(&path, &cloud).unwrap();
            let back = read_point_cloud(&path).unwrap();
            assert_eq!(back.len(), cloud.len(), "{ext}");
            let bound = 1.25e-9 * extent * 1.01;
            for (a, b) in back.points.iter().zip(&cloud.points) {
                let moved = (a - b).amax();
                assert!(moved <= bound, "{ext}: {a} vs {b}: {moved} > {bound}");
            }
        }
    }
}

/// Issue 59, E7: rgm wrote a LAZ of stacked duplicates (1,024 points × 1,000 in 20,611 bytes)
/// that it then refused to read ("at most 16 points a byte"): LASzip stores a repeated point in
/// a fraction of a bit. What rgm writes, it reads.
#[test]
fn a_laz_of_stacked_duplicates_is_read_back() {
    let shape: Vec<Point3<f64>> = (0..1024)
        .map(|k| {
            let t = k as f64 * 0.37;
            Point3::new(t.sin(), t.cos() * 0.5, (t * 0.1).tanh())
        })
        .collect();
    let stacked = PointCloud::new(
        shape
            .iter()
            .flat_map(|p| std::iter::repeat_n(*p, 1000))
            .collect(),
    );
    let path = scratch("stacked.laz");
    write_point_cloud(&path, &stacked).unwrap();
    let bytes = std::fs::metadata(&path).unwrap().len();
    assert!(bytes < stacked.len() as u64 / 16, "{bytes} bytes");
    assert_eq!(read_point_cloud(&path).unwrap().len(), stacked.len());
}

#[test]
fn pcd_written_by_rgm_round_trips_plain_and_gzipped() {
    let near = PointCloud::new(open3d_points());
    // A few metres at UTM coordinates: float32 would move them by centimetres.
    let far = PointCloud::new(las_points()[..2].to_vec());
    for (cloud, size) in [(&near, "SIZE 4 4 4"), (&far, "SIZE 8 8 8")] {
        for ext in ["pcd", "pcd.gz", "PCD"] {
            let path = scratch(&format!("round_trip.{ext}"));
            write_point_cloud(&path, cloud).unwrap();
            assert_eq!(
                read_point_cloud(&path).unwrap().points,
                cloud.points,
                "{ext}"
            );
        }
        let text = std::fs::read(scratch("round_trip.pcd")).unwrap();
        let text = String::from_utf8_lossy(&text);
        assert!(
            text.contains(size) && text.contains("DATA binary\n"),
            "{text}"
        );
    }
}

/// A scan of 3DMatch's redkitchen as PCL wrote it (binary float32 x y z), from `../shared`.
#[test]
fn a_pcl_binary_scan_is_read() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/scenes/redkitchen/cloud_bin_7.pcd");
    if !path.exists() {
        eprintln!("skipped: {} is absent", path.display());
        return;
    }
    let (cloud, warnings) = read_point_cloud_warned(&path).unwrap();
    assert_eq!(warnings, []);
    assert_eq!(cloud.len(), 246_311);
    let f = |x: f32, y: f32, z: f32| Point3::new(x as f64, y as f64, z as f64);
    assert_eq!(cloud.points[0], f(0.828_000_07, 0.335_999_97, 0.68));
    assert_eq!(cloud.points[1], f(0.834_000_1, 0.335_999_97, 0.68));
    assert_eq!(
        cloud.points[246_310],
        f(0.149_999_98, -0.156_000_02, 3.110_000_1)
    );
}

/// Every format of the list is read and written through its extensions, plain and gzipped.
#[test]
fn every_listed_extension_round_trips() {
    let cloud = PointCloud::new(open3d_points());
    for format in FORMATS {
        for ext in format.extensions() {
            for name in [format!("all.{ext}"), format!("all.{ext}.gz")] {
                let path = scratch(&name);
                assert_eq!(format_of(&path).unwrap().name(), format.name());
                write_point_cloud(&path, &cloud).unwrap();
                let back = read_point_cloud(&path).unwrap();
                for (a, b) in back.points.iter().zip(&cloud.points) {
                    assert!((a - b).amax() < 1e-6, "{name}: {a} vs {b}");
                }
                assert_eq!(back.len(), cloud.len(), "{name}");
            }
        }
    }
}

/// README, the error for an unknown extension and the list agree.
#[test]
fn readme_and_the_unknown_extension_error_name_every_extension() {
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../README.md"))
            .unwrap();
    let err = read_point_cloud("cloud.obj").unwrap_err().to_string();
    for format in FORMATS {
        assert!(
            readme.contains(format.name()),
            "README lacks {}",
            format.name()
        );
        for ext in format.extensions() {
            assert!(
                readme.contains(&format!("`.{ext}`")),
                "README lacks `.{ext}`"
            );
            assert!(err.contains(&format!(".{ext}")), "{err}");
        }
    }
    assert!(err.ends_with(".las or .laz)"), "{err}");
}

/// Issue 59, E10: an all-NaN PCD "held no point" without saying why, and a LAS header of
/// version 2.0 was read on as 1.x, its bytes shown as a huge point count.
#[test]
fn an_all_nan_pcd_and_a_las_of_another_version_say_what_they_are() {
    let nan = scratch("all_nan.pcd");
    std::fs::write(
        &nan,
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\n\
         POINTS 2\nDATA ascii\nnan nan nan\nnan 1 2\n",
    )
    .unwrap();
    let err = read_point_cloud(&nan).unwrap_err().to_string();
    assert!(
        err.contains("every one of its 2 points has a NaN coordinate"),
        "{err}"
    );
    let las = scratch("version.las");
    write_point_cloud(&las, &PointCloud::new(open3d_points())).unwrap();
    let mut bytes = std::fs::read(&las).unwrap();
    bytes[24] = 2;
    bytes[25] = 0;
    std::fs::write(&las, bytes).unwrap();
    let err = read_point_cloud(&las).unwrap_err().to_string();
    assert!(
        err.contains("LAS version 2.0 is not one rgm reads"),
        "{err}"
    );
}
