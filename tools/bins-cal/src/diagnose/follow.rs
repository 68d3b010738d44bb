//! SIM for a real recording: what a calibration predicts, row for row, for the reference,
//! temperature and time of a real recording (`bins-cal diagnose --real REAL.csv --calib
//! CAL.toml`). A user of a real unit has its calibration, not a simulation of the very test.
//!
//! Each row with a known reference gets the signals of T(1) with the constants at the row's
//! `temp_C` by T(3)/T(4) ([`CalibrationParams::constants_at`], the core's one implementation):
//! `U = U0(T) + K(T)·f`. Every other cell is REAL's own, so the pair matches row for row. The
//! calibration's vibration model is not applied: under vibration the rectified error stays in
//! the residual, where the V(2) mechanisms of the library name it.

use crate::recording::Row;
use bins_comp::CalibrationParams;

/// The prediction of `real` by the calibration `params`: REAL's rows with `ux_V..uz_V`
/// replaced where the reference is known (kept where it is not: those rows are not used).
pub fn predict(real: &[Row], params: &CalibrationParams) -> Vec<Row> {
    real.iter()
        .map(|r| {
            let mut s = Row::default();
            predict_into(r, params, &mut s);
            s
        })
        .collect()
}

/// The prediction of one row of REAL ([`predict`]) into `out`, reusing its storage.
pub fn predict_into(real: &Row, params: &CalibrationParams, out: &mut Row) {
    out.clone_from(real);
    if let Some(f) = real.reference_f_g()
        && real.temp_c.is_finite()
    {
        out.u_v = params.constants_at(real.temp_c).signals_v(&f);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bins_comp::{Method, paper};

    #[test]
    fn prediction_is_t1_at_the_rows_temperature() {
        let params = paper::params(paper::two_range_model().expect("paper model"), Method::CoefficientCorrection);
        let mut row = Row { line: 2, t_s: 1.0, temp_c: -20.0, ..Row::default() };
        row.f_g = [Some(0.0), Some(0.6), Some(-0.8)];
        let unknown = Row { line: 3, t_s: 2.0, temp_c: 30.0, u_v: [1.0, 2.0, 3.0], ..Row::default() };
        let out = predict(&[row.clone(), unknown.clone()], &params);
        // Independent evaluation: U_i = U0_i(T) + Σ_j K_ij(T) f_j.
        let c = params.constants_at(-20.0);
        for i in 0..3 {
            let want = c.u0_v[i] + c.k_v_per_g[i][1] * 0.6 - c.k_v_per_g[i][2] * 0.8;
            assert!((out[0].u_v[i] - want).abs() < 1e-12, "{i}: {} vs {want}", out[0].u_v[i]);
        }
        // Other cells kept; rows without a reference untouched.
        assert_eq!((out[0].t_s, out[0].temp_c, out[0].f_g), (row.t_s, row.temp_c, row.f_g));
        assert_eq!(out[1].u_v, unknown.u_v);
        // At another temperature the prediction differs (the temperature model is applied).
        let c20 = params.constants_at(20.0);
        assert!((c20.u0_v[0] - c.u0_v[0]).abs() > 0.0 || (c20.k_v_per_g[0][0] - c.k_v_per_g[0][0]).abs() > 0.0);
    }
}
