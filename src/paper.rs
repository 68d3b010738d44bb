//! The temperature paper's unit: Tables T1/T2 (constants at −40, +20, +70 °C) and Table T3
//! (its two-range temperature coefficients), plus the calibrations the demo and the firmware
//! test vectors build from them. Values are copied digit for digit from the paper; the host
//! tests cross-check them against `data/paper-constants.csv`.

use crate::compensate::{Calibration, CalibrationError, CalibrationParams, Method};
use crate::float::Float;
use crate::ident;
use crate::model::Constants;
use crate::temperature::{CoefDelta, TempModel};

/// T0, the "normal conditions" calibration temperature [°C].
pub const T0_C: f64 = 20.0;
/// Calibration temperatures of Tables T1/T2 [°C], in table order.
pub const TABLE_TEMPS_C: [f64; 3] = [20.0, -40.0, 70.0];
/// Check temperatures of the paper's experiment [°C].
pub const CHECK_TEMPS_C: [f64; 2] = [-10.0, 45.0];

/// Tables T1/T2: the 12 constants at each of [`TABLE_TEMPS_C`].
pub const TABLE_CONSTANTS: [Constants<f64>; 3] = [
    Constants {
        k_v_per_g: [
            [-0.55060863, -0.00051742, 0.01639328],
            [-0.01322881, -0.54854890, -0.00066841],
            [-0.01466957, -0.00035441, -0.54859224],
        ],
        u0_v: [0.00449084, -0.00442299, -0.00347099],
    },
    Constants {
        k_v_per_g: [
            [-0.55074263, -0.00038930, 0.01602241],
            [-0.01277214, -0.54790681, -0.00074432],
            [-0.01433019, -0.00023161, -0.54832201],
        ],
        u0_v: [0.01181219, 0.00057544, 0.00041269],
    },
    Constants {
        k_v_per_g: [
            [-0.55140269, -0.00042829, 0.01652937],
            [-0.01364519, -0.54933059, -0.00068396],
            [-0.01478830, -0.00027167, -0.54979681],
        ],
        u0_v: [0.00359778, -0.00643609, -0.00223732],
    },
];

/// Table T3 as printed: `(low, high)` slopes for −40…+20 °C and +20…+70 °C, in the order
/// β_xx, β_yy, β_zz [1/°C], α_x, α_y, α_z [V/°C], γ_xy, γ_xz, γ_yx, γ_yz, γ_zx, γ_zy [1/°C].
pub const TABLE_T3: [(f64, f64); 12] = [
    (-0.00000406, 0.00002884),
    (0.00001951, 0.00002850),
    (0.00000821, 0.00004391),
    (-0.00012202, -0.00001786),
    (-0.00008331, -0.00004026),
    (-0.00006473, 0.00002467),
    (0.00412678, -0.00344515),
    (0.00037706, 0.00016603),
    (0.00057535, 0.00062950),
    (-0.00189274, 0.00046547),
    (0.00038558, 0.00016187),
    (0.00577492, -0.00466918),
];

/// The paper's calibrated temperature range [°C].
pub const TEMP_RANGE_C: (f64, f64) = (-40.0, 70.0);

/// The constants at −40 and +70 °C paired with their temperatures.
pub fn off_nominal_points() -> [(f64, Constants<f64>); 2] {
    [(TABLE_TEMPS_C[1], TABLE_CONSTANTS[1]), (TABLE_TEMPS_C[2], TABLE_CONSTANTS[2])]
}

/// The paper's calibration: the two-range piecewise-linear model T(4)/T(12) (knots −40, +20,
/// +70 °C) identified from Tables T1/T2.
pub fn two_range_model() -> Result<TempModel<f64>, ident::FitError> {
    ident::pwl_from_constants(T0_C, &TABLE_CONSTANTS[0], &off_nominal_points())
}

/// The quadratic in T through Tables T1/T2 (T(11) with order 2, exact through the three
/// temperatures): the demo's stand-in for the unit's true temperature behaviour.
pub fn quadratic_truth() -> Result<TempModel<f64>, ident::FitError> {
    ident::poly_from_constants(T0_C, &TABLE_CONSTANTS[0], &off_nominal_points(), 2)
}

/// The parameters of a calibration of the paper's unit with the given model and method.
pub fn params(model: TempModel<f64>, method: Method) -> CalibrationParams {
    CalibrationParams { constants: TABLE_CONSTANTS[0], t0_c: T0_C, model, method, temp_range_c: TEMP_RANGE_C }
}

/// A validated calibration of the paper's unit with the given model and method.
pub fn calibration<F: Float>(model: TempModel<f64>, method: Method) -> Result<Calibration<F>, CalibrationError> {
    Calibration::new(&params(model, method))
}

/// [`quadratic_truth`] made order 3 by a small cubic term (each cubic coefficient 10⁻³ of
/// the quadratic one, per °C), so the evaluation of an order-3 model has its full
/// length: the benchmarks' "order-3 polynomial" case.
pub fn order3_model() -> Result<TempModel<f64>, ident::FitError> {
    match quadratic_truth()? {
        TempModel::Poly { mut coef, .. } => {
            let c3 = coef[1].to_array().map(|c| c * 1e-3);
            coef[2] = CoefDelta::from_array(&c3);
            Ok(TempModel::Poly { order: 3, coef })
        }
        other => Ok(other),
    }
}
