//! Identification helpers against simulated rig data: six-position T(10), its least-squares
//! generalisation under noise, and the polynomial temperature coefficients T(11) / least
//! squares.

use bins_comp::ident::{self, TILTER_POSITIONS_G};
use bins_comp::{Constants, TempModel, paper};
use host_tests::{mv, truth_constants};
use rand::{Rng, SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, Normal};

fn signals(c: &Constants<f64>, f: &[f64; 3]) -> [f64; 3] {
    let kf = mv(&c.k_v_per_g, f);
    [0, 1, 2].map(|i| kf[i] + c.u0_v[i])
}

#[test]
fn six_position_is_exact_on_ideal_positions() {
    let c = paper::TABLE_CONSTANTS[1];
    let u = TILTER_POSITIONS_G.map(|f| signals(&c, &f));
    let got = ident::six_position(&u);
    let ls = ident::fit_constants(&TILTER_POSITIONS_G, &u).unwrap();
    for i in 0..3 {
        assert!((got.u0_v[i] - c.u0_v[i]).abs() < 1e-15);
        assert!((ls.u0_v[i] - c.u0_v[i]).abs() < 1e-15);
        for j in 0..3 {
            assert!((got.k_v_per_g[i][j] - c.k_v_per_g[i][j]).abs() < 1e-15);
            assert!((ls.k_v_per_g[i][j] - c.k_v_per_g[i][j]).abs() < 1e-15);
        }
    }
}

#[test]
fn least_squares_recovers_constants_from_noisy_unlevel_positions() {
    // 12 holds: the six positions plus the tilted check positions, each tilted by a random
    // error of up to 0.5° that is known to the fit (as a real rig's reference would be), each
    // the mean of 500 samples with 1 mV noise.
    let truth = paper::TABLE_CONSTANTS[0];
    let mut rng = StdRng::seed_from_u64(7);
    let noise = Normal::new(0.0, 1e-3).unwrap();
    let (n_samples, sigma_v) = (500usize, 1e-3);
    let mut f_all = Vec::new();
    let mut u_all = Vec::new();
    for f in TILTER_POSITIONS_G.iter().chain(ident::check_positions_g(25.0).iter()) {
        let tilt = [0, 1, 2].map(|_| rng.random_range(-0.0087..0.0087));
        let mut g = [f[0] + tilt[0], f[1] + tilt[1], f[2] + tilt[2]];
        let n = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
        g = g.map(|x| x / n);
        let clean = signals(&truth, &g);
        let mut mean = [0.0; 3];
        for _ in 0..n_samples {
            for i in 0..3 {
                mean[i] += (clean[i] + noise.sample(&mut rng)) / n_samples as f64;
            }
        }
        f_all.push(g);
        u_all.push(mean);
    }
    let got = ident::fit_constants(&f_all, &u_all).unwrap();
    // Standard error of each coefficient ≈ σ/√(n·Σf²) with Σf² ≈ 4 over 12 holds; allow 5σ.
    let se = sigma_v / ((n_samples as f64) * 4.0).sqrt();
    for i in 0..3 {
        assert!((got.u0_v[i] - truth.u0_v[i]).abs() < 5.0 * se * 2.0, "U0[{i}]");
        for j in 0..3 {
            let e = (got.k_v_per_g[i][j] - truth.k_v_per_g[i][j]).abs();
            assert!(e < 5.0 * se, "K[{i}][{j}] off by {e:e} (se {se:e})");
        }
    }
    // Coplanar positions cannot determine K.
    let flat = [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]];
    let u = flat.map(|f| signals(&truth, &f));
    assert_eq!(ident::fit_constants(&flat, &u), Err(ident::FitError::Singular));
}

#[test]
fn six_position_under_noise_stays_within_the_predicted_error() {
    // T(10) on noisy means: each K element is a half-difference of two means, so its error
    // is N(0, σ_mean²/2); over 200 trials the RMS error must match that within 20 %.
    let truth = paper::TABLE_CONSTANTS[2];
    let mut rng = StdRng::seed_from_u64(11);
    let sigma_mean = 2e-5;
    let noise = Normal::new(0.0, sigma_mean).unwrap();
    let mut sq = 0.0;
    let trials = 200;
    for _ in 0..trials {
        let u = TILTER_POSITIONS_G.map(|f| signals(&truth, &f).map(|x| x + noise.sample(&mut rng)));
        let got = ident::six_position(&u);
        for i in 0..3 {
            for j in 0..3 {
                sq += (got.k_v_per_g[i][j] - truth.k_v_per_g[i][j]).powi(2);
            }
        }
    }
    let rms = (sq / (9 * trials) as f64).sqrt();
    let predicted = sigma_mean / 2f64.sqrt();
    assert!((rms / predicted - 1.0).abs() < 0.2, "rms {rms:e} vs predicted {predicted:e}");
}

#[test]
fn polynomial_coefficients_t11_exact_and_least_squares() {
    // Exact T(11): order 2 through the paper's three temperatures reproduces them.
    let model = paper::quadratic_truth().unwrap();
    for (t, c) in paper::off_nominal_points() {
        let back = paper::params(model, bins_comp::Method::CoefficientCorrection).constants_at(t);
        for i in 0..3 {
            assert!((back.u0_v[i] - c.u0_v[i]).abs() < 1e-15);
            for j in 0..3 {
                assert!((back.k_v_per_g[i][j] - c.k_v_per_g[i][j]).abs() < 1e-15);
            }
        }
    }
    // Least squares, order 3 from 9 noiseless temperatures of a cubic truth: exact.
    let TempModel::Poly { coef: mut truth_coef, .. } = model else { unreachable!() };
    truth_coef[2].du0_v = [2e-9, -1e-9, 3e-9];
    truth_coef[2].rel_k[0][0] = 4e-10;
    let truth = TempModel::Poly { order: 3, coef: truth_coef };
    let c0 = paper::TABLE_CONSTANTS[0];
    let p = paper::params(truth, bins_comp::Method::CoefficientCorrection);
    let pts: Vec<(f64, Constants<f64>)> =
        (-4..=5).map(|k| (20.0 + 12.0 * k as f64, p.constants_at(20.0 + 12.0 * k as f64))).collect();
    let TempModel::Poly { order, coef } = ident::poly_from_constants(20.0, &c0, &pts, 3).unwrap() else {
        unreachable!()
    };
    assert_eq!(order, 3);
    for n in 0..3 {
        let (a, b) = (coef[n].to_array(), truth_coef[n].to_array());
        for k in 0..12 {
            // Compared by their contribution at ΔT = 60 °C (V for α, 1 for β/γ).
            let at60 = 60f64.powi(n as i32 + 1);
            assert!((a[k] - b[k]).abs() * at60 <= 1e-12, "order {} elem {k}: {} vs {}", n + 1, a[k], b[k]);
        }
    }
    // Too few temperatures for the order is an error, not a guess.
    assert_eq!(
        ident::poly_from_constants(20.0, &c0, &paper::off_nominal_points(), 3),
        Err(ident::FitError::TooFewPoints { needed: 3, got: 2 })
    );
    // The two-range model through the same points equals the independent interpolation.
    let pwl = paper::params(paper::two_range_model().unwrap(), bins_comp::Method::CoefficientCorrection);
    for t in [-40.0, -10.0, 20.0, 45.0, 70.0] {
        let (a, b) = (pwl.constants_at(t), truth_constants(t, false));
        for i in 0..3 {
            assert!((a.u0_v[i] - b.u0_v[i]).abs() < 1e-15);
        }
    }
}
