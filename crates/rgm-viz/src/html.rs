//! A registration as one self-contained HTML page that turns in a browser: the clouds before and
//! after the transform (a toggle), the source coloured by whether its points lie within the
//! inlier distance of the target, RGM's correspondences when they are the result's, and a panel
//! with the transform and the candidates. Orbit, zoom, pan and point size by mouse or touch.
//!
//! The renderer is rgm's own (`viewer/viewer.js`, a few hundred lines of WebGL 1: points as
//! `gl.POINTS`, lines for correspondences), compiled into the binary with `include_str!`, so the
//! page needs no network when it is viewed; `docs/viewer.md` says why it is not three.js.
//!
//! The points travel in the page as base64 of little-endian f32 arrays (4 bytes a coordinate,
//! decoded with one `atob` and a typed-array view), centred and scaled so that f32 keeps map
//! coordinates exact enough. Clouds beyond a point budget are thinned by a fixed stride, and the
//! page says so.

use rgm_geom::frame::{FrameRule, Normalisation};
use rgm_geom::{KnnIndex, PointCloud, RigidTransform, Vector3};
use rgm_registration::fit::score;
use rgm_registration::methods::refine::RefineConfig;
use rgm_registration::registrar::Candidate;
use rgm_registration::Registration;
use serde_json::json;

use crate::{RenderError, Result};

/// Points shown by default, both clouds together: a 1M-point scan stays smooth to turn on a
/// laptop's integrated GPU, and the page stays near 3 MB.
pub const DEFAULT_POINT_BUDGET: usize = 200_000;

/// The budget of a page shown inline in a notebook, which keeps its page in the notebook file.
pub const INLINE_POINT_BUDGET: usize = 50_000;

/// Most correspondence lines drawn; more only hide the clouds.
pub const MAX_LINES: usize = 5_000;

/// The page around the data and the viewer (`/*DATA*/` and `/*VIEWER*/` mark where they go).
const TEMPLATE: &str = include_str!("viewer/page.html");
/// The renderer.
const VIEWER: &str = include_str!("viewer/viewer.js");

/// The distance under which a moved source point counts as lying on the target, and why it is
/// that distance (both shown on the page).
#[derive(Clone, Debug, PartialEq)]
pub struct InlierDistance {
    /// In the clouds' units.
    pub distance: f64,
    pub why: String,
}

impl InlierDistance {
    /// The refinement's finest correspondence distance (`RefineConfig::finest_distance`, 0.03 in
    /// the unit-sphere frame), in the clouds' units (the frame by `rule`, as the method's): the
    /// distance at which a refined result's fitness counts a source point as an inlier.
    pub fn of_refinement(source: &PointCloud, target: &PointCloud, rule: &FrameRule) -> Self {
        let unit = RefineConfig::default().finest_distance();
        let scale = Normalisation::of_pair(source, target, rule).scale;
        Self {
            distance: unit * scale,
            why: if scale == 1.0 {
                format!("the refinement's finest correspondence distance ({unit})")
            } else {
                format!(
                    "the refinement's finest correspondence distance, {unit} in the \
                     unit-sphere frame, times the pair's scale into it ({scale:.6})"
                )
            },
        }
    }
}

/// What the page says about the result beside the clouds: filled from a [`Registration`] by
/// [`ResultNotes::of_registration`], or by hand for a transform that no method found here.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ResultNotes {
    /// The method that found the transform (`auto+refine`), or where the transform came from.
    pub method: String,
    /// A composite's candidates, each with its score; empty for a single method.
    pub candidates: Vec<Candidate>,
    /// The index in `candidates` of the one taken.
    pub chosen: Option<usize>,
    /// Why the result is not to be trusted, when it is not.
    pub doubt: Option<String>,
    /// (source index, target index) pairs to draw as lines: RGM's own matches, when those are
    /// the result's correspondences; empty otherwise.
    pub correspondences: Vec<(usize, usize)>,
    /// What `correspondences` are, or why none are drawn.
    pub correspondences_note: String,
    /// The result's own score, when a method ran: (fitness, inlier RMSE, time in ms).
    pub fitness: Option<(f64, f64, f64)>,
}

impl ResultNotes {
    /// The notes of `registration` by method `method` (as [`rgm_registration::MethodId`] spells it).
    /// Its correspondences are drawn only when they are RGM's hard matches (`rgm`, unrefined):
    /// a refined result's correspondences are its inliers, which the colouring shows already.
    pub fn of_registration(method: &str, registration: &Registration) -> Self {
        let (correspondences, correspondences_note) = if method == "rgm" {
            (
                registration.correspondences.clone(),
                "RGM's hard correspondences of its last pass".to_string(),
            )
        } else {
            (
                Vec::new(),
                "none drawn: this result's correspondences are its inliers (the colouring); \
                 RGM's own matches are drawn when they are the result's (--method rgm \
                 --no-refine)"
                    .to_string(),
            )
        };
        let result = &registration.result;
        Self {
            method: method.to_string(),
            candidates: registration.candidates.clone(),
            chosen: registration.chosen,
            doubt: registration.doubt.clone(),
            correspondences,
            correspondences_note,
            fitness: Some((result.fitness, result.inlier_rmse, registration.time_ms)),
        }
    }
}

/// Everything one page shows.
#[derive(Clone, Debug)]
pub struct Page<'a> {
    /// What the page is called (the files' names).
    pub title: String,
    pub source: &'a PointCloud,
    pub target: &'a PointCloud,
    pub t_target_source: RigidTransform,
    pub inlier_distance: InlierDistance,
    pub notes: ResultNotes,
    /// Most points shown, both clouds together (at least 2).
    pub point_budget: usize,
}

/// Height of the frame of [`inline_frame`], in CSS pixels.
pub const INLINE_HEIGHT_PX: u32 = 520;

/// `page` inside an iframe (as its `srcdoc`), for a notebook's output cell: the page keeps its
/// own document, so its script and style touch nothing of the notebook's, and the notebook file
/// holds it whole (no file beside it to lose).
pub fn inline_frame(page: &str) -> String {
    let escaped = page.replace('&', "&amp;").replace('"', "&quot;");
    format!(
        "<iframe srcdoc=\"{escaped}\" sandbox=\"allow-scripts\" style=\"width: 100%; \
         height: {INLINE_HEIGHT_PX}px; border: 1px solid #ccc\"></iframe>"
    )
}

/// How many points of clouds of `n_source` and `n_target` points are shown within `budget`:
/// all of both when they fit, otherwise half the budget each, the share a smaller cloud leaves
/// going to the other.
pub fn display_counts(n_source: usize, n_target: usize, budget: usize) -> (usize, usize) {
    if n_source + n_target <= budget {
        return (n_source, n_target);
    }
    let half = budget / 2;
    if n_source <= half {
        (n_source, budget - n_source)
    } else if n_target <= half {
        (budget - n_target, n_target)
    } else {
        (half, budget - half)
    }
}

/// `keep` indices of `0..n`, evenly spaced by a fixed stride (`k · n / keep`), in order: the
/// same points on every run, spread over the whole file whatever its order.
pub fn stride_indices(n: usize, keep: usize) -> Vec<usize> {
    let keep = keep.min(n);
    (0..keep).map(|k| k * n / keep).collect()
}

impl Page<'_> {
    /// The page as one HTML document.
    pub fn to_html(&self) -> Result<String> {
        let op = "html page";
        if self.source.is_empty() || self.target.is_empty() {
            return Err(RenderError::Empty { op });
        }
        if self.point_budget < 2 {
            return Err(RenderError::Invalid {
                op,
                why: format!(
                    "the point budget must be at least 2, got {}",
                    self.point_budget
                ),
            });
        }
        let d = self.inlier_distance.distance;
        if !(d > 0.0 && d.is_finite()) {
            return Err(RenderError::Invalid {
                op,
                why: format!("the inlier distance must be finite and > 0, got {d}"),
            });
        }
        let (n, m) = (self.source.len(), self.target.len());
        if let Some(&(i, j)) = self
            .notes
            .correspondences
            .iter()
            .find(|&&(i, j)| i >= n || j >= m)
        {
            return Err(RenderError::OutOfRange {
                op,
                source_index: i,
                target_index: j,
                n_source: n,
                n_target: m,
            });
        }
        let t = &self.t_target_source;
        let moved_all = self.source.transformed(t);
        let finite =
            |cloud: &PointCloud| cloud.points.iter().all(|p| p.iter().all(|c| c.is_finite()));
        if !finite(self.source) || !finite(self.target) || !finite(&moved_all) {
            return Err(RenderError::Invalid {
                op,
                why: "a point or the transform has a coordinate that is not finite".to_string(),
            });
        }
        let (shown_n, shown_m) = display_counts(n, m, self.point_budget);
        let source_kept = stride_indices(n, shown_n);
        let source = self.source.select(&source_kept);
        let target = self.target.select(&stride_indices(m, shown_m));

        // Which shown source points lie within `d` of the whole target once moved: the same
        // test as the result's fitness.
        let mut inliers = Vec::new();
        let tree = KnnIndex::new(&self.target.points);
        score(&source.points, &tree, t, d, Some(&mut inliers));
        let mut inlier_flags = vec![0u8; source.len()]; // (n shown,)
        for &(i, _) in &inliers {
            inlier_flags[i] = 1;
        }

        // One frame for the page: centred on the middle of everything drawn and scaled into
        // [-1, 1]³, so f32 holds any input; the moved source follows by `after`.
        let frame = PageFrame::of(&[self.source, self.target, &moved_all]);
        let line_pairs: Vec<(usize, usize)> = {
            let k = self.notes.correspondences.len();
            stride_indices(k, MAX_LINES.min(k))
                .into_iter()
                .map(|l| self.notes.correspondences[l])
                .collect()
        };
        let line_source = PointCloud::new(
            line_pairs
                .iter()
                .map(|&(i, _)| self.source.points[i])
                .collect(),
        );
        let line_target = PointCloud::new(
            line_pairs
                .iter()
                .map(|&(_, j)| self.target.points[j])
                .collect(),
        );

        let candidates: Vec<_> = self
            .notes
            .candidates
            .iter()
            .enumerate()
            .map(|(k, c)| {
                json!({
                    "method": c.method,
                    "score": c.score,
                    "failure": c.failure,
                    "timeMs": c.time_ms,
                    "chosen": self.notes.chosen == Some(k),
                })
            })
            .collect();
        let data = json!({
            "title": self.title,
            "method": self.notes.method,
            "doubt": self.notes.doubt,
            "fitness": self.notes.fitness.map(|(f, _, _)| f),
            "inlierRmse": self.notes.fitness.map(|(_, r, _)| r),
            "timeMs": self.notes.fitness.map(|(_, _, ms)| ms),
            "transform": t.to_rows(),
            "budget": self.point_budget,
            "source": {"points": n, "shown": shown_n, "xyz": base64(&frame.f32_bytes(&source))},
            "target": {"points": m, "shown": shown_m, "xyz": base64(&frame.f32_bytes(&target))},
            "inlier": base64(&inlier_flags),
            "inlierDistance": d,
            "inlierWhy": self.inlier_distance.why,
            "after": frame.moved_matrix(t),
            "candidates": candidates,
            "correspondences": {
                "note": self.notes.correspondences_note,
                "total": self.notes.correspondences.len(),
                "shown": line_pairs.len(),
                "source": base64(&frame.f32_bytes(&line_source)),
                "target": base64(&frame.f32_bytes(&line_target)),
            },
        });
        Ok(page_with(&data))
    }
}

/// The viewer's page with `data` in it.
pub(crate) fn page_with(data: &serde_json::Value) -> String {
    // No `<` in the data: the HTML parser would read `</script` as the end of its element
    // and `<!--` followed by `<script` as the start of its double-escaped state, which
    // swallows the viewer's script. JSON has `<` only inside strings, where `\u003c` is
    // the same character.
    let data = data.to_string().replace('<', "\\u003c");
    let (head, rest) = TEMPLATE
        .split_once("/*DATA*/")
        .expect("the template marks its data");
    let (middle, tail) = rest
        .split_once("/*VIEWER*/")
        .expect("the template marks its viewer");
    [head, &data, middle, VIEWER, tail].concat()
}

/// The page's coordinates: `p' = (p − centre) / scale`.
pub(crate) struct PageFrame {
    centre: Vector3<f64>,
    scale: f64,
}

impl PageFrame {
    /// Centred on the middle of the box holding every cloud, scaled so that its largest side is 2.
    pub(crate) fn of(clouds: &[&PointCloud]) -> Self {
        let (lo, hi) =
            rgm_geom::cloud::bounds(clouds.iter().flat_map(|c| c.points.iter().copied()));
        let side = (hi - lo).max();
        Self {
            centre: (lo + hi) / 2.0,
            scale: if side > 0.0 { side / 2.0 } else { 1.0 },
        }
    }

    /// The points of `cloud` in this frame as little-endian f32 bytes. // (N, 3) f32
    pub(crate) fn f32_bytes(&self, cloud: &PointCloud) -> Vec<u8> {
        cloud
            .points
            .iter()
            .flat_map(|p| {
                let q = (p.coords - self.centre) / self.scale;
                [q.x as f32, q.y as f32, q.z as f32]
            })
            .flat_map(f32::to_le_bytes)
            .collect()
    }

    /// `t` acting in this frame, as WebGL takes a matrix: 4×4, column after column.
    /// p' ↦ (R (s p' + c) + t − c) / s = R p' + (R c + t − c) / s.
    fn moved_matrix(&self, t: &RigidTransform) -> [f64; 16] {
        let shift = (t.rotation * self.centre + t.translation - self.centre) / self.scale;
        let mut columns = [0.0; 16]; // (4 columns, 4 rows)
        for c in 0..3 {
            for r in 0..3 {
                columns[4 * c + r] = t.rotation[(r, c)];
            }
        }
        columns[12..15].copy_from_slice(shift.as_slice());
        columns[15] = 1.0;
        columns
    }
}

/// Standard base64 (RFC 4648, with `=` padding), as the browser's `atob` reads it.
pub(crate) fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let bits = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(bits >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use rgm_geom::{Matrix3, Point3};

    /// A frame rule for the tests, of the default's values (rgm-model's `policy::TUNED.frame`,
    /// which this crate, on rgm-model's layer, cannot read): the tests need a rule, not those.
    const FRAME: FrameRule = FrameRule {
        far_outlier: 12.0,
        within: 2.0,
        extent: (0.3, 1.7),
    };

    /// Standard base64 back to bytes (what the page's `atob` does).
    pub(crate) fn unbase64(text: &str) -> Vec<u8> {
        let value = |c: u8| match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => panic!("{c} is not base64"),
        };
        let mut out = Vec::new();
        for quad in text.as_bytes().chunks(4) {
            let digits: Vec<u8> = quad
                .iter()
                .filter(|&&c| c != b'=')
                .map(|&c| value(c))
                .collect();
            let bits =
                digits.iter().fold(0u32, |acc, &d| acc << 6 | d as u32) << (6 * (4 - digits.len()));
            out.extend_from_slice(&bits.to_be_bytes()[1..digits.len()]);
        }
        out
    }

    /// The f32 rows of a base64 field. // (N, 3)
    pub(crate) fn points_of(field: &serde_json::Value) -> Vec<[f32; 3]> {
        let bytes = unbase64(field.as_str().unwrap());
        assert_eq!(bytes.len() % 12, 0);
        bytes
            .chunks(12)
            .map(|row| {
                std::array::from_fn(|c| {
                    f32::from_le_bytes(row[4 * c..4 * c + 4].try_into().unwrap())
                })
            })
            .collect()
    }

    /// The text of the JSON data element of a page.
    fn data_text(html: &str) -> &str {
        let start = html
            .find(r#"<script id="rgm-data" type="application/json">"#)
            .unwrap();
        let body = &html[start..];
        &body[body.find('>').unwrap() + 1..body.find("</script>").unwrap()]
    }

    /// The JSON data a page carries.
    pub(crate) fn data_of(html: &str) -> serde_json::Value {
        serde_json::from_str(data_text(html)).unwrap()
    }

    /// `n` points along a helix, far from the origin and in metres, like a scan.
    fn helix(n: usize) -> PointCloud {
        PointCloud::new(
            (0..n)
                .map(|i| {
                    let a = i as f64 * 0.01;
                    Point3::new(1000.0 + a.cos(), 2000.0 + a.sin(), 50.0 + 0.001 * i as f64)
                })
                .collect(),
        )
    }

    fn page<'a>(source: &'a PointCloud, target: &'a PointCloud, t: RigidTransform) -> Page<'a> {
        Page {
            title: "a → b".to_string(),
            source,
            target,
            t_target_source: t,
            inlier_distance: InlierDistance {
                distance: 0.01,
                why: "a test's".to_string(),
            },
            notes: ResultNotes::default(),
            point_budget: DEFAULT_POINT_BUDGET,
        }
    }

    #[test]
    fn base64_is_rfc_4648() {
        // RFC 4648 §10.
        let vectors = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ];
        for (plain, encoded) in vectors {
            assert_eq!(base64(plain.as_bytes()), encoded);
            assert_eq!(unbase64(encoded), plain.as_bytes());
        }
        let every_byte: Vec<u8> = (0..=255).collect();
        assert_eq!(unbase64(&base64(&every_byte)), every_byte);
    }

    #[test]
    fn the_budget_is_shared_and_never_exceeded() {
        assert_eq!(display_counts(700, 800, 200_000), (700, 800));
        assert_eq!(
            display_counts(300_000, 250_000, 200_000),
            (100_000, 100_000)
        );
        // A small cloud leaves its unused half to the other.
        assert_eq!(
            display_counts(20_000, 1_000_000, 200_000),
            (20_000, 180_000)
        );
        assert_eq!(
            display_counts(1_000_000, 20_000, 200_000),
            (180_000, 20_000)
        );
        assert_eq!(display_counts(5, 5, 3), (1, 2));
        for (n, m, budget) in [(10, 10, 7), (1, 100, 2), (12_345, 678, 1_000), (3, 3, 6)] {
            let (a, b) = display_counts(n, m, budget);
            assert!(
                a + b <= budget && a <= n && b <= m && a >= 1 && b >= 1,
                "{n} {m} {budget}"
            );
            let kept = stride_indices(n, a);
            assert_eq!(kept.len(), a);
            assert!(kept.windows(2).all(|w| w[0] < w[1]) && kept.last() < Some(&n));
        }
        assert_eq!(stride_indices(10, 4), [0, 2, 5, 7]);
        assert_eq!(stride_indices(3, 5), [0, 1, 2]);
    }

    #[test]
    fn the_page_holds_the_points_it_says_and_they_decode_back() {
        let (source, target) = (helix(300), helix(500));
        let turn = RigidTransform::new(
            Matrix3::new(
                0.3f64.cos(),
                -0.3f64.sin(),
                0.0,
                0.3f64.sin(),
                0.3f64.cos(),
                0.0,
                0.0,
                0.0,
                1.0,
            ),
            Vector3::new(2.0, -1.0, 0.5),
        );
        let mut page = page(&source, &target, turn);
        page.point_budget = 400;
        let html = page.to_html().unwrap();
        let data = data_of(&html);
        assert_eq!(data["source"]["points"], 300);
        assert_eq!(data["target"]["points"], 500);
        assert_eq!(data["source"]["shown"], 200);
        assert_eq!(data["target"]["shown"], 200);
        let shown_source = points_of(&data["source"]["xyz"]);
        let shown_target = points_of(&data["target"]["xyz"]);
        assert_eq!((shown_source.len(), shown_target.len()), (200, 200));
        assert_eq!(unbase64(data["inlier"].as_str().unwrap()).len(), 200);
        // The page's frame: centred and within [-1, 1]; each shown point is the point of the
        // stride, and `after` moves it where the transform moves the original.
        let frame = PageFrame::of(&[&source, &target, &source.transformed(&turn)]);
        let after: Vec<f64> = data["after"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        for (k, &i) in stride_indices(300, 200).iter().enumerate() {
            let p = source.points[i];
            let expected = (p.coords - frame.centre) / frame.scale;
            let q = shown_source[k];
            for c in 0..3 {
                assert!((q[c] as f64 - expected[c]).abs() < 1e-6, "{q:?} {expected}");
                assert!(q[c].abs() <= 1.0 + 1e-6);
            }
            let moved: Vec<f64> = (0..3)
                .map(|r| {
                    (0..3).map(|c| after[4 * c + r] * q[c] as f64).sum::<f64>() + after[12 + r]
                })
                .collect();
            let truth = (turn.apply(&p).coords - frame.centre) / frame.scale;
            for r in 0..3 {
                assert!((moved[r] - truth[r]).abs() < 1e-5, "{moved:?} {truth}");
            }
        }
        let first_target = (target.points[0].coords - frame.centre) / frame.scale;
        assert!((shown_target[0][2] as f64 - first_target.z).abs() < 1e-6);
        // The viewer and its data are in the page; the data says how it was thinned.
        assert!(html.contains("getContext(\"webgl\""));
        assert_eq!(data["budget"], 400);
    }

    #[test]
    fn the_source_is_coloured_by_its_distance_to_the_whole_target() {
        // The identity on a cloud onto itself, with every other source point pushed 1 m off:
        // exactly the untouched half lies within the inlier distance.
        let target = helix(1000);
        let source = PointCloud::new(
            target
                .points
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    if i % 2 == 0 {
                        *p
                    } else {
                        p + Vector3::new(0.0, 0.0, 1.0)
                    }
                })
                .collect(),
        );
        let html = page(&source, &target, RigidTransform::identity())
            .to_html()
            .unwrap();
        let flags = unbase64(data_of(&html)["inlier"].as_str().unwrap());
        assert_eq!(flags.len(), 1000);
        for (i, &flag) in flags.iter().enumerate() {
            assert_eq!(flag, u8::from(i % 2 == 0), "point {i}");
        }
    }

    #[test]
    fn correspondences_become_lines_between_their_points() {
        let (source, target) = (helix(50), helix(60));
        let mut page = page(&source, &target, RigidTransform::identity());
        page.notes.correspondences = vec![(0, 59), (49, 0), (10, 10)];
        page.notes.correspondences_note = "RGM's".to_string();
        let data = data_of(&page.to_html().unwrap());
        let ends = (
            points_of(&data["correspondences"]["source"]),
            points_of(&data["correspondences"]["target"]),
        );
        assert_eq!(data["correspondences"]["shown"], 3);
        let frame = PageFrame::of(&[&source, &target, &source]);
        let at = |p: &Point3<f64>| (p.coords - frame.centre) / frame.scale;
        assert!((ends.0[1][0] as f64 - at(&source.points[49]).x).abs() < 1e-6);
        assert!((ends.1[0][1] as f64 - at(&target.points[59]).y).abs() < 1e-6);
        // Many are drawn by stride, at most MAX_LINES.
        page.notes.correspondences = (0..12_000).map(|k| (k % 50, k % 60)).collect();
        let data = data_of(&page.to_html().unwrap());
        assert_eq!(data["correspondences"]["total"], 12_000);
        assert_eq!(data["correspondences"]["shown"], MAX_LINES);
        assert_eq!(
            points_of(&data["correspondences"]["source"]).len(),
            MAX_LINES
        );
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let (cloud, empty) = (helix(10), PointCloud::new(Vec::new()));
        let identity = RigidTransform::identity();
        assert!(matches!(
            page(&cloud, &empty, identity).to_html(),
            Err(RenderError::Empty { .. })
        ));
        let mut outside = page(&cloud, &cloud, identity);
        outside.notes.correspondences = vec![(3, 10)];
        let err = outside.to_html().unwrap_err();
        assert!(err.to_string().contains("(3, 10)"), "{err}");
        let mut few = page(&cloud, &cloud, identity);
        few.point_budget = 1;
        assert!(few
            .to_html()
            .unwrap_err()
            .to_string()
            .contains("at least 2"));
        let mut no_distance = page(&cloud, &cloud, identity);
        no_distance.inlier_distance.distance = f64::NAN;
        assert!(no_distance.to_html().is_err());
        let nan = PointCloud::new(vec![Point3::new(f64::NAN, 0.0, 0.0)]);
        assert!(page(&nan, &cloud, identity)
            .to_html()
            .unwrap_err()
            .to_string()
            .contains("finite"));
    }

    #[test]
    fn the_inline_frame_holds_the_page_escaped() {
        let cloud = helix(10);
        let mut page = page(&cloud, &cloud, RigidTransform::identity());
        page.title = "\"quoted\" & <b>".to_string();
        let html = page.to_html().unwrap();
        let frame = inline_frame(&html);
        let srcdoc = frame
            .strip_prefix("<iframe srcdoc=\"")
            .and_then(|rest| rest.split_once('"'))
            .unwrap()
            .0;
        assert_eq!(srcdoc.replace("&quot;", "\"").replace("&amp;", "&"), html);
        assert!(frame.contains(&format!("height: {INLINE_HEIGHT_PX}px")));
    }

    #[test]
    fn only_rgms_own_matches_are_drawn() {
        let result = rgm_registration::Fit::scored(
            RigidTransform::identity(),
            2,
            true,
            score(
                &[],
                &KnnIndex::new(&[]),
                &RigidTransform::identity(),
                1.0,
                None,
            ),
        );
        let registration =
            Registration::single(result, vec![(0, 1), (2, 3)], std::time::Instant::now());
        assert_eq!(
            ResultNotes::of_registration("rgm", &registration)
                .correspondences
                .len(),
            2
        );
        let refined = ResultNotes::of_registration("rgm+refine", &registration);
        assert!(refined.correspondences.is_empty());
        assert!(refined.correspondences_note.contains("inliers"));
    }

    #[test]
    fn a_title_that_opens_a_comment_and_a_script_leaves_the_viewer_whole() {
        let cloud = helix(10);
        let mut page = page(&cloud, &cloud, RigidTransform::identity());
        page.title = "scan <!--<script> 1.ply".to_string();
        let html = page.to_html().unwrap();
        assert_eq!(data_of(&html)["title"], page.title);
        // The data element holds no `<` at all, so no parser state can start inside it.
        let data = data_text(&html);
        assert!(!data.contains('<'), "{data}");
        assert_eq!(
            html.matches("<script").count(),
            TEMPLATE.matches("<script").count()
        );
    }

    #[test]
    fn text_cannot_end_the_data_script_early() {
        let cloud = helix(10);
        let mut page = page(&cloud, &cloud, RigidTransform::identity());
        page.title = "</script><script>alert(1)</script>".to_string();
        let html = page.to_html().unwrap();
        assert_eq!(data_of(&html)["title"], page.title);
        assert_eq!(
            html.matches("</script>").count(),
            TEMPLATE.matches("</script>").count()
        );
    }

    #[test]
    fn the_refinements_distance_scales_with_the_pair() {
        let unit = RefineConfig::default().finest_distance();
        let shape = PointCloud::new(
            (0..100)
                .map(|i| {
                    let a = i as f64 * 0.3;
                    Point3::new(a.cos(), a.sin(), (i as f64 / 50.0) - 1.0) * 0.7
                })
                .collect(),
        );
        // A unit-sphere shape is in the frame already; a copy 1,000 times the size is scaled.
        assert_eq!(
            InlierDistance::of_refinement(&shape, &shape, &FRAME).distance,
            unit
        );
        let big = PointCloud::new(shape.points.iter().map(|p| p * 1000.0).collect());
        let d = InlierDistance::of_refinement(&big, &big, &FRAME);
        let scale = Normalisation::of_pair(&big, &big, &FRAME).scale;
        assert!(scale > 500.0);
        assert!((d.distance - unit * scale).abs() < 1e-9, "{d:?}");
        assert!(d.why.contains("scale"), "{}", d.why);
    }
}
