//! rgm-viz — figures of a registration, as RGB pictures written to PNG:
//! - [`registration_figure`]: source and target from a fixed oblique view (orthographic), before
//!   the transform (left) and after it (right), the source orange, the target blue;
//! - [`correspondence_figure`]: the hard correspondence matrix in blocks, black where the
//!   correspondences are correct and red where they are not (the paper's Figure 5).
//!
//! - [`html`]: the same registration as one self-contained HTML page that turns in a browser
//!   (WebGL, rgm's own small renderer), with the source coloured by its distance to the target
//!   and the result's candidates;
//! - [`model`]: many scans merged into one frame as such a page, each point coloured by its scan.
//!
//! Layering rule: builds on rgm-geom (clouds, transforms, kNN, the unit-sphere frame),
//! rgm-registration (the [`rgm_registration::Registration`] a page describes, the scores and
//! refinement it shows) and rgm-data (correspondences) only, so anyone holding clouds and a transform
//! can draw them, without BLAS or the network; the `rgm render` and `rgm register` commands and
//! the Python package (`to_html`) are its users.

use std::path::{Path, PathBuf};

pub mod html;
pub mod model;

use rgm_data::Correspondence;
use rgm_geom::{Point3, PointCloud, RigidTransform, Vector3};

/// One pixel's colour.
pub type Rgb = [u8; 3];

pub const WHITE: Rgb = [255, 255, 255];
pub const BLACK: Rgb = [0, 0, 0];
pub const RED: Rgb = [220, 30, 30];
/// A block holding ground-truth correspondences that the method did not find.
pub const LIGHT_GREY: Rgb = [215, 215, 215];
/// The line between the two panels of a registration figure.
pub const MID_GREY: Rgb = [160, 160, 160];
/// The source cloud.
pub const SOURCE: Rgb = [240, 130, 20];
/// The target cloud.
pub const TARGET: Rgb = [30, 90, 220];

/// Why a figure could not be made or written.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A figure of nothing.
    #[error("render: {op} needs at least one point, got none")]
    Empty { op: &'static str },
    /// An argument outside what the figure can show.
    #[error("render: {op}: {why}")]
    Invalid { op: &'static str, why: String },
    /// A correspondence names a point the cloud does not have.
    #[error("render: {op}: correspondence ({source_index}, {target_index}) is outside a {n_source}×{n_target} matrix")]
    OutOfRange {
        op: &'static str,
        source_index: usize,
        target_index: usize,
        n_source: usize,
        n_target: usize,
    },
    /// The picture could not be encoded (a zero-sized one).
    #[error("render: encoding a {width}×{height} PNG: {source}")]
    Encode {
        width: usize,
        height: usize,
        source: png::EncodingError,
    },
    /// The PNG could not be written.
    #[error("render: writing {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
}

pub type Result<T> = std::result::Result<T, RenderError>;

/// An RGB picture.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pixels: Vec<Rgb>, // (height, width)
}

impl Image {
    /// A `width` × `height` picture filled with `background`.
    pub fn new(width: usize, height: usize, background: Rgb) -> Self {
        Self {
            width,
            height,
            pixels: vec![background; width * height],
        }
    }

    /// The colour at column `x`, row `y` (row 0 at the top); `None` outside the picture.
    pub fn pixel(&self, x: usize, y: usize) -> Option<Rgb> {
        (x < self.width && y < self.height).then(|| self.pixels[y * self.width + x])
    }

    /// Paints the rectangle of `w` × `h` pixels whose top-left corner is (`x`, `y`); the part
    /// outside the picture is dropped.
    pub fn fill_rect(&mut self, x: usize, y: usize, w: usize, h: usize, colour: Rgb) {
        for row in y..(y + h).min(self.height) {
            let start = row * self.width;
            let line = &mut self.pixels[start + x.min(self.width)..start + (x + w).min(self.width)];
            line.fill(colour);
        }
    }

    /// The picture as a PNG file's bytes (8-bit RGB).
    pub fn to_png(&self) -> Result<Vec<u8>> {
        let mut bytes = Vec::new();
        let mut encoder = png::Encoder::new(&mut bytes, self.width as u32, self.height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let data: Vec<u8> = self.pixels.iter().flatten().copied().collect(); // (height, width, 3)
        encoder
            .write_header()
            .and_then(|mut writer| writer.write_image_data(&data))
            .map_err(|source| RenderError::Encode {
                width: self.width,
                height: self.height,
                source,
            })?;
        Ok(bytes)
    }

    /// Writes the picture as a PNG file.
    pub fn write_png(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let png = self.to_png()?;
        rgm_data::io::output::write_file(path, |out| out.write_all(&png)).map_err(|source| {
            RenderError::Write {
                path: path.to_path_buf(),
                source,
            }
        })
    }
}

/// An orthographic camera looking at the origin from a direction given by its azimuth (about z,
/// from +x) and elevation (above the x-y plane), z pointing up in the picture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    pub azimuth_deg: f64,
    pub elevation_deg: f64,
}

impl Default for View {
    /// An oblique view that shows all three axes.
    fn default() -> Self {
        Self {
            azimuth_deg: 45.0,
            elevation_deg: 30.0,
        }
    }
}

impl View {
    /// `p` on the picture plane: (right, up, depth), depth growing towards the camera.
    pub fn project(&self, p: &Point3<f64>) -> [f64; 3] {
        let (sa, ca) = self.azimuth_deg.to_radians().sin_cos();
        let (se, ce) = self.elevation_deg.to_radians().sin_cos();
        let towards_camera = Vector3::new(ce * ca, ce * sa, se);
        let right = Vector3::new(-sa, ca, 0.0);
        let up = towards_camera.cross(&right);
        let v = p.coords;
        [v.dot(&right), v.dot(&up), v.dot(&towards_camera)]
    }
}

/// Square panels side by side that share one scale, so that every cloud drawn keeps its size
/// and position from panel to panel.
#[derive(Clone, Debug, PartialEq)]
pub struct Panels {
    pub view: View,
    /// Side of one panel, in pixels.
    pub size: usize,
    /// Number of panels.
    pub count: usize,
    /// Pixels per unit of length.
    scale: f64,
    /// The picture-plane point drawn at each panel's centre.
    centre: [f64; 2],
}

/// Side of the square drawn for one point, in pixels.
const POINT_SIZE: usize = 3;

impl Panels {
    /// `count` panels of `size` pixels that fit every point of `clouds` with a margin.
    pub fn fit(view: View, size: usize, count: usize, clouds: &[&PointCloud]) -> Result<Self> {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in clouds.iter().flat_map(|c| &c.points) {
            let q = view.project(p);
            for a in 0..2 {
                lo[a] = lo[a].min(q[a]);
                hi[a] = hi[a].max(q[a]);
            }
        }
        if lo[0] > hi[0] {
            return Err(RenderError::Empty { op: "Panels::fit" });
        }
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-9);
        Ok(Self {
            view,
            size,
            count,
            scale: 0.9 * size.saturating_sub(2 * POINT_SIZE) as f64 / extent,
            centre: [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0],
        })
    }

    /// An empty picture with the panels separated by a line.
    pub fn canvas(&self) -> Image {
        let mut image = Image::new(self.size * self.count, self.size, WHITE);
        for panel in 1..self.count {
            image.fill_rect(panel * self.size, 0, 1, self.size, MID_GREY);
        }
        image
    }

    /// The pixel (column, row) where `p` is drawn in panel `panel`.
    pub fn pixel_of(&self, panel: usize, p: &Point3<f64>) -> (usize, usize) {
        let q = self.view.project(p);
        let half = self.size as f64 / 2.0;
        let x = half + (q[0] - self.centre[0]) * self.scale;
        let y = half - (q[1] - self.centre[1]) * self.scale;
        let clamp = |v: f64| v.round().clamp(0.0, (self.size - 1) as f64) as usize;
        (panel * self.size + clamp(x), clamp(y))
    }

    /// Draws the clouds of `layers` into panel `panel`, far points first so that near ones
    /// cover them, whichever cloud they belong to.
    pub fn draw(&self, image: &mut Image, panel: usize, layers: &[(&PointCloud, Rgb)]) {
        let mut dots: Vec<(f64, Point3<f64>, Rgb)> = layers
            .iter()
            .flat_map(|(cloud, colour)| {
                cloud
                    .points
                    .iter()
                    .map(|p| (self.view.project(p)[2], *p, *colour))
            })
            .collect();
        dots.sort_by(|a, b| a.0.total_cmp(&b.0));
        let half = POINT_SIZE / 2;
        for (_, p, colour) in dots {
            let (x, y) = self.pixel_of(panel, &p);
            image.fill_rect(
                x.saturating_sub(half),
                y.saturating_sub(half),
                POINT_SIZE,
                POINT_SIZE,
                colour,
            );
        }
    }
}

/// Side of one panel of [`registration_figure`], in pixels.
pub const PANEL_SIZE: usize = 400;

/// Source (orange) and target (blue) before registration (left) and with the source moved by
/// `t_target_source` (right), from the default [`View`].
pub fn registration_figure(
    source: &PointCloud,
    target: &PointCloud,
    t_target_source: &RigidTransform,
) -> Result<Image> {
    let moved = source.transformed(t_target_source);
    let panels = Panels::fit(View::default(), PANEL_SIZE, 2, &[source, &moved, target])?;
    let mut image = panels.canvas();
    panels.draw(&mut image, 0, &[(source, SOURCE), (target, TARGET)]);
    panels.draw(&mut image, 1, &[(&moved, SOURCE), (target, TARGET)]);
    Ok(image)
}

/// Side of one block of [`correspondence_figure`], in pixels.
pub const BLOCK_SIZE: usize = 10;

/// Share of `predicted` (source index, target index) pairs that are ground-truth
/// correspondences; 0 when nothing is predicted.
pub fn correct_fraction(truth: &Correspondence, predicted: &[(usize, usize)]) -> f64 {
    let partner = truth.source_to_target();
    let correct = predicted
        .iter()
        .filter(|&&(i, j)| partner.get(i).copied().flatten() == Some(j))
        .count();
    correct as f64 / predicted.len().max(1) as f64
}

/// The N × M hard correspondence matrix of `predicted`, drawn in `blocks` × `blocks` blocks
/// (fewer when the matrix is smaller), the way the paper's Figure 5 sub-samples a 717 × 717
/// matrix to 36 × 36.
///
/// Rows are the source points that have a ground-truth partner (by index), then the others;
/// columns are those partners in the same order, then the other target points, so the
/// ground truth lies on the diagonal. A block is black when most of its predicted
/// correspondences are correct, red when most are not, light grey when it holds ground-truth
/// correspondences but no prediction, white otherwise.
pub fn correspondence_figure(
    truth: &Correspondence,
    predicted: &[(usize, usize)],
    blocks: usize,
) -> Result<Image> {
    let (n, m) = (truth.n_source, truth.n_target);
    if n == 0 || m == 0 || blocks == 0 {
        return Err(RenderError::Empty {
            op: "correspondence_figure",
        });
    }
    let row_of = order_by_truth(n, truth.pairs.iter().map(|&(i, _)| i)); // (N,)
    let col_of = order_by_truth(m, truth.pairs.iter().map(|&(_, j)| j)); // (M,)
    let (rows_per, cols_per) = (n.div_ceil(blocks), m.div_ceil(blocks));
    let (row_blocks, col_blocks) = (n.div_ceil(rows_per), m.div_ceil(cols_per));
    let block = |i: usize, j: usize| (row_of[i] / rows_per) * col_blocks + col_of[j] / cols_per;
    let mut in_truth = vec![false; row_blocks * col_blocks]; // (row blocks, column blocks)
    for &(i, j) in &truth.pairs {
        in_truth[block(i, j)] = true;
    }
    let partner = truth.source_to_target();
    let mut correct = vec![0usize; row_blocks * col_blocks]; // (row blocks, column blocks)
    let mut wrong = vec![0usize; row_blocks * col_blocks]; // (row blocks, column blocks)
    for &(i, j) in predicted {
        if i >= n || j >= m {
            return Err(RenderError::OutOfRange {
                op: "correspondence_figure",
                source_index: i,
                target_index: j,
                n_source: n,
                n_target: m,
            });
        }
        if partner[i] == Some(j) {
            correct[block(i, j)] += 1;
        } else {
            wrong[block(i, j)] += 1;
        }
    }
    let mut image = Image::new(col_blocks * BLOCK_SIZE, row_blocks * BLOCK_SIZE, WHITE);
    for b in 0..row_blocks * col_blocks {
        let colour = match (correct[b], wrong[b]) {
            (0, 0) if in_truth[b] => LIGHT_GREY,
            (0, 0) => continue,
            (c, w) if c >= w => BLACK,
            _ => RED,
        };
        let (r, c) = (b / col_blocks, b % col_blocks);
        image.fill_rect(
            c * BLOCK_SIZE,
            r * BLOCK_SIZE,
            BLOCK_SIZE,
            BLOCK_SIZE,
            colour,
        );
    }
    Ok(image)
}

/// The position of each of `len` indices when the `first` ones (in that order) come first and
/// the rest follow by index.
fn order_by_truth(len: usize, first: impl Iterator<Item = usize>) -> Vec<usize> {
    let mut position = vec![usize::MAX; len]; // (len,)
    let mut next = 0;
    for i in first {
        position[i] = next;
        next += 1;
    }
    for p in position.iter_mut().filter(|p| **p == usize::MAX) {
        *p = next;
        next += 1;
    }
    position
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(points: &[[f64; 3]]) -> PointCloud {
        PointCloud::new(points.iter().map(|p| Point3::from(*p)).collect())
    }

    #[test]
    fn the_view_keeps_lengths_and_puts_z_up() {
        let view = View::default();
        let [x, y, d] = view.project(&Point3::new(0.3, -0.4, 1.2));
        assert!(((x * x + y * y + d * d).sqrt() - 1.3).abs() < 1e-12);
        // z (up in the world) goes up on the picture, by cos(elevation).
        let up = view.project(&Point3::new(0.0, 0.0, 1.0));
        assert!(up[0].abs() < 1e-12);
        assert!((up[1] - 30f64.to_radians().cos()).abs() < 1e-12);
        // The camera sits at azimuth 45°: the point (1, 1, 0) faces it and (−1, 1, 0) is to the
        // right of its centre line.
        assert!(view.project(&Point3::new(1.0, 1.0, 0.0))[2] > 0.0);
        assert!(view.project(&Point3::new(-1.0, 1.0, 0.0))[0] > 0.0);
    }

    #[test]
    fn points_are_drawn_where_they_project_in_both_panels() {
        // Two points on the line through the view's centre: the target at the origin, the
        // source on the far side of the picture. The transform moves the source onto the target.
        let source = cloud(&[[0.0, 0.0, 1.0]]);
        let target = cloud(&[[0.0, 0.0, -1.0]]);
        let shift =
            RigidTransform::new(rgm_geom::Matrix3::identity(), Vector3::new(0.0, 0.0, -2.0));
        let image = registration_figure(&source, &target, &shift).unwrap();
        assert_eq!((image.width, image.height), (2 * PANEL_SIZE, PANEL_SIZE));
        let panels = Panels::fit(View::default(), PANEL_SIZE, 2, &[&source, &target]).unwrap();
        let (sx, sy) = panels.pixel_of(0, &source.points[0]);
        let (tx, ty) = panels.pixel_of(0, &target.points[0]);
        // The source is above the target and both sit on the vertical centre line.
        assert_eq!(sx, PANEL_SIZE / 2);
        assert_eq!(tx, PANEL_SIZE / 2);
        assert!(sy < ty);
        assert_eq!(image.pixel(sx, sy), Some(SOURCE));
        assert_eq!(image.pixel(tx, ty), Some(TARGET));
        // After the transform the source lies exactly on the target: at equal depth the later
        // layer (the target) is drawn on top, and the source's old place is empty.
        let (ax, ay) = panels.pixel_of(1, &target.points[0]);
        assert_eq!(image.pixel(ax, ay), Some(TARGET));
        let (ox, oy) = panels.pixel_of(1, &source.points[0]);
        assert_eq!(image.pixel(ox, oy), Some(WHITE));
        // The separator between the panels.
        assert_eq!(image.pixel(PANEL_SIZE, 0), Some(MID_GREY));
    }

    #[test]
    fn nearer_points_cover_farther_ones() {
        // Two points on the camera's line of sight through the origin: the nearer one (blue)
        // must be visible whatever order the layers are given in.
        let view = View::default();
        let towards_camera = {
            let (sa, ca) = 45f64.to_radians().sin_cos();
            let (se, ce) = 30f64.to_radians().sin_cos();
            Vector3::new(ce * ca, ce * sa, se)
        };
        let far = cloud(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]);
        let near = PointCloud::new(vec![Point3::from(towards_camera * 0.5)]);
        let panels = Panels::fit(view, 100, 1, &[&far, &near]).unwrap();
        let mut image = panels.canvas();
        panels.draw(&mut image, 0, &[(&near, TARGET), (&far, SOURCE)]);
        let (x, y) = panels.pixel_of(0, &near.points[0]);
        assert_eq!(panels.pixel_of(0, &far.points[0]), (x, y));
        assert_eq!(image.pixel(x, y), Some(TARGET));
    }

    #[test]
    fn an_empty_figure_is_an_error() {
        let empty = PointCloud::new(Vec::new());
        let err = registration_figure(&empty, &empty, &RigidTransform::identity()).unwrap_err();
        assert!(matches!(err, RenderError::Empty { .. }));
    }

    #[test]
    fn the_matrix_colours_correct_and_wrong_blocks() {
        // Ground truth: source 0 ↔ target 2, source 2 ↔ target 0; source 1 and target 1 are
        // outliers. Rows in order 0, 2, 1; columns 2, 0, 1.
        let truth = Correspondence::new(3, 3, vec![(0, 2), (2, 0)]).unwrap();
        let predicted = [(0, 2), (1, 0)];
        let image = correspondence_figure(&truth, &predicted, 3).unwrap();
        assert_eq!(
            (image.width, image.height),
            (3 * BLOCK_SIZE, 3 * BLOCK_SIZE)
        );
        let at = |row: usize, col: usize| {
            image
                .pixel(
                    col * BLOCK_SIZE + BLOCK_SIZE / 2,
                    row * BLOCK_SIZE + BLOCK_SIZE / 2,
                )
                .unwrap()
        };
        assert_eq!(at(0, 0), BLACK); // (0, 2): correct, on the diagonal
        assert_eq!(at(1, 1), LIGHT_GREY); // (2, 0): ground truth, missed
        assert_eq!(at(2, 1), RED); // (1, 0): an outlier matched
        assert_eq!(at(2, 2), WHITE);
        assert_eq!(at(0, 1), WHITE);
        assert_eq!(correct_fraction(&truth, &predicted), 0.5);
    }

    #[test]
    fn the_matrix_is_sub_sampled_into_blocks() {
        // 717 × 717 identity ground truth into 36 blocks of 20 rows (the last holds 17).
        let pairs: Vec<_> = (0..717).map(|i| (i, i)).collect();
        let truth = Correspondence::new(717, 717, pairs.clone()).unwrap();
        let image = correspondence_figure(&truth, &pairs, 36).unwrap();
        assert_eq!(
            (image.width, image.height),
            (36 * BLOCK_SIZE, 36 * BLOCK_SIZE)
        );
        for b in 0..36 {
            let centre = b * BLOCK_SIZE + BLOCK_SIZE / 2;
            assert_eq!(image.pixel(centre, centre), Some(BLACK));
        }
        assert_eq!(image.pixel(BLOCK_SIZE + 5, 5), Some(WHITE));
        // One wrong match per block cannot outvote twenty correct ones.
        let mut noisy = pairs.clone();
        noisy[0] = (0, 1);
        let image = correspondence_figure(&truth, &noisy, 36).unwrap();
        assert_eq!(image.pixel(5, 5), Some(BLACK));
    }

    #[test]
    fn a_zero_sized_picture_is_an_error_not_a_panic() {
        let err = Image::new(0, 3, WHITE).to_png().unwrap_err();
        assert!(err.to_string().contains("0×3"), "{err}");
    }

    #[test]
    fn a_correspondence_outside_the_matrix_is_an_error() {
        let truth = Correspondence::new(2, 2, vec![(0, 0)]).unwrap();
        let err = correspondence_figure(&truth, &[(0, 5)], 2).unwrap_err();
        assert!(err.to_string().contains("(0, 5)"), "{err}");
    }

    #[test]
    fn the_png_decodes_to_the_same_pixels() {
        let mut image = Image::new(4, 3, WHITE);
        image.fill_rect(1, 1, 2, 5, RED);
        let bytes = image.to_png().unwrap();
        let decoder = png::Decoder::new(bytes.as_slice());
        let mut reader = decoder.read_info().unwrap();
        let mut data = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut data).unwrap();
        assert_eq!((info.width, info.height), (4, 3));
        assert_eq!(&data[..3], &WHITE);
        let at = |x: usize, y: usize| &data[3 * (y * 4 + x)..3 * (y * 4 + x) + 3];
        assert_eq!(at(1, 1), &RED);
        assert_eq!(at(2, 2), &RED);
        assert_eq!(at(3, 2), &WHITE);
    }
}
