//! The local feature extractor (spec §2.1), DGCNN style: four shared 1×1 convolutions on the
//! (x_n, x_i) rows of every point's K neighbours, each followed by batch norm, ReLU and a max
//! over K; the four maxima concatenated are the node features, and a fifth 1×1 convolution with
//! batch norm and ReLU on them gives the edge features. Output: node ⊕ edge per point.

use super::{shaped, zeroed, Element, Mode, Result};
use ndarray::{s, Array2, ArrayView2, ArrayViewMut2, Axis};
use rgm_geom::{knn_graph, Point3};
use rgm_nn::init::Init;
use rgm_nn::param::{join_name, ParamView, ParamViewMut};
use rgm_nn::{
    edge_features_forward, max_k_backward, max_k_forward, relu_backward, relu_forward, BatchNorm,
    BatchNormCache, Compute, Linear, MaxKCache, Parameters,
};
use serde::{Deserialize, Serialize};

/// Which statistics batch norm normalises with at test time ([`Mode::Eval`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum TestStatistics {
    /// The running statistics gathered in training (spec §3, PyTorch's `eval()`).
    #[default]
    Running,
    /// Each cloud's own statistics, as in training, leaving the running ones untouched. rgm
    /// trains one cloud per batch-norm batch, so a network trained that way sees at test time
    /// exactly what it saw in training (measured in docs/training/README.md).
    Cloud,
}

/// `pointfeaturer.conv{1..5}` (no bias) and `pointfeaturer.bn{1..5}`.
#[derive(Clone, Debug)]
pub struct PointFeaturer<T: Element> {
    pub k: usize,
    pub convs: Vec<Linear<T>>, // 5: (C_1, 6), (C_2, C_1), (C_3, C_2), (C_4, C_3), (E, ΣC)
    pub bns: Vec<BatchNorm<T>>, // 5: C_1 .. C_4, E
    /// Batch-norm statistics in [`Mode::Eval`].
    pub test_statistics: TestStatistics,
}

/// One cloud's pass through the extractor: what the backward needs, and its scratch.
#[derive(Clone, Debug, Default)]
pub struct FeaturerCache<T> {
    idx: Array2<usize>,         // (N, K) neighbours, self first
    act: Vec<Array2<T>>,        // 5: the edge rows (N*K, 6), then each ReLU output (N*K, C_i)
    pre: Vec<Array2<T>>,        // 5: each convolution's output, (N*K, C_i) and (N, E)
    normed: Vec<Array2<T>>,     // 5: each batch norm's output, same shapes
    bn: Vec<BatchNormCache<T>>, // 5
    max_k: Vec<MaxKCache>,      // 4
    /// (N, ΣC + E) the output: node features (the four maxima) then edge features.
    pub features: Array2<T>,
    dpre: Vec<Array2<T>>,    // 5, as pre
    dnormed: Vec<Array2<T>>, // 5, as normed
    dnode: Array2<T>,        // (N, ΣC)
    dmax: Array2<T>,         // (N, C_i) one block of dnode through its ReLU
}

impl<T: Element> PointFeaturer<T> {
    /// PyTorch-initialised convolutions and fresh batch norms.
    pub fn new(k: usize, widths: [usize; 4], edge: usize, init: &mut impl Init) -> Self {
        let ins = [6, widths[0], widths[1], widths[2], widths.iter().sum()];
        let outs = [widths[0], widths[1], widths[2], widths[3], edge];
        Self {
            k,
            convs: ins
                .iter()
                .zip(outs)
                .map(|(&i, o)| Linear::new(i, o, false, init))
                .collect(),
            bns: outs.iter().map(|&o| BatchNorm::new(o)).collect(),
            test_statistics: TestStatistics::Running,
        }
    }

    /// Node-feature width ΣC.
    fn node_width(&self) -> usize {
        self.convs[4].c_in()
    }

    /// Runs one cloud `points` (N, 3) into `cache.features` (N, ΣC + E). Training mode
    /// normalises with this cloud's statistics and updates the running ones; evaluation mode
    /// is [`PointFeaturer::forward_eval`].
    pub fn forward(
        &mut self,
        points: ArrayView2<'_, T>,
        mode: Mode,
        cache: &mut FeaturerCache<T>,
        compute: Compute,
    ) -> Result<()> {
        match mode {
            Mode::Train => {
                let bns = &mut self.bns;
                Self::run(
                    self.k,
                    &self.convs,
                    points,
                    cache,
                    false,
                    |i, out, inp, bn| bns[i].forward(out, inp, true, bn),
                    compute,
                )
            }
            Mode::Eval => self.forward_eval(points, cache, compute),
        }
    }

    /// The evaluation-mode pass of [`PointFeaturer::forward`], which changes nothing in the
    /// extractor, so that clouds can run side by side: batch norm with
    /// [`PointFeaturer::test_statistics`].
    pub fn forward_eval(
        &self,
        points: ArrayView2<'_, T>,
        cache: &mut FeaturerCache<T>,
        compute: Compute,
    ) -> Result<()> {
        let cloud_statistics = self.test_statistics == TestStatistics::Cloud;
        Self::run(
            self.k,
            &self.convs,
            points,
            cache,
            true,
            |i, out, inp, bn| self.bns[i].normalise(out, inp, cloud_statistics, bn),
            compute,
        )
    }

    /// The pass of [`PointFeaturer::forward`] with `normalise(i, out, inp, cache)` as batch
    /// norm `i`; with `side_by_side` (no backward follows) the convolutions and ReLUs on two
    /// halves of the rows at once.
    fn run(
        k: usize,
        convs: &[Linear<T>],
        points: ArrayView2<'_, T>,
        cache: &mut FeaturerCache<T>,
        side_by_side: bool,
        mut normalise: impl FnMut(
            usize,
            ArrayViewMut2<'_, T>,
            ArrayView2<'_, T>,
            &mut BatchNormCache<T>,
        ) -> rgm_nn::Result<()>,
        compute: Compute,
    ) -> Result<()> {
        let (n, node) = (points.nrows(), convs[4].c_in());
        let cloud: Vec<Point3<f64>> = points
            .rows()
            .into_iter()
            .map(|p| Point3::new(p[0].to_f64(), p[1].to_f64(), p[2].to_f64()))
            .collect();
        cache.idx = Array2::from_shape_vec((n, k), knn_graph(&cloud, k)?)
            .expect("knn_graph returns N*K indices");
        let rows = |i: usize| if i < 4 { n * k } else { n };
        let widths: Vec<usize> = convs.iter().map(|c| c.c_out()).collect();
        cache.act.resize_with(5, Default::default);
        cache.pre.resize_with(5, Default::default);
        cache.normed.resize_with(5, Default::default);
        cache.bn.resize_with(5, Default::default);
        cache.max_k.resize_with(4, Default::default);
        shaped(&mut cache.act[0], (n * k, 6));
        edge_features_forward(cache.act[0].view_mut(), points, cache.idx.view())?;
        shaped(&mut cache.features, (n, node + widths[4]));
        let mut offset = 0;
        for i in 0..5 {
            shaped(&mut cache.pre[i], (rows(i), widths[i]));
            shaped(&mut cache.normed[i], (rows(i), widths[i]));
            // conv → bn → ReLU; the fifth reads the node features and writes the edge features.
            let (done, rest) = cache.act.split_at_mut(i + 1);
            let inp = if i < 4 {
                done[i].view()
            } else {
                cache.features.slice(s![.., ..node])
            };
            by_rows(side_by_side, cache.pre[i].view_mut(), inp, |out, inp| {
                convs[i].forward(out, inp, compute)
            })?;
            normalise(
                i,
                cache.normed[i].view_mut(),
                cache.pre[i].view(),
                &mut cache.bn[i],
            )?;
            if i < 4 {
                let act = &mut rest[0];
                shaped(act, (n * k, widths[i]));
                by_rows(
                    side_by_side,
                    act.view_mut(),
                    cache.normed[i].view(),
                    relu_forward,
                )?;
                let block = s![.., offset..offset + widths[i]];
                max_k_forward(
                    cache.features.slice_mut(block),
                    act.view(),
                    k,
                    &mut cache.max_k[i],
                )?;
                offset += widths[i];
            } else {
                by_rows(
                    side_by_side,
                    cache.features.slice_mut(s![.., node..]),
                    cache.normed[4].view(),
                    relu_forward,
                )?;
            }
        }
        Ok(())
    }

    /// Adds the parameter gradients of one cloud's pass, given `dfeatures` (N, ΣC + E), walking
    /// the forward in reverse: edge ReLU, bn5, conv5 (into the node features), then for layer
    /// 4 down to 1 the max over K, ReLU, batch norm and convolution. A convolution's input is
    /// the previous layer's ReLU output, so its backward goes through that ReLU in the
    /// product's write-back; the max's gradient then adds to it. The first convolution's input
    /// (the edge rows) needs no gradient.
    pub fn backward(
        &mut self,
        dfeatures: ArrayView2<'_, T>,
        cache: &mut FeaturerCache<T>,
        compute: Compute,
    ) -> Result<()> {
        let (n, k, node) = (cache.idx.nrows(), self.k, self.node_width());
        let widths: Vec<usize> = self.convs.iter().map(|c| c.c_out()).collect();
        cache.dpre.resize_with(5, Default::default);
        cache.dnormed.resize_with(5, Default::default);
        for i in 0..5 {
            // Batch norm's backward adds into dpre; each dnormed but the last two is written
            // by the next convolution's backward.
            let shape = cache.pre[i].dim();
            zeroed(&mut cache.dpre[i], shape);
            match i {
                3 | 4 => zeroed(&mut cache.dnormed[i], shape),
                _ => shaped(&mut cache.dnormed[i], shape),
            }
        }
        shaped(&mut cache.dnode, (n, node));
        // features[:, ..ΣC] = node  →  dnode = dfeatures[:, ..ΣC] (plus conv5's below)
        cache.dnode.assign(&dfeatures.slice(s![.., ..node]));
        // features[:, ΣC..] = ReLU(bn5(conv5(node)))
        relu_backward(
            cache.dnormed[4].view_mut(),
            dfeatures.slice(s![.., node..]),
            cache.features.slice(s![.., node..]),
        )?;
        self.bns[4].backward(
            cache.dpre[4].view_mut(),
            cache.dnormed[4].view(),
            cache.pre[4].view(),
            &cache.bn[4],
        )?;
        self.convs[4].backward(
            cache.dnode.view_mut(),
            cache.dpre[4].view(),
            cache.features.slice(s![.., ..node]),
            compute,
        )?;
        let mut offset = node;
        for i in (0..4).rev() {
            offset -= widths[i];
            // node[:, block] = max_k(act_{i+1}), act_{i+1} = ReLU(normed_i): the ReLU's
            // backward on the maxima (the ReLU output at the winning neighbour is the
            // maximum), then the max's, added to conv_{i+1}'s part of dnormed_i.
            let block = s![.., offset..offset + widths[i]];
            zeroed(&mut cache.dmax, (n, widths[i]));
            relu_backward(
                cache.dmax.view_mut(),
                cache.dnode.slice(block),
                cache.features.slice(block),
            )?;
            max_k_backward(
                cache.dnormed[i].view_mut(),
                cache.dmax.view(),
                k,
                &cache.max_k[i],
            )?;
            self.bns[i].backward(
                cache.dpre[i].view_mut(),
                cache.dnormed[i].view(),
                cache.pre[i].view(),
                &cache.bn[i],
            )?;
            // act_i = ReLU(normed_{i−1}) for i > 0: dnormed_{i−1} written through that ReLU.
            match i {
                0 => self.convs[0].backward_params(
                    cache.dpre[0].view(),
                    cache.act[0].view(),
                    compute,
                )?,
                _ => self.convs[i].backward_through_relu(
                    cache.dnormed[i - 1].view_mut(),
                    cache.dpre[i].view(),
                    cache.act[i].view(),
                    compute,
                )?,
            }
        }
        Ok(())
    }
}

impl<T: Element> Parameters<T> for PointFeaturer<T> {
    fn visit_params_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ParamView<'a, T>)) {
        for (i, (conv, bn)) in self.convs.iter().zip(&self.bns).enumerate() {
            conv.visit_params_ref(&join_name(prefix, &format!("conv{}", i + 1)), f);
            bn.visit_params_ref(&join_name(prefix, &format!("bn{}", i + 1)), f);
        }
    }

    fn visit_buffers_ref<'a>(
        &'a self,
        prefix: &str,
        f: &mut dyn FnMut(&str, ndarray::ArrayViewD<'a, T>),
    ) {
        for (i, bn) in self.bns.iter().enumerate() {
            bn.visit_buffers_ref(&join_name(prefix, &format!("bn{}", i + 1)), f);
        }
    }

    fn visit_params(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ParamViewMut<'_, T>)) {
        for (i, (conv, bn)) in self.convs.iter_mut().zip(&mut self.bns).enumerate() {
            conv.visit_params(&join_name(prefix, &format!("conv{}", i + 1)), f);
            bn.visit_params(&join_name(prefix, &format!("bn{}", i + 1)), f);
        }
    }

    fn visit_buffers(
        &mut self,
        prefix: &str,
        f: &mut dyn FnMut(&str, ndarray::ArrayViewMutD<'_, T>),
    ) {
        for (i, bn) in self.bns.iter_mut().enumerate() {
            bn.visit_buffers(&join_name(prefix, &format!("bn{}", i + 1)), f);
        }
    }
}

/// `f(out, inp)`, or with `side_by_side` `f` on the top and on the bottom half of both's rows
/// side by side on rayon's pool: for a row-by-row `f` the same values.
fn by_rows<T: Element>(
    side_by_side: bool,
    out: ArrayViewMut2<'_, T>,
    inp: ArrayView2<'_, T>,
    f: impl Fn(ArrayViewMut2<'_, T>, ArrayView2<'_, T>) -> rgm_nn::Result<()> + Sync,
) -> rgm_nn::Result<()> {
    let half = out.nrows() / 2;
    if !side_by_side || half == 0 || inp.nrows() != out.nrows() {
        return f(out, inp);
    }
    let (out_top, out_bottom) = out.split_at(Axis(0), half);
    let (inp_top, inp_bottom) = inp.split_at(Axis(0), half);
    let (top, bottom) = rayon::join(|| f(out_top, inp_top), || f(out_bottom, inp_bottom));
    top.and(bottom)
}
