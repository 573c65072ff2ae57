//! `--html FILE` of `rgm render` and `rgm register`: the registration as a page that turns in a
//! browser ([`rgm_viz::html`]).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use rgm_geom::{PointCloud, RigidTransform};
use rgm_model::policy::TUNED;
use rgm_viz::html::{InlierDistance, Page, ResultNotes, DEFAULT_POINT_BUDGET};

/// `--html FILE` and `--html-points N`.
#[derive(clap::Args, Debug)]
pub struct HtmlArgs {
    /// Also write the registration as one self-contained HTML page (no network needed to view
    /// it): the clouds before and after (a toggle), the source coloured by whether each point
    /// lies within the refinement's inlier distance of the target, RGM's correspondences when
    /// they are the result's (`--method rgm --no-refine`), the transform and the candidates
    /// with their scores. Drag to turn, right-drag to pan, wheel to zoom; a point-size slider.
    #[arg(long, value_name = "FILE")]
    pub html: Option<PathBuf>,
    /// Most points the page shows, both clouds together; larger clouds are thinned by a fixed
    /// stride for display (the page says so), so a 1M-point scan stays smooth to turn.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_POINT_BUDGET,
          value_parser = point_budget, requires = "html")]
    pub html_points: usize,
}

/// `--html-points N`: a whole number of at least 2 (one point of each cloud).
fn point_budget(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(n) if n >= 2 => Ok(n),
        Ok(n) => Err(format!(
            "{n} is too few: the page shows at least one point of each cloud"
        )),
        Err(err) => Err(format!("{text:?} is not a whole number of points: {err}")),
    }
}

impl HtmlArgs {
    /// Refuses a `--html` path that is not a writable `.html` file, before any work.
    pub fn check(&self) -> Result<()> {
        let Some(path) = &self.html else {
            return Ok(());
        };
        let html = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("html") || e.eq_ignore_ascii_case("htm"));
        if !html {
            bail!(
                "--html {}: the page is HTML; give the file an .html name",
                path.display()
            );
        }
        crate::files::check_writable(path)
    }

    /// Writes the page of `transform` on the pair read from `paths`, described by `notes`, when
    /// `--html` asks for one.
    pub fn write(
        &self,
        (source, target): (&PointCloud, &PointCloud),
        (source_path, target_path): (&Path, &Path),
        t_target_source: RigidTransform,
        notes: ResultNotes,
    ) -> Result<()> {
        let Some(path) = &self.html else {
            return Ok(());
        };
        let name = |p: &Path| {
            p.file_name()
                .unwrap_or(p.as_os_str())
                .to_string_lossy()
                .into_owned()
        };
        let page = Page {
            title: format!("{} → {}", name(source_path), name(target_path)),
            source,
            target,
            t_target_source,
            inlier_distance: InlierDistance::of_refinement(source, target, &TUNED.frame),
            notes,
            point_budget: self.html_points,
        };
        let html = page
            .to_html()
            .with_context(|| format!("making the page {}", path.display()))?;
        crate::files::write_text(path, &html)?;
        eprintln!(
            "rgm: wrote {} ({} KB)",
            path.display(),
            html.len().div_ceil(1000)
        );
        Ok(())
    }
}
