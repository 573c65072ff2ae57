//! Scene fragments with ground truth in the 3DMatch benchmark's layout (rooms, streets), and
//! the registration pairs they make.
//!
//! A scene folder holds the fragments and one `gt.log`: blocks of five lines, `i j n` (`n` the
//! fragments of the scene's sequence), then the 4×4 matrix `T` with `p_i = T · p_j`: fragment
//! `j` is the source, `i` the target, and `T` the ground-truth `t_target_source`. Fragment `k`
//! is the file `cloud_bin_k` (3DMatch's name) or `k`, with any extension [`crate::io`] reads
//! (`.ply`, `.ply.gz`, `.pcd`, `.las`, …).
//!
//! Success is the 3DMatch criterion ([`LoadedScenePair::errors`]): a rotation error below 15° and a
//! translation error below 0.3 m. A [`Turn`] makes a pair harder by turning its source by a
//! known rotation about its centroid (a global method must find any rotation; the published
//! pairs are 4–39° apart).
//!
//! Fragments are read when a pair is loaded ([`ScenePair::load`]), so a scene of sixty
//! 300k-point fragments never sits in memory whole.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use rgm_geom::{Matrix3, Matrix4, PointCloud, RigidTransform, Vector3};

use crate::io::{format_of, read_point_cloud_warned, Warning};
use crate::{DataError, Result};

/// The 3DMatch criterion: a registration succeeds below this rotation error (degrees)…
pub const MAX_ROTATION_ERROR_DEG: f64 = 15.0;
/// …and this translation error (metres).
pub const MAX_TRANSLATION_ERROR: f64 = 0.3;

/// The pairs of one scene folder, in `gt.log`'s order.
#[derive(Clone, Debug)]
pub struct SceneFolder {
    pub path: PathBuf,
    pub pairs: Vec<ScenePair>,
}

/// One pair of `gt.log`: which files, and the ground truth.
#[derive(Clone, Debug)]
pub struct ScenePair {
    /// The pair's number in `gt.log` (0 for its first block).
    pub index: usize,
    /// Fragment `j`, the source, and fragment `i`, the target.
    pub source: PathBuf,
    pub target: PathBuf,
    /// Maps the source's points onto the target's (`T` of `gt.log`).
    pub t_target_source: RigidTransform,
}

/// A known rotation of a pair's source about its centroid: `degrees` about `axis`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Turn {
    pub degrees: f64,
    /// Need not be of unit length; not zero.
    pub axis: Vector3<f64>,
}

/// A pair as it is registered: both clouds, the source turned, and the truth that goes with it.
#[derive(Clone, Debug)]
pub struct LoadedScenePair {
    pub source: PointCloud, // (N,)
    pub target: PointCloud, // (M,)
    pub t_target_source: RigidTransform,
    /// What reading the two files warned of.
    pub warnings: Vec<Warning>,
}

impl SceneFolder {
    /// Reads the folder's `gt.log` and finds each fragment it names (not yet reading them).
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let log = path.join("gt.log");
        if !log.is_file() {
            return Err(DataError::Dataset {
                path: path.to_path_buf(),
                why: "no `gt.log` (the 3DMatch ground-truth file) in the folder".into(),
            });
        }
        let text =
            String::from_utf8(crate::read_regular_file(&log)?).map_err(|_| DataError::Dataset {
                path: log.clone(),
                why: "not UTF-8 text".into(),
            })?;
        let fragments = fragment_files(path)?;
        let mut pairs = Vec::new();
        for entry in parse_gt_log(&text, &log)? {
            let find = |k: u64| {
                fragments.get(&k).cloned().ok_or_else(|| DataError::Line {
                    path: log.clone(),
                    line: entry.line,
                    text: entry.text.clone(),
                    why: format!(
                        "no fragment {k} in {} (a point-cloud file named `cloud_bin_{k}` or `{k}`)",
                        path.display()
                    ),
                })
            };
            pairs.push(ScenePair {
                index: pairs.len(),
                source: find(entry.source)?,
                target: find(entry.target)?,
                t_target_source: entry.t_target_source,
            });
        }
        if pairs.is_empty() {
            return Err(DataError::Dataset {
                path: log,
                why: "no pair (a pair is five lines: `i j n`, then the 4×4 matrix)".into(),
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            pairs,
        })
    }

    /// The fragments its pairs name, each once, in the order `gt.log` first names them (its
    /// target, then its source).
    pub fn fragments(&self) -> Vec<PathBuf> {
        let mut seen = Vec::new();
        for pair in &self.pairs {
            for file in [&pair.target, &pair.source] {
                if !seen.contains(file) {
                    seen.push(file.clone());
                }
            }
        }
        seen
    }
}

impl ScenePair {
    /// The source's and the target's file names, for tables.
    pub fn names(&self) -> (String, String) {
        let name = |p: &Path| {
            p.file_name()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned()
        };
        (name(&self.source), name(&self.target))
    }

    /// Reads both fragments, turning the source by `turn` about its centroid when given (the
    /// truth becomes `T · P⁻¹`, `P` the turn).
    pub fn load(&self, turn: Option<&Turn>) -> Result<LoadedScenePair> {
        let (mut source, mut warnings) = read_point_cloud_warned(&self.source)?;
        let (target, more) = read_point_cloud_warned(&self.target)?;
        warnings.extend(more);
        let mut t_target_source = self.t_target_source;
        if let Some(turn) = turn {
            let c = source.centroid().coords;
            let rotation = turn.rotation();
            // p ↦ R (p − c) + c
            let motion = RigidTransform::new(rotation, c - rotation * c);
            source = source.transformed(&motion);
            t_target_source = t_target_source.compose(&motion.inverse());
        }
        Ok(LoadedScenePair {
            source,
            target,
            t_target_source,
            warnings,
        })
    }
}

impl LoadedScenePair {
    /// The errors of `found` (a `t_target_source`) as the 3DMatch benchmark measures them: the
    /// angle of `R_truthᵀ R` in degrees, and `‖t − t_truth‖` in the clouds' units (metres).
    pub fn errors(&self, found: &RigidTransform) -> (f64, f64) {
        transform_errors(&self.t_target_source, found)
    }
}

/// The errors of `found` against `truth` (both `t_target_source`) as the 3DMatch benchmark
/// measures them: the angle of `R_truthᵀ R` in degrees, and `‖t − t_truth‖` in the clouds' units.
pub fn transform_errors(truth: &RigidTransform, found: &RigidTransform) -> (f64, f64) {
    let rotation = truth.inverse().compose(found).rotation_angle_deg();
    (rotation, (found.translation - truth.translation).norm())
}

impl Turn {
    /// The rotation, about the axis made a unit vector.
    pub fn rotation(&self) -> Matrix3<f64> {
        crate::scans::axis_angle(&self.axis.normalize(), self.degrees.to_radians())
    }
}

impl std::str::FromStr for Turn {
    type Err = String;

    /// `DEG` (about the z axis, the vertical of LiDAR and survey scans) or `DEG@X,Y,Z`.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let number = |t: &str| {
            t.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("`{t}` is not a finite number"))
        };
        let (degrees, axis) = match s.split_once('@') {
            None => (number(s)?, Vector3::z()),
            Some((degrees, axis)) => {
                let values = axis
                    .split(',')
                    .map(number)
                    .collect::<std::result::Result<Vec<f64>, String>>()?;
                let [x, y, z] = values[..] else {
                    return Err(format!("the axis `{axis}` is not three numbers X,Y,Z"));
                };
                (number(degrees)?, Vector3::new(x, y, z))
            }
        };
        if !(axis.norm() > 1e-12 && axis.norm().is_finite()) {
            return Err(format!("the axis of `{s}` has no direction"));
        }
        Ok(Self { degrees, axis })
    }
}

impl std::fmt::Display for Turn {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.axis == Vector3::z() {
            write!(f, "{}°", self.degrees)
        } else {
            let a = self.axis;
            write!(f, "{}° about ({}, {}, {})", self.degrees, a.x, a.y, a.z)
        }
    }
}

/// One block of `gt.log`.
struct LogEntry {
    /// Its first line's number (1-based) and text, for errors.
    line: usize,
    text: String,
    /// `j` and `i`.
    source: u64,
    target: u64,
    t_target_source: RigidTransform,
}

/// The blocks of a `gt.log`: a line `i j n`, then the four rows of `T`. Blank lines are skipped.
fn parse_gt_log(text: &str, log: &Path) -> Result<Vec<LogEntry>> {
    let lines: Vec<(usize, &str)> = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty())
        .collect();
    let bad = |(line, text): (usize, &str), why: String| DataError::Line {
        path: log.to_path_buf(),
        line,
        text: text.chars().take(80).collect(),
        why,
    };
    let mut entries = Vec::new();
    for block in lines.chunks(5) {
        let head = block[0];
        let ids: Vec<u64> = head
            .1
            .split_whitespace()
            .map(|t| t.parse::<u64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| bad(head, "expected `i j n`, three fragment numbers".into()))?;
        let [target, source, _] = ids[..] else {
            return Err(bad(head, "expected `i j n`, three fragment numbers".into()));
        };
        if block.len() < 5 {
            return Err(bad(
                head,
                format!(
                    "the file ends {} rows into this pair's 4×4 matrix",
                    block.len() - 1
                ),
            ));
        }
        let mut m = Matrix4::zeros();
        for (r, &row) in block[1..].iter().enumerate() {
            let values: Vec<f64> = row
                .1
                .split_whitespace()
                .map(|t| t.parse::<f64>().ok().filter(|x| x.is_finite()))
                .collect::<Option<_>>()
                .ok_or_else(|| bad(row, "expected four finite numbers".into()))?;
            if values.len() != 4 {
                return Err(bad(
                    row,
                    format!("expected 4 numbers, found {}", values.len()),
                ));
            }
            for (c, v) in values.into_iter().enumerate() {
                m[(r, c)] = v;
            }
        }
        // The benchmark's own files are rigid to about 1e-4 only (few digits on some lines).
        let t_target_source = RigidTransform::from_matrix4(&m, 1e-3)
            .map_err(|e| bad(head, format!("this pair's matrix is not rigid: {e}")))?;
        entries.push(LogEntry {
            line: head.0,
            text: head.1.to_string(),
            source,
            target,
            t_target_source,
        });
    }
    Ok(entries)
}

/// The point-cloud files of `folder` by fragment number: `cloud_bin_K.EXT` or `K.EXT`. Two files
/// of one number are refused.
fn fragment_files(folder: &Path) -> Result<HashMap<u64, PathBuf>> {
    let entries = std::fs::read_dir(folder).map_err(|source| DataError::Io {
        path: folder.to_path_buf(),
        source,
    })?;
    let mut found: HashMap<u64, PathBuf> = HashMap::new();
    for path in entries.filter_map(|e| e.ok().map(|e| e.path())) {
        if format_of(&path).is_err() {
            continue;
        }
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        let stem = name.split('.').next().unwrap_or_default();
        let Ok(k) = stem
            .strip_prefix("cloud_bin_")
            .unwrap_or(stem)
            .parse::<u64>()
        else {
            continue;
        };
        if let Some(other) = found.insert(k, path.clone()) {
            return Err(DataError::Dataset {
                path: folder.to_path_buf(),
                why: format!(
                    "two files are fragment {k}: {} and {}",
                    other.display(),
                    path.display()
                ),
            });
        }
    }
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rgm_geom::Point3;

    /// A room corner (floor and two walls, 1 cm grid) as fragment 3, and fragment 8 the same
    /// corner seen from a frame turned by 20° and shifted; `gt.log` maps 8 onto 3.
    fn corner_folder(name: &str) -> (PathBuf, RigidTransform) {
        let dir = crate::io::scratch_path(name);
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let mut points = Vec::new();
        for a in 0..40 {
            for b in 0..40 {
                let (u, v) = (a as f64 * 0.02, b as f64 * 0.02);
                points.push(Point3::new(u, v, 0.0));
                points.push(Point3::new(u, 0.0, v));
                points.push(Point3::new(0.0, u, v));
            }
        }
        let target = PointCloud::new(points);
        let truth = RigidTransform::new(
            Turn {
                degrees: 20.0,
                axis: Vector3::new(0.2, 1.0, 0.1),
            }
            .rotation(),
            Vector3::new(0.4, -0.2, 0.1),
        );
        let source = target.transformed(&truth.inverse());
        crate::write_point_cloud(dir.join("cloud_bin_3.ply"), &target).unwrap();
        crate::write_point_cloud(dir.join("8.xyz"), &source).unwrap();
        let rows = truth.to_rows();
        let mut log = String::from("3\t8\t60\n");
        for row in rows {
            let cells: Vec<String> = row.iter().map(|v| format!("{v:.12e}")).collect();
            log.push_str(&cells.join("  "));
            log.push('\n');
        }
        std::fs::write(dir.join("gt.log"), log).unwrap();
        (dir, truth)
    }

    /// The largest distance between the points of `a` and `b` of one index.
    fn worst_gap(a: &PointCloud, b: &PointCloud) -> f64 {
        a.points
            .iter()
            .zip(&b.points)
            .map(|(p, q)| (p - q).norm())
            .fold(0.0, f64::max)
    }

    #[test]
    fn a_folder_gives_its_pairs_with_the_truth_mapping_j_onto_i() {
        let (dir, truth) = corner_folder("scenes-open");
        let folder = SceneFolder::open(&dir).unwrap();
        assert_eq!(folder.pairs.len(), 1);
        let pair = &folder.pairs[0];
        assert_eq!(
            pair.names(),
            ("8.xyz".to_string(), "cloud_bin_3.ply".to_string())
        );
        let loaded = pair.load(None).unwrap();
        // The truth brings the source onto the target (the files keep about 7 digits).
        let worst = worst_gap(
            &loaded.source.transformed(&loaded.t_target_source),
            &loaded.target,
        );
        assert!(worst < 1e-5, "{worst}");
        assert!(loaded.errors(&truth).0 < 1e-4);
        let (r, t) = loaded.errors(&RigidTransform::identity());
        assert!((r - 20.0).abs() < 1e-6, "{r}");
        assert!((t - truth.translation.norm()).abs() < 1e-6, "{t}");
    }

    #[test]
    fn a_turned_source_keeps_the_truth_consistent() {
        let (dir, _) = corner_folder("scenes-turn");
        let pair = &SceneFolder::open(&dir).unwrap().pairs[0];
        let turn: Turn = "135@1,1,1".parse().unwrap();
        let plain = pair.load(None).unwrap();
        let turned = pair.load(Some(&turn)).unwrap();
        // Turned about its centroid: the centroid stays, the points move.
        let shift = (turned.source.centroid() - plain.source.centroid()).norm();
        assert!(shift < 1e-9, "{shift}");
        let worst = worst_gap(
            &turned.source.transformed(&turned.t_target_source),
            &plain.target,
        );
        assert!(worst < 1e-5, "{worst}");
        // The plain truth is now 135° off.
        let (r, _) = turned.errors(&plain.t_target_source);
        assert!((r - 135.0).abs() < 1e-6, "{r}");
    }

    #[test]
    fn turns_parse_with_and_without_an_axis() {
        let t: Turn = "90".parse().unwrap();
        assert_eq!(t.axis, Vector3::z());
        assert!((t.rotation() * Vector3::x() - Vector3::y()).norm() < 1e-12);
        let t: Turn = "180@1,1,1".parse().unwrap();
        assert_eq!(t.degrees, 180.0);
        assert_eq!(t.to_string(), "180° about (1, 1, 1)");
        assert!("x".parse::<Turn>().unwrap_err().contains("`x`"));
        assert!("90@0,0,0"
            .parse::<Turn>()
            .unwrap_err()
            .contains("no direction"));
        assert!("90@1,2"
            .parse::<Turn>()
            .unwrap_err()
            .contains("three numbers"));
    }

    #[test]
    fn bad_logs_name_the_line_and_missing_fragments_name_the_number() {
        let (dir, _) = corner_folder("scenes-bad");
        let log = dir.join("gt.log");
        let good = std::fs::read_to_string(&log).unwrap();
        let lines: Vec<&str> = good.lines().collect();
        let with_line = |k: usize, text: &str| {
            let mut l = lines.clone();
            l[k] = text;
            l.join("\n")
        };
        let cases = [
            (with_line(0, "3 8"), ":1: expected `i j n`"),
            (
                with_line(2, "0 1 0 nan"),
                ":3: expected four finite numbers",
            ),
            (with_line(2, "0 1 0"), ":3: expected 4 numbers, found 3"),
            (
                with_line(4, "0 0 0 2"),
                ":1: this pair's matrix is not rigid",
            ),
            (lines[..3].join("\n"), ":1: the file ends 2 rows"),
            (with_line(0, "3 9 60"), "no fragment 9"),
            (String::new(), "no pair"),
        ];
        for (text, expected) in cases {
            std::fs::write(&log, &text).unwrap();
            let err = SceneFolder::open(&dir).unwrap_err().to_string();
            assert!(err.contains(expected), "{err} should contain {expected}");
        }
        std::fs::remove_file(&log).unwrap();
        let err = SceneFolder::open(&dir).unwrap_err().to_string();
        assert!(err.contains("no `gt.log`"), "{err}");
    }
}
