//! The vibration paper's data: the AL-15 accelerometer's conversion function (Table V1), the
//! harmonic (Table V2) and broadband random (Table V3) flight vibration of GOST 20.39.304-98,
//! and a set of flight-phase profiles built from them. Values are copied from the paper; the
//! host tests cross-check Table V1 against `shared/data/al15-coefficients.csv`.

use super::{ConversionFunction, MAX_PROFILES, Vibration};

/// Table V1: the AL-15's scale factor `K1` [V/g] (V(1): `a_u = U/K1`).
pub const AL15_K1_V_PER_G: f64 = -1.6698;

/// Table V1: the AL-15's conversion function V(2) in g units (a0 = 3.324 mg, δ_1A = 15 ppm,
/// k2…k5 = 105, 87, 10, 0.9 µg/gⁿ, m1 = m2 = 1.15 mg/g, m31 = m32 = 11.6 µg/g²).
pub const AL15: ConversionFunction<f64> = ConversionFunction {
    a0_g: 3.324e-3,
    delta_1a: 15e-6,
    k2_g_per_g2: 105e-6,
    k3_g_per_g3: 87e-6,
    k4_g_per_g4: 10e-6,
    k5_g_per_g5: 0.9e-6,
    m1_g_per_g: 1.15e-3,
    m2_g_per_g: 1.15e-3,
    m31_g_per_g2: 11.6e-6,
    m32_g_per_g2: 11.6e-6,
};

/// One row of Table V2: harmonic vibration in autonomous flight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HarmonicRow {
    /// True for the longitudinal (X) direction, false for transverse (Y, Z).
    pub longitudinal: bool,
    /// Angular frequency range ω [1/s].
    pub omega_per_s: (f64, f64),
    /// Amplitude range \[g\].
    pub amp_g: (f64, f64),
    /// Duration \[s\].
    pub duration_s: f64,
}

/// Table V2.
pub const TABLE_V2: [HarmonicRow; 4] = [
    HarmonicRow { longitudinal: true, omega_per_s: (50.24, 100.48), amp_g: (0.42, 0.42), duration_s: 100.0 },
    HarmonicRow { longitudinal: true, omega_per_s: (12.56, 25.12), amp_g: (0.1, 0.2), duration_s: 100.0 },
    HarmonicRow { longitudinal: false, omega_per_s: (25.12, 50.24), amp_g: (0.2, 0.8), duration_s: 100.0 },
    HarmonicRow { longitudinal: false, omega_per_s: (50.24, 100.48), amp_g: (0.8, 1.5), duration_s: 100.0 },
];

/// One row of Table V3: broadband random vibration (duration 640 s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RandomRow {
    /// Band (f_low, f_up) \[Hz\].
    pub band_hz: (f64, f64),
    /// Spectral density range S_B [g²/Hz].
    pub psd_g2_per_hz: (f64, f64),
}

/// Table V3.
pub const TABLE_V3: [RandomRow; 5] = [
    RandomRow { band_hz: (20.0, 40.0), psd_g2_per_hz: (0.016, 0.017) },
    RandomRow { band_hz: (40.0, 80.0), psd_g2_per_hz: (0.017, 0.020) },
    RandomRow { band_hz: (80.0, 160.0), psd_g2_per_hz: (0.020, 0.070) },
    RandomRow { band_hz: (160.0, 320.0), psd_g2_per_hz: (0.070, 0.120) },
    RandomRow { band_hz: (320.0, 640.0), psd_g2_per_hz: (0.120, 0.120) },
];

/// Flight-phase profiles built from Tables V2/V3 at the upper end of each range (the worst
/// case), the unit's x axis longitudinal:
///
/// - 0: harmonic, ω = 100.48 1/s, X 0.42 g, Y and Z 1.5 g (Table V4's case at its upper end);
/// - 1: harmonic, ω = 25.12 1/s, X 0.2 g, Y and Z 0.8 g;
/// - 2 to 6: random, each band of Table V3 at its highest density, the same on every axis.
///
/// Returns the table and the number of profiles used (7).
pub fn flight_profiles() -> ([Vibration<f64>; MAX_PROFILES], u8) {
    let mut out = [Vibration::None; MAX_PROFILES];
    let omega_to_hz = |w: f64| w / (2.0 * core::f64::consts::PI);
    out[0] = Vibration::Harmonic { amp_g: [0.42, 1.5, 1.5], freq_hz: omega_to_hz(100.48) };
    out[1] = Vibration::Harmonic { amp_g: [0.2, 0.8, 0.8], freq_hz: omega_to_hz(25.12) };
    for (slot, row) in out.iter_mut().skip(2).zip(TABLE_V3.iter()) {
        let s = row.psd_g2_per_hz.1;
        *slot = Vibration::random_from_psd([s, s, s], row.band_hz);
    }
    (out, 7)
}
