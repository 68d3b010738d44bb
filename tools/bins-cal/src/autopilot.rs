//! A calibration's bias against temperature as autopilot parameters (`bins-cal export`,
//! `docs/logs.md`): PX4's `TC_A*` and ArduPilot's `INS_TCAL*`, each evaluated exactly as its
//! firmware evaluates it, in `f32`.
//!
//! Both autopilots correct an accelerometer's offset alone against temperature, subtracted
//! from the raw data before their own offset and scale calibration:
//!
//! - **PX4** (`src/modules/temperature_compensation/TemperatureCompensation.cpp`,
//!   `calc_thermal_offsets_3D`; applied in `src/lib/sensor_calibration/Accelerometer.hpp`,
//!   `Correct`: `R·((data − thermal_offset − offset) ∘ scale)`): per axis
//!   `offset = X0 + X1·Δ + X2·Δ² + X3·Δ³` \[m/s²\], `Δ = clamp(T, TMIN, TMAX) − TREF`, for the
//!   sensor whose `device_id` is `TC_An_ID`, when `TC_A_ENABLE` = 1.
//! - **ArduPilot** (`libraries/AP_InertialSensor/AP_InertialSensor_tempcal.cpp`,
//!   `correct_sensor`; applied in `AP_InertialSensor_Backend.cpp`,
//!   `_rotate_and_correct_accel`, before `INS_ACCOFFS`/`INS_ACCSCAL`):
//!   `v −= p(T − 35) − p(Tcal − 35)`, `p(d) = (ACC1 + (ACC2 + ACC3·d)·d)·d·10⁻⁶` \[m/s²\],
//!   `T` and `Tcal` (the temperature of the autopilot's own accelerometer calibration,
//!   `INS_ACCn_CALTEMP`) clamped to `[TMIN, TMAX]`, when `INS_TCALn_ENABLE` = 1.
//!
//! The calibration's bias is what its offset change does at zero input,
//! `b(T) = N·(U0(T) − U0(T0))` \[g\], with the temperature clamped to the calibrated range as
//! the core clamps it. `N` says what the autopilot's raw data are ([`Raw`]): the calibration's
//! own T0 acceleration (`N = K(T0)⁻¹`), or the recording's signals at the nominal 1 V/g of a
//! log imported by `bins-cal import` (`N = 1 g/V`). The exported polynomial is the
//! least-squares cubic of `b` over the range ([`fit_cubic`]): the bias itself where the
//! temperature model is a polynomial of order ≤ 3, an approximation (whose largest error is
//! said) otherwise. Scale factors and cross-axis terms against temperature, and thermal
//! dynamics, have no place in either autopilot's parameters: the export drops them.

use crate::fclog::G_M_S2;
use bins_comp::CalibrationParams;
use nalgebra::{Matrix4, Vector4};

/// What the autopilot's raw data are, in the calibration's terms.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Raw {
    /// The calibration's own acceleration at T0, `K(T0)⁻¹·(U − U0(T0))`: the offsets are in
    /// g of that acceleration (a unit whose autopilot applies the T0 constants).
    Calibrated,
    /// The recording's signals at 1 V/g, `U`: a log imported by `bins-cal import`, whose
    /// signals are the autopilot's own raw data (PX4 `sensor_accel`) or its published ones
    /// (ArduPilot `IMU`).
    Logged,
}

/// The bias `b(T)` \[g\] of the calibration at `temp_c` (clamped to its range): the change of
/// U0 from T0, through `N` of `raw`.
pub fn bias_g(p: &CalibrationParams, raw: Raw, temp_c: f64) -> [f64; 3] {
    let t = temp_c.clamp(p.temp_range_c.0, p.temp_range_c.1);
    let du = [0, 1, 2].map(|i| p.constants_at(t).u0_v[i] - p.constants.u0_v[i]);
    match raw {
        Raw::Logged => du,
        Raw::Calibrated => {
            let n = inverse(&p.constants.k_v_per_g);
            [0, 1, 2].map(|i| (0..3).map(|j| n[i][j] * du[j]).sum())
        }
    }
}

/// The inverse of a 3×3 matrix (the calibration's K, invertible by its validation).
fn inverse(k: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let m = nalgebra::Matrix3::from_fn(|i, j| k[i][j]);
    let n = m.try_inverse().unwrap_or_else(nalgebra::Matrix3::zeros);
    [0, 1, 2].map(|i| [0, 1, 2].map(|j| n[(i, j)]))
}

/// A cubic per axis in `Δ = T − tref_c`: `c[axis][k]` multiplies Δᵏ \[g/°Cᵏ\].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cubic {
    /// Reference temperature [°C].
    pub tref_c: f64,
    /// Coefficients per axis, Δ⁰ … Δ³.
    pub c: [[f64; 4]; 3],
}

impl Cubic {
    /// The value at `temp_c` \[g\], in `f64`.
    pub fn at(&self, temp_c: f64) -> [f64; 3] {
        let d = temp_c - self.tref_c;
        self.c.map(|c| c[0] + d * (c[1] + d * (c[2] + d * c[3])))
    }

    /// The same cubic around another reference temperature (binomial re-expansion).
    pub fn around(&self, tref_c: f64) -> Cubic {
        let s = tref_c - self.tref_c;
        let c = self.c.map(|a| {
            [
                a[0] + a[1] * s + a[2] * s * s + a[3] * s * s * s,
                a[1] + 2.0 * a[2] * s + 3.0 * a[3] * s * s,
                a[2] + 3.0 * a[3] * s,
                a[3],
            ]
        });
        Cubic { tref_c, c }
    }
}

/// Temperatures at which the cubic is fitted and its error measured over the range.
pub const FIT_POINTS: usize = 441;

/// The least-squares cubic of the bias over the calibration's range, around its middle, and
/// its largest error there \[g\] (rounding alone, ~1e-15 g, where the temperature model is a
/// polynomial of order ≤ 3).
pub fn fit_cubic(p: &CalibrationParams, raw: Raw) -> (Cubic, f64) {
    let (lo, hi) = p.temp_range_c;
    let (mid, half) = (0.5 * (lo + hi), 0.5 * (hi - lo));
    let temps: Vec<f64> = (0..FIT_POINTS).map(|k| lo + (hi - lo) * k as f64 / (FIT_POINTS - 1) as f64).collect();
    // A polynomial model of order below 3 is fitted with its own degree: the terms above it
    // are zero, not rounding noise.
    let degree = match p.model {
        bins_comp::TempModel::Poly { order, .. } => (order as usize).min(3),
        bins_comp::TempModel::Pwl { .. } => 3,
    };
    let mut c = [[0.0; 4]; 3];
    for (axis, ca) in c.iter_mut().enumerate() {
        // In s = (T − mid)/half ∈ [−1, 1]: normal equations of a well-conditioned basis
        // (the unused powers pinned to zero by a unit diagonal).
        let mut a = Matrix4::<f64>::zeros();
        let mut y = Vector4::<f64>::zeros();
        for &t in &temps {
            let s = (t - mid) / half;
            let x = Vector4::from_fn(|k, _| if k <= degree { s.powi(k as i32) } else { 0.0 });
            a += x * x.transpose();
            y += x * bias_g(p, raw, t)[axis];
        }
        for k in degree + 1..4 {
            a[(k, k)] = 1.0;
        }
        let sol = a.lu().solve(&y).unwrap_or_else(Vector4::zeros);
        for k in 0..4 {
            ca[k] = sol[k] / half.powi(k as i32);
        }
    }
    let cubic = Cubic { tref_c: mid, c };
    let err = temps
        .iter()
        .flat_map(|&t| {
            let (b, f) = (bias_g(p, raw, t), cubic.at(t));
            (0..3).map(move |i| (b[i] - f[i]).abs())
        })
        .fold(0.0, f64::max);
    (cubic, err)
}

/// The `TC_A*` parameters of one PX4 accelerometer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Px4 {
    /// `n` of `TC_An_*` (0 … 3).
    pub index: u8,
    /// `TC_An_ID`: the sensor's `device_id`.
    pub device_id: u32,
    /// `TC_An_TREF`, `TC_An_TMIN`, `TC_An_TMAX` [°C].
    pub tref_c: f32,
    /// `TC_An_TMIN` [°C].
    pub tmin_c: f32,
    /// `TC_An_TMAX` [°C].
    pub tmax_c: f32,
    /// `TC_An_Xk_i`: `x[k][i]` for axis i \[m/s²/°Cᵏ\].
    pub x: [[f32; 3]; 4],
}

impl Px4 {
    /// The parameters of the cubic `b` \[g\] (in m/s², around its own reference), valid over
    /// `range_c`.
    pub fn new(index: u8, device_id: u32, b: &Cubic, range_c: (f64, f64)) -> Px4 {
        let x = [0, 1, 2, 3].map(|k| [0, 1, 2].map(|i| (b.c[i][k] * G_M_S2) as f32));
        Px4 { index, device_id, tref_c: b.tref_c as f32, tmin_c: range_c.0 as f32, tmax_c: range_c.1 as f32, x }
    }

    /// The offset PX4 subtracts at `temp_c` \[m/s²\], as `calc_thermal_offsets_3D` computes it
    /// (`f32`, the temperature clipped to TMIN … TMAX).
    pub fn offset_m_s2(&self, temp_c: f32) -> [f32; 3] {
        let d = if temp_c > self.tmax_c {
            self.tmax_c - self.tref_c
        } else if temp_c < self.tmin_c {
            self.tmin_c - self.tref_c
        } else {
            temp_c - self.tref_c
        };
        let d2 = d * d;
        let d3 = d2 * d;
        [0, 1, 2].map(|i| self.x[0][i] + self.x[1][i] * d + self.x[2][i] * d2 + self.x[3][i] * d3)
    }

    /// The parameter file in QGroundControl's format (`vehicle component name value type`,
    /// tab-separated; type 6 = INT32, 9 = REAL32), values as the shortest decimal of the
    /// `f32` PX4 stores.
    pub fn params_text(&self, header: &[String]) -> String {
        let n = self.index;
        let mut s = String::new();
        for h in header {
            s.push_str(&format!("# {h}\n"));
        }
        s.push_str("#\n# Vehicle-Id Component-Id Name Value Type\n");
        let mut int = |name: String, v: i64| s.push_str(&format!("1\t1\t{name}\t{v}\t6\n"));
        int("TC_A_ENABLE".into(), 1);
        int(format!("TC_A{n}_ID"), self.device_id as i32 as i64);
        let mut real = |name: String, v: f32| s.push_str(&format!("1\t1\t{name}\t{v:?}\t9\n"));
        real(format!("TC_A{n}_TREF"), self.tref_c);
        real(format!("TC_A{n}_TMIN"), self.tmin_c);
        real(format!("TC_A{n}_TMAX"), self.tmax_c);
        for k in 0..4 {
            for i in 0..3 {
                real(format!("TC_A{n}_X{k}_{i}"), self.x[k][i]);
            }
        }
        s
    }
}

/// ArduPilot's fixed reference temperature of `INS_TCAL*` [°C] (`TEMP_REFERENCE`).
pub const ARDUPILOT_TREF_C: f64 = 35.0;
/// ArduPilot's scale of the `INS_TCAL*_ACC*` parameters (`SCALE_FACTOR`).
pub const ARDUPILOT_SCALE: f64 = 1.0e6;

/// The `INS_TCAL*` parameters of one ArduPilot IMU.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ArduPilot {
    /// `n` of `INS_TCALn_*` (1 … 3: IMU instance + 1).
    pub imu: u8,
    /// `INS_TCALn_TMIN` [°C].
    pub tmin_c: f32,
    /// `INS_TCALn_TMAX` [°C].
    pub tmax_c: f32,
    /// `INS_TCALn_ACCk_{X,Y,Z}`: `acc[k-1][i]` \[10⁻⁶ m/s²/°Cᵏ\].
    pub acc: [[f32; 3]; 3],
}

impl ArduPilot {
    /// The parameters of the cubic `b` \[g\]: `p(d) = b(35 + d) − b(35)` in m/s², so that
    /// `p(T − 35) − p(Tcal − 35) = b(T) − b(Tcal)` whatever the temperature of the
    /// autopilot's own calibration.
    pub fn new(imu: u8, b: &Cubic, range_c: (f64, f64)) -> ArduPilot {
        let at = b.around(ARDUPILOT_TREF_C);
        let acc = [1, 2, 3].map(|k| [0, 1, 2].map(|i| (at.c[i][k] * G_M_S2 * ARDUPILOT_SCALE) as f32));
        ArduPilot { imu, tmin_c: range_c.0 as f32, tmax_c: range_c.1 as f32, acc }
    }

    /// `polynomial_eval` \[m/s²\] (`f32`).
    fn poly(&self, d: f32) -> [f32; 3] {
        let c = &self.acc;
        [0, 1, 2].map(|i| (c[0][i] + (c[1][i] + c[2][i] * d) * d) * d * (1.0e-6_f64 as f32))
    }

    /// What ArduPilot subtracts at `temp_c` from an accelerometer calibrated at `cal_temp_c`
    /// \[m/s²\], as `correct_sensor` computes it (`f32`, both clamped to TMIN … TMAX).
    pub fn correction_m_s2(&self, temp_c: f32, cal_temp_c: f32) -> [f32; 3] {
        let t = temp_c.clamp(self.tmin_c, self.tmax_c);
        let tc = cal_temp_c.clamp(self.tmin_c, self.tmax_c);
        let r = ARDUPILOT_TREF_C as f32;
        let (a, b) = (self.poly(t - r), self.poly(tc - r));
        [0, 1, 2].map(|i| a[i] - b[i])
    }

    /// The parameter file as MAVProxy and Mission Planner load it (`NAME,VALUE`, `#`
    /// comments), values as the shortest decimal of the `f32` ArduPilot stores.
    pub fn params_text(&self, header: &[String]) -> String {
        let n = self.imu;
        let mut s = String::new();
        for h in header {
            s.push_str(&format!("# {h}\n"));
        }
        s.push_str(&format!("INS_TCAL{n}_ENABLE,1\n"));
        s.push_str(&format!("INS_TCAL{n}_TMIN,{:?}\n", self.tmin_c));
        s.push_str(&format!("INS_TCAL{n}_TMAX,{:?}\n", self.tmax_c));
        for k in 0..3 {
            for (i, axis) in ["X", "Y", "Z"].iter().enumerate() {
                s.push_str(&format!("INS_TCAL{n}_ACC{}_{axis},{:?}\n", k + 1, self.acc[k][i]));
            }
        }
        s
    }
}
