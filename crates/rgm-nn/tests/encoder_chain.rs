//! The ops composed as the edge generator's pre-norm encoder layer composes them (spec §2.2):
//! `y = x + MHA(LN₁(x))`, `z = y + FF(LN₂(y))`, `out = LN₃(z)`, backward in reverse with the
//! residual gradients accumulating, checked end to end against finite differences.

use ndarray::{Array2, ArrayD};
use rand::{rngs::StdRng, SeedableRng};
use rgm_nn::gradcheck::{assert_gradients, ix1, ix2, uniform};
use rgm_nn::*;

const R: usize = 5; // points
const C: usize = 4;
const H: usize = 2;

struct Encoder {
    ln1: LayerNorm<f64>,
    mha: MultiHeadAttention<f64>,
    ln2: LayerNorm<f64>,
    ff: FeedForward<f64>,
    ln3: LayerNorm<f64>,
}

/// Seeded PyTorch-default layers; LN₁'s scale is the checked parameter `a1`.
fn encoder(a1: &ArrayD<f64>) -> Encoder {
    let rng = &mut StdRng::seed_from_u64(7);
    let mut ln1 = LayerNorm::new(C);
    ln1.scale.value = ix1(a1);
    Encoder {
        ln1,
        mha: MultiHeadAttention::new(C, H, rng).unwrap(),
        ln2: LayerNorm::new(C),
        ff: FeedForward::new(C, 6, rng),
        ln3: LayerNorm::new(C),
    }
}

#[derive(Default)]
struct Caches {
    ln1: LayerNormCache<f64>,
    mha: AttentionCache<f64>,
    ln2: LayerNormCache<f64>,
    ff: FeedForwardCache<f64>,
    ln3: LayerNormCache<f64>,
    n1: Array2<f64>, // (R, C) LN₁(x)
    y: Array2<f64>,  // (R, C)
    n2: Array2<f64>, // (R, C) LN₂(y)
    z: Array2<f64>,  // (R, C)
}

fn forward(enc: &Encoder, x: &Array2<f64>, c: &mut Caches) -> Array2<f64> {
    let zeros = || Array2::zeros((R, C));
    (c.n1, c.n2) = (zeros(), zeros());
    enc.ln1
        .forward(c.n1.view_mut(), x.view(), &mut c.ln1)
        .unwrap();
    let mut attn = zeros();
    enc.mha
        .forward(
            attn.view_mut(),
            c.n1.view(),
            c.n1.view(),
            &mut c.mha,
            Compute::default(),
        )
        .unwrap();
    c.y = x + &attn;
    enc.ln2
        .forward(c.n2.view_mut(), c.y.view(), &mut c.ln2)
        .unwrap();
    let mut ff = zeros();
    enc.ff
        .forward(ff.view_mut(), c.n2.view(), &mut c.ff, Compute::default())
        .unwrap();
    c.z = &c.y + &ff;
    let mut out = zeros();
    enc.ln3
        .forward(out.view_mut(), c.z.view(), &mut c.ln3)
        .unwrap();
    out
}

#[test]
fn pre_norm_encoder_layer_backward_matches_finite_differences() {
    let inputs = [uniform(&[R, C], 1), uniform(&[C], 2)];
    let run = |i: &[ArrayD<f64>]| {
        let (enc, mut c) = (encoder(&i[1]), Caches::default());
        let out = forward(&enc, &ix2(&i[0]), &mut c);
        (out, enc, c)
    };
    assert_gradients(
        "encoder layer",
        1e-6,
        &inputs,
        &mut |i| run(i).0.into_dyn(),
        &mut |i, dout| {
            let (_, mut enc, mut c) = run(i);
            let x = ix2(&i[0]);
            let zeros = || Array2::<f64>::zeros((R, C));
            let mut dz = zeros();
            enc.ln3
                .backward(dz.view_mut(), ix2(dout).view(), c.z.view(), &c.ln3)
                .unwrap();
            // z = y + FF(LN₂(y)): dy gets dz directly and through the feed-forward branch.
            let mut dy = dz.clone();
            let mut dn2 = zeros();
            enc.ff
                .backward(
                    dn2.view_mut(),
                    dz.view(),
                    c.n2.view(),
                    &mut c.ff,
                    Compute::default(),
                )
                .unwrap();
            enc.ln2
                .backward(dy.view_mut(), dn2.view(), c.y.view(), &c.ln2)
                .unwrap();
            // y = x + MHA(LN₁(x)), self-attention: keys and values share the query's gradient.
            let mut dx = dy.clone();
            let mut dn1 = zeros();
            enc.mha
                .backward(
                    dn1.view_mut(),
                    None,
                    dy.view(),
                    c.n1.view(),
                    c.n1.view(),
                    &mut c.mha,
                    Compute::default(),
                )
                .unwrap();
            enc.ln1
                .backward(dx.view_mut(), dn1.view(), x.view(), &c.ln1)
                .unwrap();
            vec![dx.into_dyn(), enc.ln1.scale.grad.into_dyn()]
        },
    );
}
