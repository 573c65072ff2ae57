//! Many scans put into one frame (`rgm merge`) as one self-contained HTML page: the merged model,
//! each point coloured by the scan it came from, and a toggle to the scans as they were given
//! (each in its own frame), so that a wrong placement shows as one colour out of place. The same
//! viewer and page as [`crate::html`]'s, in its model mode.

use rgm_geom::PointCloud;
use serde_json::json;

use crate::html::{base64, page_with, stride_indices, PageFrame};
use crate::{RenderError, Result};

/// Everything a model page shows.
#[derive(Clone, Debug)]
pub struct ModelPage<'a> {
    /// What the page is called.
    pub title: String,
    /// Each scan's name (its file) and its points in its own frame, in the order given.
    pub scans: Vec<(String, &'a PointCloud)>,
    /// The merged model (thinned), in the model's frame.
    pub model: &'a PointCloud,
    /// The scan each model point came from: an index into `scans`. // (model points,)
    pub labels: &'a [u32],
    /// Most points shown: half for the model, half for the scans as given (at least 2).
    pub point_budget: usize,
}

impl ModelPage<'_> {
    /// The page as one HTML document.
    pub fn to_html(&self) -> Result<String> {
        let op = "model page";
        if self.model.is_empty() || self.scans.is_empty() {
            return Err(RenderError::Empty { op });
        }
        let invalid = |why: String| RenderError::Invalid { op, why };
        if self.point_budget < 2 {
            return Err(invalid(format!(
                "the point budget must be at least 2, got {}",
                self.point_budget
            )));
        }
        // The page carries each point's scan as a u16.
        if self.scans.len() > u16::MAX as usize {
            return Err(invalid(format!(
                "{} scans: a page shows at most {}",
                self.scans.len(),
                u16::MAX
            )));
        }
        if self.labels.len() != self.model.len() {
            return Err(invalid(format!(
                "{} labels for {} model points",
                self.labels.len(),
                self.model.len()
            )));
        }
        if let Some(&label) = self
            .labels
            .iter()
            .find(|&&l| l as usize >= self.scans.len())
        {
            return Err(invalid(format!(
                "a model point is labelled scan {label}, but there are {} scans",
                self.scans.len()
            )));
        }
        let clouds: Vec<&PointCloud> = std::iter::once(self.model)
            .chain(self.scans.iter().map(|(_, cloud)| *cloud))
            .collect();
        if clouds
            .iter()
            .any(|c| c.points.iter().any(|p| p.iter().any(|x| !x.is_finite())))
        {
            return Err(invalid(
                "a point has a coordinate that is not finite".into(),
            ));
        }
        let half = self.point_budget / 2;
        let model_kept = stride_indices(self.model.len(), half);
        let model = self.model.select(&model_kept);
        let labels: Vec<u32> = model_kept.iter().map(|&i| self.labels[i]).collect(); // (shown,)
                                                                                     // The scans as given share their half of the budget by their sizes.
        let total: usize = self.scans.iter().map(|(_, c)| c.len()).sum();
        let given_each: Vec<PointCloud> = self
            .scans
            .iter()
            .map(|(_, cloud)| {
                let keep = (half as f64 * cloud.len() as f64 / total.max(1) as f64).ceil();
                cloud.select(&stride_indices(cloud.len(), (keep as usize).max(1)))
            })
            .collect();
        let given = PointCloud::new(
            given_each
                .iter()
                .flat_map(|c| c.points.iter().copied())
                .collect(),
        );
        let given_labels: Vec<u32> = given_each
            .iter()
            .enumerate()
            .flat_map(|(s, c)| std::iter::repeat_n(s as u32, c.len()))
            .collect(); // (given shown,)
        let frame = PageFrame::of(&clouds);
        let mut in_model = vec![0usize; self.scans.len()];
        for &l in self.labels {
            in_model[l as usize] += 1;
        }
        let scans: Vec<_> = self
            .scans
            .iter()
            .enumerate()
            .map(|(s, (name, cloud))| {
                json!({"name": name, "points": cloud.len(), "inModel": in_model[s]})
            })
            .collect();
        let label_bytes = |labels: &[u32]| -> Vec<u8> {
            labels
                .iter()
                .flat_map(|&l| (l as u16).to_le_bytes())
                .collect()
        };
        let data = json!({
            "title": self.title,
            "budget": self.point_budget,
            "model": {
                "scans": scans,
                "points": self.model.len(),
                "shown": model.len(),
                "xyz": base64(&frame.f32_bytes(&model)),
                "scan": base64(&label_bytes(&labels)),
                "given": {
                    "shown": given.len(),
                    "xyz": base64(&frame.f32_bytes(&given)),
                    "scan": base64(&label_bytes(&given_labels)),
                },
            },
        });
        Ok(page_with(&data))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::html::tests::{data_of, points_of, unbase64};
    use rgm_geom::Point3;

    fn line(n: usize, y: f64) -> PointCloud {
        PointCloud::new((0..n).map(|i| Point3::new(i as f64, y, 0.0)).collect())
    }

    #[test]
    fn the_page_carries_each_point_with_its_scan_in_both_states() {
        let (a, b) = (line(30, 0.0), line(10, 5.0));
        let model = line(20, 1.0);
        let labels: Vec<u32> = (0..20).map(|i| u32::from(i >= 15)).collect();
        let page = ModelPage {
            title: "two scans".into(),
            scans: vec![("a.ply".into(), &a), ("b.ply".into(), &b)],
            model: &model,
            labels: &labels,
            point_budget: 20,
        };
        let data = data_of(&page.to_html().unwrap());
        let m = &data["model"];
        assert_eq!(m["points"], 20);
        assert_eq!(m["shown"], 10);
        assert_eq!(m["scans"][0]["name"], "a.ply");
        assert_eq!(m["scans"][0]["inModel"], 15);
        assert_eq!(m["scans"][1]["inModel"], 5);
        let shown_labels = |field: &serde_json::Value| -> Vec<u16> {
            unbase64(field.as_str().unwrap())
                .chunks(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .collect()
        };
        // Every second model point (a stride of 2), with its own scan.
        assert_eq!(
            shown_labels(&m["scan"]),
            [0, 0, 0, 0, 0, 0, 0, 0, 1, 1].to_vec()
        );
        assert_eq!(points_of(&m["xyz"]).len(), 10);
        // The scans as given: 10 points shared 30 : 10, so 8 of a (7.5 up) and 3 of b (2.5 up).
        let given = &m["given"];
        assert_eq!(given["shown"], 11);
        assert_eq!(
            shown_labels(&given["scan"]),
            [0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1].to_vec()
        );
        // One frame for both states: b's points (y = 5) lie at the top, a's at the bottom.
        let rows = points_of(&given["xyz"]);
        assert_eq!(rows.len(), 11);
        assert!(rows[..8].iter().all(|r| r[1] < rows[8][1]));
    }

    #[test]
    fn labels_that_do_not_fit_the_scans_are_refused() {
        let a = line(5, 0.0);
        let model = line(5, 0.0);
        let page = |labels: &'static [u32]| ModelPage {
            title: "x".into(),
            scans: vec![("a.ply".into(), &a)],
            model: &model,
            labels,
            point_budget: 100,
        };
        let error = page(&[0, 0, 0, 0, 1]).to_html().unwrap_err().to_string();
        assert!(
            error.contains("labelled scan 1, but there are 1 scans"),
            "{error}"
        );
        let error = page(&[0, 0]).to_html().unwrap_err().to_string();
        assert!(error.contains("2 labels for 5 model points"), "{error}");
    }
}
