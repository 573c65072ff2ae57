extern crate openblas_src;
