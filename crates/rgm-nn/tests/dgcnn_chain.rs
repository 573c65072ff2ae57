//! The ops composed as the model composes them: two DGCNN layers (edge gather → 1×1 conv →
//! batch norm → ReLU → max over K, each max written straight into its column block of the
//! concatenated node features), backward in reverse order with gradients accumulating into
//! shared buffers, checked end to end against finite differences.

use ndarray::{s, Array2, ArrayD};
use rgm_nn::gradcheck::{assert_gradients, ix2, uniform};
use rgm_nn::*;

const N: usize = 5;
const K: usize = 3;
const C: usize = 4;

/// kNN-like indices: each point first, then two others.
fn neighbours() -> Array2<usize> {
    Array2::from_shape_fn((N, K), |(n, k)| (n + k * 2) % N)
}

struct Layer {
    conv: Linear<f64>,
    bn: BatchNorm<f64>,
    bn_cache: BatchNormCache<f64>,
    pre_bn: Array2<f64>,   // (N*K, C)
    pre_relu: Array2<f64>, // (N*K, C)
    act: Array2<f64>,      // (N*K, C)
    max: MaxKCache,
}

impl Layer {
    fn new(weight: Array2<f64>) -> Self {
        Self {
            conv: Linear::from_values(weight, None).unwrap(),
            bn: BatchNorm::new(C),
            bn_cache: BatchNormCache::default(),
            pre_bn: Array2::zeros((N * K, C)),
            pre_relu: Array2::zeros((N * K, C)),
            act: Array2::zeros((N * K, C)),
            max: MaxKCache::default(),
        }
    }

    fn forward(&mut self, inp: &Array2<f64>, mut node: ndarray::ArrayViewMut2<'_, f64>) {
        self.conv
            .forward(self.pre_bn.view_mut(), inp.view(), Compute::default())
            .unwrap();
        self.bn
            .forward(
                self.pre_relu.view_mut(),
                self.pre_bn.view(),
                true,
                &mut self.bn_cache,
            )
            .unwrap();
        relu_forward(self.act.view_mut(), self.pre_relu.view()).unwrap();
        max_k_forward(node.view_mut(), self.act.view(), K, &mut self.max).unwrap();
    }

    /// Adds into `dinp` given `dact` (the gradient reaching this layer's activations).
    fn backward(
        &mut self,
        dinp: ndarray::ArrayViewMut2<'_, f64>,
        dact: &Array2<f64>,
        inp: &Array2<f64>,
    ) {
        let mut dpre_relu = Array2::zeros((N * K, C));
        relu_backward(dpre_relu.view_mut(), dact.view(), self.act.view()).unwrap();
        let mut dpre_bn = Array2::zeros((N * K, C));
        self.bn
            .backward(
                dpre_bn.view_mut(),
                dpre_relu.view(),
                self.pre_bn.view(),
                &self.bn_cache,
            )
            .unwrap();
        self.conv
            .backward(dinp, dpre_bn.view(), inp.view(), Compute::default())
            .unwrap();
    }
}

/// Runs both layers; returns the node features (N, 2C) and the state backward needs.
fn forward(
    x: &Array2<f64>,
    w1: &Array2<f64>,
    w2: &Array2<f64>,
) -> (Array2<f64>, Array2<f64>, Layer, Layer) {
    let mut edges = Array2::zeros((N * K, 6)); // (N*K, 6)
    edge_features_forward(edges.view_mut(), x.view(), neighbours().view()).unwrap();
    let mut node = Array2::zeros((N, 2 * C)); // (N, 2C)
    let (mut l1, mut l2) = (Layer::new(w1.clone()), Layer::new(w2.clone()));
    l1.forward(&edges, node.slice_mut(s![.., ..C]));
    let h1 = l1.act.clone();
    l2.forward(&h1, node.slice_mut(s![.., C..]));
    (node, edges, l1, l2)
}

#[test]
fn two_dgcnn_layers_backward_matches_finite_differences() {
    let inputs = [
        uniform(&[N, 3], 1),
        uniform(&[C, 6], 2),
        uniform(&[C, C], 3),
    ];
    let run = |i: &[ArrayD<f64>]| forward(&ix2(&i[0]), &ix2(&i[1]), &ix2(&i[2]));
    assert_gradients(
        "two DGCNN layers",
        1e-6,
        &inputs,
        &mut |i| run(i).0.into_dyn(),
        &mut |i, dout| {
            let (_, edges, mut l1, mut l2) = run(i);
            let dnode = ix2(dout); // (N, 2C)
                                   // Layer 2 first: its input h1 is layer 1's activation, so dh1 collects from both the
                                   // first max and layer 2's input gradient.
            let mut dh1 = Array2::zeros((N * K, C));
            max_k_backward(dh1.view_mut(), dnode.slice(s![.., ..C]), K, &l1.max).unwrap();
            let mut dh2 = Array2::zeros((N * K, C));
            max_k_backward(dh2.view_mut(), dnode.slice(s![.., C..]), K, &l2.max).unwrap();
            let h1 = l1.act.clone();
            l2.backward(dh1.view_mut(), &dh2, &h1);
            let mut dedges = Array2::zeros((N * K, 6));
            l1.backward(dedges.view_mut(), &dh1, &edges);
            let mut dx = Array2::zeros((N, 3));
            edge_features_backward(dx.view_mut(), dedges.view(), neighbours().view()).unwrap();
            vec![
                dx.into_dyn(),
                l1.conv.weight.grad.into_dyn(),
                l2.conv.weight.grad.into_dyn(),
            ]
        },
    );
}
