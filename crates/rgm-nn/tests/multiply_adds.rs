//! `gemm::multiply_adds` counts every product's M·K·N, in each precision and through both entry
//! points. Its own test binary: the count is the process's, and no other test may add to it.

use ndarray::Array2;
use rgm_nn::gemm::{bf16_available, count_multiply_adds, mat_mul, mat_mul_then, multiply_adds};
use rgm_nn::scalar::Then;
use rgm_nn::{Compute, Precision};

#[test]
fn every_product_counts_its_multiply_adds() {
    let (a, b) = (Array2::<f32>::ones((5, 7)), Array2::<f32>::ones((7, 3)));
    let mut c = Array2::<f32>::zeros((5, 3));
    let start = multiply_adds();
    mat_mul(1.0, &a, &b, 0.0, &mut c, Compute::default());
    assert_eq!(multiply_adds() - start, 105);
    let then = Then::Layer {
        bias: None,
        relu: true,
    };
    mat_mul_then(&a, &b, then, &mut c, Compute::default());
    assert_eq!(multiply_adds() - start, 210);
    let a64 = Array2::<f64>::ones((2, 4));
    let mut c64 = Array2::<f64>::zeros((2, 2));
    mat_mul(1.0, &a64, &a64.t(), 0.0, &mut c64, Compute::default());
    assert_eq!(multiply_adds() - start, 226);
    if bf16_available() {
        mat_mul(
            1.0,
            &a,
            &b,
            0.0,
            &mut c,
            Compute::with_precision(Precision::Bf16),
        );
        assert_eq!(multiply_adds() - start, 331);
        assert_eq!(c[(0, 0)], 7.0);
    }
    let before = multiply_adds();
    count_multiply_adds(10, 20, 30);
    assert_eq!(multiply_adds() - before, 6000);
}
