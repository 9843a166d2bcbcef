//! Finite differences validate the f64 reference loss gradient.

mod common;

use cocog_engine::reference::loss::image_loss;
use common::Rng;

#[test]
fn loss_gradient_matches_finite_differences() {
    let (w, h) = (13, 9);
    let mut rng = Rng::new(4);
    let mut pred: Vec<[f64; 3]> = (0..w * h)
        .map(|_| std::array::from_fn(|_| rng.range(0.0, 1.0)))
        .collect();
    let target: Vec<[f64; 3]> = (0..w * h)
        .map(|_| std::array::from_fn(|_| rng.range(0.0, 1.0)))
        .collect();
    for lambda in [0.0, 0.2, 1.0] {
        let (_, grad) = image_loss(&pred, &target, w, h, lambda);
        let eps = 1e-6;
        let mut worst = 0.0f64;
        for p in 0..w * h {
            for c in 0..3 {
                let orig = pred[p][c];
                pred[p][c] = orig + eps;
                let lp = image_loss(&pred, &target, w, h, lambda).0;
                pred[p][c] = orig - eps;
                let lm = image_loss(&pred, &target, w, h, lambda).0;
                pred[p][c] = orig;
                let fd = (lp - lm) / (2.0 * eps);
                let err = (fd - grad[p][c]).abs() / (fd.abs().max(grad[p][c].abs()) + 1e-9);
                worst = worst.max(err);
                assert!(
                    err < 0.01,
                    "λ={lambda} pixel {p} channel {c}: fd {fd} vs analytic {}",
                    grad[p][c]
                );
            }
        }
        eprintln!("λ={lambda}: worst relative error {worst:.2e}");
    }
}

#[test]
fn identical_images_have_zero_loss() {
    let mut rng = Rng::new(9);
    let img: Vec<[f64; 3]> = (0..64)
        .map(|_| std::array::from_fn(|_| rng.range(0.0, 1.0)))
        .collect();
    let (loss, _) = image_loss(&img, &img, 8, 8, 0.2);
    assert!(loss.abs() < 1e-12, "loss {loss}");
}
