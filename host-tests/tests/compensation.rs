//! The per-sample step against independent references: exact recovery by method 1, the
//! first-order agreement of method 2 with a derived bound, the cost of the simplified forms,
//! f32 against the f64 reference, and the status policies.

use bins_comp::linalg::{mat_mul, norm_inf};
use bins_comp::{Calibration, Form, Method, Status, TempModel, ident, paper};
use host_tests::{inverse_gj, max_diff, mv, truth_constants, widen};
use proptest::prelude::*;

const M1: Method = Method::CoefficientCorrection;
const M2F: Method = Method::OutputCorrection(Form::Full);
const M2S: Method = Method::OutputCorrection(Form::Simplified);
const M2L: Method = Method::OutputCorrection(Form::Linearized);

fn cal(model: TempModel<f64>, method: Method) -> Calibration<f64> {
    paper::calibration(model, method).expect("valid calibration")
}

fn cal32(model: TempModel<f64>, method: Method) -> Calibration<f32> {
    paper::calibration(model, method).expect("valid calibration")
}

/// Grid of specific forces with |a| ≤ 10 g: axes, diagonals and the check positions scaled.
fn accel_grid() -> Vec<[f64; 3]> {
    let mut out = Vec::new();
    for &s in &[-10.0, -3.0, -1.0, 0.0, 0.5, 1.0, 4.0, 10.0] {
        for dir in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.577, -0.577, 0.577], [0.6, 0.8, 0.0]] {
            out.push(dir.map(|d: f64| d * s));
        }
    }
    for cp in ident::check_positions_g(25.0) {
        out.push(cp);
    }
    out
}

fn temps() -> Vec<f64> {
    (0..=22).map(|i| -40.0 + 5.0 * i as f64).collect()
}

/// Signals of the unit whose true constants at `t` are `truth` (generated independently of
/// the core's forward model).
fn signals(truth: &bins_comp::Constants<f64>, a: &[f64; 3]) -> [f64; 3] {
    let ka = mv(&truth.k_v_per_g, a);
    [ka[0] + truth.u0_v[0], ka[1] + truth.u0_v[1], ka[2] + truth.u0_v[2]]
}

#[test]
fn method1_recovers_the_truth_exactly_for_piecewise_and_polynomial_truths() {
    let pwl = cal(paper::two_range_model().unwrap(), M1);
    let quad = cal(paper::quadratic_truth().unwrap(), M1);
    let (pwl32, quad32) = (cal32(paper::two_range_model().unwrap(), M1), cal32(paper::quadratic_truth().unwrap(), M1));
    let (mut worst64, mut worst32): (f64, f64) = (0.0, 0.0);
    for t in temps() {
        for (quadratic, c64, c32) in [(false, &pwl, &pwl32), (true, &quad, &quad32)] {
            let truth = truth_constants(t, quadratic);
            for a in accel_grid() {
                let u = signals(&truth, &a);
                let s = c64.compensate(u, t);
                assert_eq!(s.status, Status::OK);
                worst64 = worst64.max(max_diff(&s.accel_g, &a));
                let s32 = c32.compensate(u.map(|x| x as f32), t as f32);
                worst32 = worst32.max(max_diff(&widen(&s32.accel_g), &a));
            }
        }
    }
    println!("method 1: worst error f64 {worst64:.2e} g, f32 {worst32:.2e} g");
    assert!(worst64 < 1e-11, "f64 method 1 error {worst64} g");
    // Includes rounding the signals to f32 (2^-24 relative of up to 5.5 V).
    assert!(worst32 <= 2e-6, "f32 method 1 error {worst32} g");
}

/// The derived bound on |method 1 − method 2 (full)| in the ∞-norm (see
/// `docs/compensation.md`): with X = N·ΔK, n = N·ΔU0, â = N(U − U0), r = ‖X‖, e = ‖n‖,
/// `a₁ = (I+X)⁻¹(â − n) = â − Xâ − n + R`, `‖R‖ ≤ r·e + r²/(1−r)·(‖â‖ + e)`, and the full
/// form differs from the exact linearisation only by replacing N with D = diag(1/K_ii) in
/// the first term and with D − D·K_off·D in the second: `‖(NΔKN − DΔKD)v‖ + ‖(N − D + DK_offD)ΔU0‖`.
fn method2_bound(c: &Calibration<f64>, u: &[f64; 3], t: f64) -> f64 {
    let (remainder, lin_gap) = method2_bound_parts(c, u, t);
    remainder + lin_gap
}

/// (second-order remainder, gap of the printed T(5) to the exact linearisation).
fn method2_bound_parts(c: &Calibration<f64>, u: &[f64; 3], t: f64) -> (f64, f64) {
    let k = c.constants().k_v_per_g;
    let n = inverse_gj(&k);
    let d = c.model().delta(t, c.t0_c());
    let mut dk = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            dk[i][j] = k[i][j] * d.rel_k[i][j];
        }
    }
    let v = [0, 1, 2].map(|i| u[i] - c.constants().u0_v[i]);
    let a_hat = mv(&n, &v);
    let x = mat_mul(&n, &dk);
    let r = norm_inf(&x);
    let e = mv(&n, &d.du0_v).iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let amax = a_hat.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let remainder = r * e + r * r / (1.0 - r) * (amax + e);
    let dm = [0, 1, 2].map(|i| 1.0 / k[i][i]);
    let mut lin_gap = [0.0; 3];
    let ndkn = mat_mul(&mat_mul(&n, &dk), &n);
    for i in 0..3 {
        let mut s = 0.0;
        for j in 0..3 {
            let dkd = dm[i] * dk[i][j] * dm[j];
            let koff = if i == j { 0.0 } else { k[i][j] };
            let approx_n = if i == j { dm[i] } else { -dm[i] * koff * dm[j] };
            s += (ndkn[i][j] - dkd) * v[j] + (n[i][j] - approx_n) * d.du0_v[j];
        }
        lin_gap[i] = s.abs();
    }
    (remainder, lin_gap.iter().fold(0.0f64, |m, x| m.max(*x)))
}

#[test]
fn method2_linearized_agrees_with_method1_to_second_order() {
    for model in [paper::two_range_model().unwrap(), paper::quadratic_truth().unwrap()] {
        let (m1, m2) = (cal(model, M1), cal(model, M2L));
        let (mut worst, mut worst_ratio): (f64, f64) = (0.0, 0.0);
        for t in temps() {
            let truth = truth_constants(t, matches!(model, TempModel::Poly { .. }));
            for a in accel_grid() {
                let u = signals(&truth, &a);
                let diff = max_diff(&m1.compensate(u, t).accel_g, &m2.compensate(u, t).accel_g);
                let (remainder, _) = method2_bound_parts(&m1, &u, t);
                assert!(diff <= remainder * (1.0 + 1e-9) + 1e-15, "T={t} a={a:?}: {diff:e} > {remainder:e}");
                worst = worst.max(diff);
                worst_ratio = worst_ratio.max(diff / remainder.max(1e-300));
            }
        }
        println!("method 2 linearized vs method 1: worst {:.3} µg, worst diff/bound {worst_ratio:.2}", worst * 1e6);
        assert!(worst_ratio > 0.05, "bound too loose: {worst_ratio}");
    }
}

#[test]
fn method2_full_agrees_with_method1_within_the_derived_first_order_bound() {
    for model in [paper::two_range_model().unwrap(), paper::quadratic_truth().unwrap()] {
        let (m1, m2) = (cal(model, M1), cal(model, M2F));
        let mut worst: f64 = 0.0;
        let mut worst_ratio: f64 = 0.0;
        for t in temps() {
            let truth = truth_constants(t, matches!(model, TempModel::Poly { .. }));
            for a in accel_grid() {
                let u = signals(&truth, &a);
                let diff = max_diff(&m1.compensate(u, t).accel_g, &m2.compensate(u, t).accel_g);
                let bound = method2_bound(&m1, &u, t);
                assert!(diff <= bound * (1.0 + 1e-9) + 1e-15, "T={t} a={a:?}: |m1-m2| {diff:e} > bound {bound:e}");
                worst = worst.max(diff);
                worst_ratio = worst_ratio.max(diff / bound.max(1e-300));
            }
        }
        println!("method 2 full vs method 1: worst {:.3} µg, worst diff/bound {worst_ratio:.2}", worst * 1e6);
        // The bound must be informative: the difference reaches a sizeable fraction of it.
        assert!(worst_ratio > 0.05, "bound too loose to mean anything: {worst_ratio}");
    }
}

#[test]
fn method2_with_the_wrong_sign_would_double_the_error() {
    // Guards the §4 sign decision: subtracting T(5) instead of adding it moves the result
    // away from method 1 by twice the correction.
    let model = paper::two_range_model().unwrap();
    let (m0, m1, m2) = (cal(model, Method::Uncorrected), cal(model, M1), cal(model, M2F));
    let truth = truth_constants(-40.0, false);
    let u = signals(&truth, &[0.3, -0.5, 0.8]);
    let (a0, a1, a2) =
        (m0.compensate(u, -40.0).accel_g, m1.compensate(u, -40.0).accel_g, m2.compensate(u, -40.0).accel_g);
    let wrong = [0, 1, 2].map(|i| a0[i] - (a2[i] - a0[i]));
    assert!(max_diff(&a2, &a1) < 0.05 * max_diff(&a0, &a1));
    assert!(max_diff(&wrong, &a1) > 1.9 * max_diff(&a0, &a1));
}

#[test]
fn simplified_forms_cost_exactly_the_dropped_cross_terms() {
    for model in [paper::two_range_model().unwrap(), paper::quadratic_truth().unwrap()] {
        let (m1, full, simp) = (cal(model, M1), cal(model, M2F), cal(model, M2S));
        let k = m1.constants().k_v_per_g;
        let (mut extra, mut full_err, mut simp_err): (f64, f64, f64) = (0.0, 0.0, 0.0);
        for t in temps() {
            let d = m1.model().delta(t, 20.0);
            for a in accel_grid() {
                let truth = truth_constants(t, matches!(model, TempModel::Poly { .. }));
                let u = signals(&truth, &a);
                let (af, as_) = (full.compensate(u, t).accel_g, simp.compensate(u, t).accel_g);
                // Dropped terms of T(5), written out: Σ_{j≠i} K_ij (α_j − v_j γ_ij)/(K_ii K_jj).
                let v = [0, 1, 2].map(|i| u[i] - m1.constants().u0_v[i]);
                for i in 0..3 {
                    let dropped: f64 = (0..3)
                        .filter(|&j| j != i)
                        .map(|j| k[i][j] * (d.du0_v[j] - v[j] * d.rel_k[i][j]) / (k[i][i] * k[j][j]))
                        .sum();
                    assert!((af[i] - as_[i] - dropped).abs() < 1e-14, "identity broken at T={t}");
                    extra = extra.max(dropped.abs());
                }
                let a1 = m1.compensate(u, t).accel_g;
                full_err = full_err.max(max_diff(&af, &a1));
                simp_err = simp_err.max(max_diff(&as_, &a1));
            }
        }
        println!(
            "{}: simplified form drops up to {:.1} µg; vs method 1: full {:.2} µg, simplified {:.1} µg (|a| ≤ 10 g, −40…+70 °C)",
            if matches!(model, TempModel::Poly { .. }) { "quadratic" } else { "two-range" },
            extra * 1e6,
            full_err * 1e6,
            simp_err * 1e6
        );
        assert!(simp_err > 3.0 * full_err, "the simplified form should be measurably worse");
        assert!(extra > 1e-6, "the dropped terms are not negligible for this unit");
    }
}

#[test]
fn status_policies_give_defined_outputs() {
    let c = cal32(paper::two_range_model().unwrap(), M1);
    let u = [0.1f32, -0.2, 0.3];
    // In range: no flags.
    assert_eq!(c.compensate(u, 25.0).status, Status::OK);
    // Out of range: clamped to the edge, flagged, same output as at the edge.
    let hot = c.compensate(u, 95.0);
    assert!(hot.status.contains(Status::TEMP_CLAMPED));
    assert_eq!(hot.accel_g, c.compensate(u, 70.0).accel_g);
    let cold = c.compensate(u, -55.0);
    assert_eq!(cold.accel_g, c.compensate(u, -40.0).accel_g);
    // Non-finite temperature: compensated at T0.
    let nan_t = c.compensate(u, f32::NAN);
    assert!(nan_t.status.contains(Status::NONFINITE_INPUT | Status::TEMP_CLAMPED));
    assert_eq!(nan_t.accel_g, c.compensate(u, 20.0).accel_g);
    // Non-finite signal: that axis is replaced by its zero offset.
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let s = c.compensate([bad, -0.2, 0.3], 25.0);
        assert!(s.status.contains(Status::NONFINITE_INPUT));
        assert!(s.accel_g.iter().all(|x| x.is_finite()));
        let u0x = c.constants().u0_v[0];
        assert_eq!(s.accel_g, c.compensate([u0x, -0.2, 0.3], 25.0).accel_g);
    }
    // Overflowing signals: zero output, flagged.
    let s = c.compensate([3e38, 3e38, -3e38], 25.0);
    assert!(s.status.contains(Status::NONFINITE_INPUT));
    assert_eq!(s.accel_g, [0.0; 3]);
    // Uncalibrated: raw volts, flagged on every sample.
    let un = Calibration::<f32>::uncalibrated().compensate(u, 25.0);
    assert_eq!(un.status, Status::INVALID_CALIBRATION);
    assert_eq!(un.accel_g, u);
}

#[test]
fn invalid_calibrations_are_typed_errors_at_load_time() {
    use bins_comp::CalibrationError as E;
    use bins_comp::temperature::TempModelError as TE;
    let good = paper::params(paper::two_range_model().unwrap(), M1);
    let load = |p: &bins_comp::CalibrationParams| Calibration::<f32>::new(p).map(|_| ());
    assert_eq!(load(&good), Ok(()));
    let mut p = good;
    p.constants.k_v_per_g[2] = p.constants.k_v_per_g[0];
    assert_eq!(load(&p), Err(E::SingularK));
    let mut p = good;
    let r0 = p.constants.k_v_per_g[0];
    p.constants.k_v_per_g[2] = [r0[0], r0[1], r0[2] + 1e-6];
    assert_eq!(load(&p), Err(E::SingularK));
    let mut p = good;
    p.constants.u0_v[1] = f64::NAN;
    assert_eq!(load(&p), Err(E::NonFiniteConstants));
    for range in [(30.0, 70.0), (70.0, -40.0), (-40.0, f64::INFINITY)] {
        assert_eq!(load(&bins_comp::CalibrationParams { temp_range_c: range, ..good }), Err(E::BadRange));
    }
    let TempModel::Pwl { n_knots, mut knots_c, at_knot } = good.model else { unreachable!() };
    knots_c.swap(0, 1);
    let p = bins_comp::CalibrationParams { model: TempModel::Pwl { n_knots, knots_c, at_knot }, ..good };
    assert_eq!(load(&p), Err(E::TempModel(TE::KnotsNotIncreasing)));
    let TempModel::Poly { coef, .. } = paper::quadratic_truth().unwrap() else { unreachable!() };
    let p = bins_comp::CalibrationParams { model: TempModel::Poly { order: 5, coef }, ..good };
    assert_eq!(load(&p), Err(E::TempModel(TE::UnsupportedOrder(5))));
    // A temperature model that drives K_zz through zero at +60 °C, inside the range.
    let mut wild = coef;
    wild[0].rel_k[2][2] = -1.0 / 40.0;
    let p = bins_comp::CalibrationParams { model: TempModel::Poly { order: 1, coef: wild }, ..good };
    assert_eq!(load(&p), Err(E::SingularInRange));
    // One that makes the z row a multiple of the x row at +60 °C.
    let k = good.constants.k_v_per_g;
    let mut dep = [bins_comp::CoefDelta::zero(); 4];
    for j in 0..3 {
        // K_zj(60) = K_zj (1 + 40 g_j) = K_xj  =>  g_j = (K_xj / K_zj − 1) / 40.
        dep[0].rel_k[2][j] = (k[0][j] / k[2][j] - 1.0) / 40.0;
    }
    let p = bins_comp::CalibrationParams { model: TempModel::Poly { order: 1, coef: dep }, ..good };
    assert_eq!(load(&p), Err(E::SingularInRange));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 4000, ..ProptestConfig::default() })]

    /// f32 on the target against the f64 reference: ≤ 2 µg over ±10 g, every method and model.
    #[test]
    fn f32_matches_the_f64_reference_within_2_ug(
        ax in -10.0f64..10.0, ay in -10.0f64..10.0, az in -10.0f64..10.0,
        t in -40.0f64..70.0, variant in 0usize..9,
    ) {
        let (which, method) = bins_comp::vectors::variant_method(variant).unwrap();
        let model = match which {
            bins_comp::vectors::VariantModel::TwoRange => paper::two_range_model().unwrap(),
            bins_comp::vectors::VariantModel::Quadratic => paper::quadratic_truth().unwrap(),
        };
        let c64 = cal(model, method);
        let c32 = cal32(model, method);
        let truth = truth_constants(t, true);
        // Signals rounded to f32 once, and both paths fed the same rounded values.
        let u32_ = signals(&truth, &[ax, ay, az]).map(|x| x as f32);
        let t32 = t as f32;
        let r64 = c64.compensate(widen(&u32_), t32 as f64);
        let r32 = c32.compensate(u32_, t32);
        prop_assert_eq!(r64.status, r32.status);
        let err = max_diff(&widen(&r32.accel_g), &r64.accel_g);
        prop_assert!(err <= 2e-6, "f32 error {} g", err);
    }
}

proptest! {
    /// The temperature cache changes no result: with the cache kept across samples, readings
    /// that repeat, leave the range or are not finite, and calibrations that change under it,
    /// every output equals `compensate`'s bit for bit.
    #[test]
    fn temperature_cache_changes_no_result(
        steps in proptest::collection::vec((0usize..4, 0usize..6, -0.6f32..0.6, -0.6f32..0.6, -0.6f32..0.6), 1..200)
    ) {
        let pwl = paper::two_range_model().unwrap();
        let cals: [Calibration<f32>; 4] = [
            paper::calibration(pwl, Method::CoefficientCorrection).unwrap(),
            paper::calibration(pwl, Method::OutputCorrection(Form::Simplified)).unwrap(),
            paper::calibration(paper::order3_model().unwrap(), Method::CoefficientCorrection).unwrap(),
            Calibration::uncalibrated(),
        ];
        let temps = [20.0f32, 20.0, -12.5, 45.25, 99.0, f32::NAN];
        let mut cache = bins_comp::TempCache::new();
        for (c, t, x, y, z) in steps {
            let (cal, t) = (&cals[c], temps[t]);
            let cached = cal.apply([x, y, z], cache.get(cal, t));
            let direct = cal.compensate([x, y, z], t);
            prop_assert_eq!(cached.status, direct.status);
            prop_assert_eq!(cached.accel_g.map(f32::to_bits), direct.accel_g.map(f32::to_bits));
        }
    }
}

#[test]
fn division_free_reciprocal_is_within_2_ulp_of_the_quotient() {
    // `float::recip` replaces the f64 division at load time (N = K⁻¹, 1/K_ii): against the
    // correctly rounded quotient over the f32 normal range, both signs.
    let mut worst = 0u64;
    let mut x = 1.3e-37f64;
    while x < 3e37 {
        for v in [x, -x, x * 1.000_000_7, x * 0.999_999_3] {
            let r = bins_comp::float::recip(v);
            let q = 1.0 / v;
            let ulps = (r.to_bits() as i64 - q.to_bits() as i64).unsigned_abs();
            worst = worst.max(ulps);
        }
        x *= 1.37;
    }
    println!("recip: worst {worst} ulp");
    assert!(worst <= 2, "{worst} ulp");
    assert!(bins_comp::float::recip(1e-300f64).is_nan() || !bins_comp::float::recip(1e-300f64).is_finite());
}

#[test]
fn an_f64_split_into_two_f32_holds_it_to_2_pow_minus_47() {
    // `Float::split_f64` (the load-time K of the target, without f64 arithmetic): hi is x
    // rounded; hi + lo against x itself, over magnitudes from 2^-60 to 2^60 and both signs,
    // and exact when x is an f32 plus a remainder of 24 bits.
    use bins_comp::Float;
    let mut worst: f64 = 0.0;
    let mut x = 1.0e-18f64;
    while x < 1.0e18 {
        for v in [x, -x, x * (1.0 + 1.0 / 3.0), -x * std::f64::consts::PI, x * 1.000_000_123_456_789] {
            let (hi, lo) = <f32 as Float>::split_f64(v);
            assert_eq!(hi, v as f32);
            let err = ((hi as f64 + lo as f64) - v).abs() / v.abs();
            worst = worst.max(err);
        }
        x *= 1.37;
    }
    println!("split_f64: worst relative error {worst:.2e}");
    assert!(worst <= 2f64.powi(-47), "{worst:e}");
    let exact = 0.55060863f32 as f64 + 3.0 * 2f64.powi(-40);
    let (hi, lo) = <f32 as Float>::split_f64(exact);
    assert_eq!(hi as f64 + lo as f64, exact);
    // Zero, and the rest (below 2^-98) of a number below 2^-74, is dropped.
    assert_eq!(<f32 as Float>::split_f64(0.0), (0.0, 0.0));
    assert_eq!(<f32 as Float>::split_f64(1e-25).1, 0.0);
}

#[test]
fn f64_comparisons_by_the_bits_are_the_ieee_ones() {
    // `float::cmp_f64` (the load-time checks of the target, without soft-float comparisons)
    // against the language's own `<`, `<=`, `==` on every pair of special values, their
    // neighbours and a spread of magnitudes of both signs.
    use bins_comp::float::cmp_f64;
    let mut xs = vec![
        0.0,
        -0.0,
        f64::MIN_POSITIVE,
        f64::from_bits(1),
        f64::MAX,
        f64::INFINITY,
        f64::NAN,
        -f64::NAN,
        f64::from_bits(0x7ff0_0000_0000_0001),
        f64::from_bits(0x7ff8_dead_beef_0000),
    ];
    let mut m = 1e-310f64;
    while m < 1e300 {
        xs.extend([m, m.next_up(), m.next_down()]);
        m *= 7.3;
    }
    xs.extend(xs.clone().iter().map(|x| -x));
    for &a in &xs {
        for &b in &xs {
            assert_eq!(cmp_f64::lt(a, b), a < b, "{a:e} < {b:e}");
            assert_eq!(cmp_f64::le(a, b), a <= b, "{a:e} <= {b:e}");
            assert_eq!(cmp_f64::eq(a, b), a == b, "{a:e} == {b:e}");
        }
    }
}
