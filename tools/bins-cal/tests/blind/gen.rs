//! Blind case generator: SIM/REAL recording pairs with concealed mechanisms (none, one, or
//! 2–3 at once in the combined mode),
//! written from `physics.md` without any of the library's code (no `bins_cal::diagnose`, no
//! `bins_cal::sim`, no core formulas): its own 12-constant unit, its own temperature model,
//! its own forms of every mechanism, deliberately different in detail from the regressors the
//! diagnosis fits (second-order thermal lag, a two-exponential warm-up, quartic or exponential
//! bias terms, quadratic cross-coupling tempcos, a rotation of the input, …).
//!
//! SIM is the ideal temperature model evaluated at the thermistor reading; REAL is the same unit
//! at the true temperature, plus the concealed mechanisms' contributions (summed), plus white
//! noise and optionally a random walk of the bias. Every draw comes from ChaCha8 streams seeded
//! by the case seed (a single-mechanism case draws exactly what it drew before the combined mode
//! existed: the combined mode and the extra members use streams of their own).

use bins_cal::recording::{Row, VibKind};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Reference temperature of the unit's temperature model [°C] (not the library's 20 °C).
pub const T_REF_C: f64 = 25.0;

/// Thermistor white noise [°C].
pub const THERMISTOR_SIGMA_C: f64 = 0.003;

/// Least displacement \[°C\] of a lag's or a play's temperature from the die's that counts as
/// the mechanism acting. A play the profile never engages, or a lag of a die that does not
/// move, displaces the sensing element by the die's residual drift alone (tens of µ°C on a soak
/// long after power-on); scaled up to a drawn size, that would be a tempco thousands of times
/// the unit's, so such a member contributes nothing and is not visible.
pub const MIN_DISPLACEMENT_C: f64 = 1e-3;

/// Mechanism ids the generator can conceal (the library's ids).
pub const MECH_IDS: [&str; 13] = [
    "thermal_lag",
    "thermal_hysteresis",
    "bias_hysteresis",
    "self_heating",
    "warmup",
    "bias_temp_order",
    "scale_temp",
    "cross_coupling_temp",
    "cross_axis",
    "scale_factor",
    "sf_asymmetry",
    "nonlinearity_k2",
    "nonlinearity_k3",
];

/// The concealed mechanism and its physical parameters (before scaling to the drawn size).
#[derive(Clone, Debug, PartialEq)]
pub enum Mech {
    /// Nothing concealed.
    None,
    /// The sensing element follows the thermistor through two cascaded first-order stages.
    ThermalLag {
        /// First (case) stage time constant \[s\].
        tau1_s: f64,
        /// Second (die) stage time constant \[s\].
        tau2_s: f64,
    },
    /// The temperature reaching the sensitivity goes through a play (backlash).
    ThermalHysteresis {
        /// Play width [°C].
        width_c: f64,
    },
    /// An additive bias play: `a_i·(play_w(T) − T)/(w/2)`, not through the sensitivity.
    BiasHysteresis {
        /// Play width [°C].
        width_c: f64,
    },
    /// The die heats after power-on: `T + rise·(1 − 0.8 e^(−P/τ) − 0.2 e^(−4P/τ))`.
    SelfHeating {
        /// Main time constant \[s\].
        tau_s: f64,
    },
    /// Turn-on bias transient: `A_i·(0.65 e^(−P/τ) + 0.35 e^(−6P/τ))`.
    Warmup {
        /// Main time constant \[s\].
        tau_s: f64,
    },
    /// A bias temperature term of a shape SIM lacks.
    BiasTempOrder {
        /// 0: quadratic, 1: cubic, 2: quartic, 3: `e^(ΔT/θ)`.
        shape: u8,
        /// θ of the exponential [°C].
        theta_c: f64,
    },
    /// Scale-factor tempco `f_i·(s1 ΔT + s2 ΔT²)` with a random mix of the two.
    ScaleTemp {
        /// Weight of the quadratic term (0 = linear only).
        quad_mix: f64,
    },
    /// Cross-sensitivity tempco `f_j·ΔT` (linear) or `f_j·ΔT²` (quadratic).
    CrossCouplingTemp {
        /// Quadratic in ΔT.
        quadratic: bool,
    },
    /// Misalignment: the input is rotated and skewed, `f' = (I + E) f`, E off-diagonal.
    CrossAxis,
    /// Scale factor error `ε f_i`.
    ScaleFactor,
    /// Scale-factor asymmetry, static part `0.5 δ |f_i|`.
    SfAsymmetry,
    /// Second-order nonlinearity `k2 f_i²`.
    K2,
    /// Third-order nonlinearity `k3 f_i³`.
    K3,
}

impl Mech {
    /// The library id, or `none`.
    pub fn id(&self) -> &'static str {
        match self {
            Mech::None => "none",
            Mech::ThermalLag { .. } => "thermal_lag",
            Mech::ThermalHysteresis { .. } => "thermal_hysteresis",
            Mech::BiasHysteresis { .. } => "bias_hysteresis",
            Mech::SelfHeating { .. } => "self_heating",
            Mech::Warmup { .. } => "warmup",
            Mech::BiasTempOrder { .. } => "bias_temp_order",
            Mech::ScaleTemp { .. } => "scale_temp",
            Mech::CrossCouplingTemp { .. } => "cross_coupling_temp",
            Mech::CrossAxis => "cross_axis",
            Mech::ScaleFactor => "scale_factor",
            Mech::SfAsymmetry => "sf_asymmetry",
            Mech::K2 => "nonlinearity_k2",
            Mech::K3 => "nonlinearity_k3",
        }
    }

    /// Parameters as text (units in the names).
    pub fn params(&self) -> String {
        match self {
            Mech::ThermalLag { tau1_s, tau2_s } => format!("tau1_s={tau1_s:.0} tau2_s={tau2_s:.0}"),
            Mech::ThermalHysteresis { width_c } | Mech::BiasHysteresis { width_c } => {
                format!("width_c={width_c:.2}")
            }
            Mech::SelfHeating { tau_s } | Mech::Warmup { tau_s } => format!("tau_s={tau_s:.0}"),
            Mech::BiasTempOrder { shape, theta_c } => match *shape {
                0 => "shape=dT2".into(),
                1 => "shape=dT3".into(),
                2 => "shape=dT4".into(),
                _ => format!("shape=exp theta_c={theta_c:.1}"),
            },
            Mech::ScaleTemp { quad_mix } => format!("quad_mix={quad_mix:.2}"),
            Mech::CrossCouplingTemp { quadratic } => {
                if *quadratic {
                    "quadratic".into()
                } else {
                    "linear".into()
                }
            }
            _ => String::new(),
        }
    }

    fn needs_temperature_change(&self) -> bool {
        matches!(
            self,
            Mech::ThermalLag { .. }
                | Mech::ThermalHysteresis { .. }
                | Mech::BiasHysteresis { .. }
                | Mech::BiasTempOrder { .. }
                | Mech::ScaleTemp { .. }
                | Mech::CrossCouplingTemp { .. }
        )
    }

    fn needs_positions(&self) -> bool {
        matches!(
            self,
            Mech::ScaleTemp { .. }
                | Mech::CrossCouplingTemp { .. }
                | Mech::CrossAxis
                | Mech::ScaleFactor
                | Mech::SfAsymmetry
                | Mech::K2
                | Mech::K3
        )
    }

    fn needs_power_on(&self) -> bool {
        matches!(self, Mech::SelfHeating { .. } | Mech::Warmup { .. })
    }

    /// One scale for the three accelerometers (the mechanism acts through the common
    /// temperature), rather than an amplitude per accelerometer.
    fn common(&self) -> bool {
        matches!(self, Mech::ThermalLag { .. } | Mech::ThermalHysteresis { .. } | Mech::SelfHeating { .. })
    }
}

/// Thermal profile of the unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Profile {
    /// Constant temperature (chamber regulation wander of ±0.05 °C).
    Constant,
    /// Ramps between two levels with holds, at 1–3 rates.
    RampsHolds {
        /// Number of rates.
        rates: u8,
    },
    /// Triangle(s) without holds.
    Triangle,
    /// Chamber sweep ~50 → −20 → 70 → 35 °C, unit lagging the chamber.
    Sweep,
}

impl Profile {
    /// Name for the tables.
    pub fn name(&self) -> String {
        match self {
            Profile::Constant => "constant".into(),
            Profile::RampsHolds { rates } => format!("ramps{rates}"),
            Profile::Triangle => "triangle".into(),
            Profile::Sweep => "sweep".into(),
        }
    }
}

/// Rig positions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Positions {
    /// One orientation for the whole record.
    One,
    /// The six tilter positions TP1..TP6, cycled.
    Six,
    /// TP1..TP6 and six tilted check positions, cycled.
    Tilted,
}

impl Positions {
    /// Name for the tables.
    pub fn name(&self) -> &'static str {
        match self {
            Positions::One => "one",
            Positions::Six => "six",
            Positions::Tilted => "tilted",
        }
    }
}

/// One blind case: every draw.
#[derive(Clone, Debug)]
pub struct Case {
    /// Seed (the case is a function of it alone).
    pub seed: u64,
    /// Concealed mechanism.
    pub mech: Mech,
    /// Drawn effect size: RMS (about its mean) of the contribution on the strongest
    /// accelerometer, in units of the white noise σ.
    pub size_sigma: f64,
    /// Relative size on each accelerometer (max 1; 0 = not applied).
    pub axis_weight: [f64; 3],
    /// White noise σ \[µg\].
    pub sigma_ug: f64,
    /// Random walk of the bias: its standard deviation at the end of the record in units of σ
    /// (0 = off).
    pub rw_ratio: f64,
    /// Thermal profile.
    pub profile: Profile,
    /// Positions.
    pub positions: Positions,
    /// Whether the recordings carry `power_s`.
    pub power_column: bool,
    /// Power-on times \[s\] (the record starts `power_offset_s` after the first power-on when it
    /// is not 0).
    pub power_on_s: Vec<f64>,
    /// `power_s` at the first row \[s\].
    pub power_offset_s: f64,
    /// Rows.
    pub rows: usize,
    /// Sample rate \[Hz\].
    pub rate_hz: f64,
    /// Dwell per position \[s\].
    pub dwell_s: f64,
    /// Temperature at which the concealed tempco terms (`scale_temp`, `cross_coupling_temp`,
    /// `bias_temp_order`) vanish [°C]: SIM's calibration temperature [`T_REF_C`] unless
    /// `BLIND_ANCHOR_C` says otherwise (20 °C = the library's own reference).
    pub anchor_c: f64,
    /// Further concealed mechanisms acting at the same time (combined cases; empty in the
    /// single-mechanism mode). `mech`, `size_sigma` and `axis_weight` are the first member.
    pub extra: Vec<Member>,
    /// A test profile drawn the way users record, independently of the concealed members
    /// ([`Case::draw_user`]): sessions, power-ons and the unit's thermal path. `None`: the
    /// profile above, drawn so that every member can be seen.
    pub user: Option<UserPlan>,
}

/// One concealed mechanism of a case, with its size and where it acts.
#[derive(Clone, Debug, PartialEq)]
pub struct Member {
    /// The mechanism.
    pub mech: Mech,
    /// Effect size: RMS (about its mean) of its contribution on its strongest accelerometer,
    /// in units of the white noise σ.
    pub size_sigma: f64,
    /// Relative size on each accelerometer (max 1; 0 = not applied).
    pub axis_weight: [f64; 3],
}

/// How the sizes of a combined case are drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SizeDraw {
    /// Per-sample size log-uniform 0.5–20 σ, random walk on with probability 0.4 (the
    /// scorecard).
    PerSample,
    /// Record-length-aware size `z = size_sigma·√rows` log-uniform in `lo`–`hi`, white noise
    /// only (the detectability curves).
    Snr {
        /// Lowest z.
        lo: f64,
        /// Highest z.
        hi: f64,
    },
}

/// The anchor of the concealed tempco terms: `BLIND_ANCHOR_C` or [`T_REF_C`].
pub fn anchor_c() -> f64 {
    std::env::var("BLIND_ANCHOR_C").ok().and_then(|v| v.parse().ok()).unwrap_or(T_REF_C)
}

fn log_uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    (lo.ln() + rng.random::<f64>() * (hi.ln() - lo.ln())).exp()
}

fn mech_of(id: &str, rng: &mut ChaCha8Rng) -> Mech {
    match id {
        "thermal_lag" => {
            let tau1_s = log_uniform(rng, 30.0, 600.0);
            Mech::ThermalLag { tau1_s, tau2_s: tau1_s * rng.random_range(0.1..0.4) }
        }
        "thermal_hysteresis" => Mech::ThermalHysteresis { width_c: rng.random_range(0.5..6.0) },
        "bias_hysteresis" => Mech::BiasHysteresis { width_c: rng.random_range(0.5..6.0) },
        "self_heating" => Mech::SelfHeating { tau_s: log_uniform(rng, 120.0, 1500.0) },
        "warmup" => Mech::Warmup { tau_s: log_uniform(rng, 120.0, 1500.0) },
        "bias_temp_order" => {
            Mech::BiasTempOrder { shape: rng.random_range(0..4), theta_c: rng.random_range(15.0..40.0) }
        }
        "scale_temp" => Mech::ScaleTemp { quad_mix: if rng.random_bool(0.5) { 0.0 } else { rng.random::<f64>() } },
        "cross_coupling_temp" => Mech::CrossCouplingTemp { quadratic: rng.random_bool(0.5) },
        "cross_axis" => Mech::CrossAxis,
        "scale_factor" => Mech::ScaleFactor,
        "sf_asymmetry" => Mech::SfAsymmetry,
        "nonlinearity_k2" => Mech::K2,
        "nonlinearity_k3" => Mech::K3,
        _ => Mech::None,
    }
}

impl Case {
    /// Every concealed mechanism (none for a null).
    pub fn members(&self) -> Vec<Member> {
        let mut v = Vec::new();
        if self.mech != Mech::None {
            v.push(Member { mech: self.mech.clone(), size_sigma: self.size_sigma, axis_weight: self.axis_weight });
        }
        v.extend(self.extra.iter().cloned());
        v
    }

    /// Record-length-aware size of a per-sample size: `size_sigma·√rows`, the signal-to-noise
    /// ratio a fit of the contribution's known shape would reach in white noise.
    pub fn snr(&self, size_sigma: f64) -> f64 {
        size_sigma * (self.rows as f64).sqrt()
    }

    /// Draws a combined case from its seed (a stream of its own, unrelated to [`Case::draw`]'s):
    /// 2 or 3 distinct mechanisms drawn uniformly among the 13, each with its own size and
    /// accelerometers, a profile, positions and power-ons every member can be seen in.
    pub fn draw_combined(seed: u64, sizes: SizeDraw) -> Case {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xC0B1_7ED5_B11D);
        let k = rng.random_range(2..=3);
        let mut ids: Vec<&str> = MECH_IDS.to_vec();
        let mut mechs = Vec::new();
        for _ in 0..k {
            let id = ids.remove(rng.random_range(0..ids.len()));
            mechs.push(mech_of(id, &mut rng));
        }
        let mut c = Self::draw_rest_of(seed, &mechs, &mut rng);
        match sizes {
            SizeDraw::PerSample => {}
            SizeDraw::Snr { lo, hi } => {
                c.rw_ratio = 0.0;
                let root_n = (c.rows as f64).sqrt();
                c.size_sigma = log_uniform(&mut rng, lo, hi) / root_n;
                for m in &mut c.extra {
                    m.size_sigma = log_uniform(&mut rng, lo, hi) / root_n;
                }
            }
        }
        c
    }

    /// Draws a case from its seed: mechanism or none (27 %), size 0.5–20 σ (log-uniform), a
    /// thermal profile and positions the mechanism can be seen in, random walk on or off, σ
    /// 5–500 µg, 3 000–12 000 rows at 0.5–2 Hz.
    pub fn draw(seed: u64) -> Case {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5EED_B11D);
        let mech = if rng.random_bool(0.27) {
            Mech::None
        } else {
            let id = MECH_IDS[rng.random_range(0..MECH_IDS.len())];
            mech_of(id, &mut rng)
        };
        Self::draw_rest_of(seed, &[mech], &mut rng)
    }

    /// Draws a case with a given mechanism id (`none` for a null).
    pub fn draw_with(seed: u64, id: &str) -> Case {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5EED_B11D);
        let mech = mech_of(id, &mut rng);
        Self::draw_rest_of(seed, &[mech], &mut rng)
    }

    /// Draws a combined case with the given mechanism ids (sizes 0.5–20 σ as drawn; the caller
    /// may set them).
    pub fn draw_combined_with(seed: u64, ids: &[&str]) -> Case {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xC0B1_7ED5_B11D);
        let mechs: Vec<Mech> = ids.iter().map(|id| mech_of(id, &mut rng)).collect();
        Self::draw_rest_of(seed, &mechs, &mut rng)
    }

    /// The rest of a case for the mechanisms `mechs` (the first is `mech`, the others `extra`):
    /// for one mechanism this draws, in the same order, what the single-mechanism mode always
    /// drew; the extra members' sizes and accelerometers are drawn last.
    fn draw_rest_of(seed: u64, mechs: &[Mech], rng: &mut ChaCha8Rng) -> Case {
        let mech = mechs[0].clone();
        let any = |f: fn(&Mech) -> bool| mechs.iter().any(f);
        let size_sigma = log_uniform(rng, 0.5, 20.0);
        let profile = if any(Mech::needs_temperature_change) || rng.random_bool(0.8) {
            match rng.random_range(0..3) {
                0 => Profile::RampsHolds { rates: rng.random_range(1..=3) },
                1 => Profile::Triangle,
                _ => Profile::Sweep,
            }
        } else {
            Profile::Constant
        };
        let positions = match mech {
            _ if any(|m| *m == Mech::K3) => Positions::Tilted,
            _ if any(Mech::needs_positions) => {
                if rng.random_bool(0.5) {
                    Positions::Six
                } else {
                    Positions::Tilted
                }
            }
            _ => match rng.random_range(0..3) {
                0 => Positions::One,
                1 => Positions::Six,
                _ => Positions::Tilted,
            },
        };
        let rows: usize = rng.random_range(3000..=12000);
        let rate_hz = [0.5, 1.0, 2.0][rng.random_range(0..3)];
        let dur = rows as f64 / rate_hz;
        let dwell_s = rng.random_range(30.0..240.0_f64).min(dur / 24.0);
        // Power: turn-on mechanisms get 2–3 power-ons; otherwise half the cases carry a
        // `power_s` column (a third of those with power-ons inside the record).
        let (power_column, power_on_s, power_offset_s) = if any(Mech::needs_power_on) {
            let n = rng.random_range(2..=3);
            (true, power_ons(rng, dur, n), 0.0)
        } else if rng.random_bool(0.5) {
            if rng.random_bool(1.0 / 3.0) {
                let n = rng.random_range(2..=3);
                (true, power_ons(rng, dur, n), 0.0)
            } else {
                let off = if rng.random_bool(0.3) { 0.0 } else { rng.random_range(600.0..7200.0) };
                (true, vec![0.0], off)
            }
        } else {
            (false, vec![0.0], 0.0)
        };
        let rw_ratio = if rng.random_bool(0.4) { log_uniform(rng, 0.5, 3.0) } else { 0.0 };
        let sigma_ug = log_uniform(rng, 5.0, 500.0);
        let axis_weight = draw_axis_weight(&mech, rng);
        let size_sigma = if mech == Mech::None { 0.0 } else { size_sigma };
        let extra = mechs[1..]
            .iter()
            .map(|m| {
                let size_sigma = log_uniform(rng, 0.5, 20.0);
                Member { mech: m.clone(), size_sigma, axis_weight: draw_axis_weight(m, rng) }
            })
            .collect();
        Case {
            seed,
            mech,
            size_sigma,
            axis_weight,
            sigma_ug,
            rw_ratio,
            profile,
            positions,
            power_column,
            power_on_s,
            power_offset_s,
            rows,
            rate_hz,
            dwell_s,
            anchor_c: anchor_c(),
            extra,
            user: None,
        }
    }
}

/// Where a mechanism acts: the thermal ones on the three accelerometers with one scale, the
/// others on one accelerometer at full size and on each other one with probability 1/3 at
/// 0.3–1 of it.
fn draw_axis_weight(mech: &Mech, rng: &mut ChaCha8Rng) -> [f64; 3] {
    let mut axis_weight = [0.0; 3];
    if mech.common() {
        axis_weight = [1.0; 3];
    } else if *mech != Mech::None {
        let main = rng.random_range(0..3);
        for i in 0..3 {
            axis_weight[i] = if i == main {
                1.0
            } else if rng.random_bool(1.0 / 3.0) {
                rng.random_range(0.3..1.0)
            } else {
                0.0
            };
        }
    }
    axis_weight
}

fn power_ons(rng: &mut ChaCha8Rng, dur: f64, n: usize) -> Vec<f64> {
    // First at 0, the others spread so each run lasts at least a fifth of the record.
    let mut v = vec![0.0];
    let span = dur / n as f64;
    for k in 1..n {
        v.push(span * (k as f64 + rng.random_range(-0.2..0.2)));
    }
    v
}

/// The unit's constants and temperature model (SIM's "passport" and tempcos).
#[derive(Clone, Debug)]
struct Unit {
    /// K [V/g] (rows: accelerometer, columns: input axis).
    k: [[f64; 3]; 3],
    /// U0 \[V\].
    u0: [f64; 3],
    /// Bias tempco in g: `b1 ΔT + b2 ΔT² + b3 ΔT³` per accelerometer.
    bias: [[f64; 3]; 3],
    /// Relative scale tempco `s1 ΔT + s2 ΔT²`.
    scale: [[f64; 2]; 3],
    /// Relative cross-sensitivity tempco (linear).
    cross: [[f64; 3]; 3],
}

fn sym(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    let v = log_uniform(rng, lo, hi);
    if rng.random_bool(0.5) { v } else { -v }
}

impl Unit {
    fn draw(rng: &mut ChaCha8Rng) -> Unit {
        let mut k = [[0.0; 3]; 3];
        let mut u0 = [0.0; 3];
        let mut bias = [[0.0; 3]; 3];
        let mut scale = [[0.0; 2]; 3];
        let mut cross = [[0.0; 3]; 3];
        for i in 0..3 {
            k[i][i] = sym(rng, 0.4, 1.5);
            u0[i] = rng.random_range(-0.01..0.01);
            bias[i] = [sym(rng, 10e-6, 200e-6), sym(rng, 0.05e-6, 2e-6), sym(rng, 2e-9, 30e-9)];
            scale[i] = [sym(rng, 2e-6, 50e-6), sym(rng, 0.02e-6, 0.5e-6)];
            for j in 0..3 {
                if j != i {
                    k[i][j] = k[i][i] * sym(rng, 1e-4, 2e-2);
                    cross[i][j] = sym(rng, 1e-5, 3e-3);
                }
            }
        }
        Unit { k, u0, bias, scale, cross }
    }

    /// Signals \[V\] at temperature `temp_c` for the specific force `f` \[g\] (T(1), T(3)).
    fn signals(&self, temp_c: f64, f: &[f64; 3]) -> [f64; 3] {
        let d = temp_c - T_REF_C;
        let mut u = [0.0; 3];
        for i in 0..3 {
            let b = &self.bias[i];
            let bias_g = d * (b[0] + d * (b[1] + d * b[2]));
            u[i] = self.u0[i] + self.k[i][i] * bias_g;
            for j in 0..3 {
                let kij = if i == j {
                    self.k[i][i] * (1.0 + d * (self.scale[i][0] + d * self.scale[i][1]))
                } else {
                    self.k[i][j] * (1.0 + self.cross[i][j] * d)
                };
                u[i] += kij * f[j];
            }
        }
        u
    }
}

/// Piecewise-linear waveform through `(t, T)` knots.
fn interp(knots: &[(f64, f64)], t: f64) -> f64 {
    if t <= knots[0].0 {
        return knots[0].1;
    }
    for w in knots.windows(2) {
        if t <= w[1].0 {
            let a = (t - w[0].0) / (w[1].0 - w[0].0).max(1e-9);
            return w[0].1 + a * (w[1].1 - w[0].1);
        }
    }
    knots[knots.len() - 1].1
}

/// True temperature of the unit at the row times.
fn temperature(profile: Profile, t: &[f64], rng: &mut ChaCha8Rng) -> Vec<f64> {
    let dur = t[t.len() - 1];
    let lo = rng.random_range(-30.0..10.0);
    let hi = rng.random_range(40.0..70.0);
    match profile {
        Profile::Constant => {
            let c = rng.random_range(-10.0..50.0);
            let p = rng.random_range(600.0..1800.0);
            t.iter().map(|&x| c + 0.05 * (std::f64::consts::TAU * x / p).sin()).collect()
        }
        Profile::Triangle => {
            let cycles = rng.random_range(1..=2);
            let mut knots = vec![(0.0, lo)];
            let leg = dur / (2 * cycles) as f64;
            for c in 0..cycles {
                knots.push((leg * (2 * c + 1) as f64, hi));
                knots.push((leg * (2 * c + 2) as f64, lo));
            }
            t.iter().map(|&x| interp(&knots, x)).collect()
        }
        Profile::RampsHolds { rates } => {
            // Rates in ratio 1 : 2 : 4 (scaled to fit the record); holds of equal length.
            let span = hi - lo;
            let mut legs = Vec::new();
            for r in 0..rates {
                let rate = f64::from(1u32 << r);
                legs.push((span / rate, hi));
                legs.push((span / rate, lo));
            }
            let ramp_sum: f64 = legs.iter().map(|l| l.0).sum();
            let hold_frac = rng.random_range(0.2..0.5);
            let hold_total = dur * hold_frac;
            let hold_s = hold_total / (legs.len() + 1) as f64;
            let ramp_scale = (dur - hold_total) / ramp_sum;
            let mut knots = vec![(0.0, lo), (hold_s, lo)];
            let mut now = hold_s;
            for (len, to) in legs {
                now += len * ramp_scale;
                knots.push((now, to));
                now += hold_s;
                knots.push((now, to));
            }
            t.iter().map(|&x| interp(&knots, x)).collect()
        }
        Profile::Sweep => {
            let w: [f64; 4] = [
                50.0 + rng.random_range(-5.0..5.0),
                -20.0 + rng.random_range(-5.0..5.0),
                70.0 + rng.random_range(-5.0..5.0),
                35.0 + rng.random_range(-5.0..5.0),
            ];
            let legs = [(w[0] - w[1]).abs(), (w[2] - w[1]).abs(), (w[2] - w[3]).abs()];
            let total: f64 = legs.iter().sum();
            let ramp = dur * 0.85;
            let mut knots = vec![(0.0, w[0])];
            let mut now = 0.0;
            for (k, l) in legs.iter().enumerate() {
                now += ramp * l / total;
                knots.push((now, w[k + 1]));
            }
            // The unit follows the chamber through a first-order lag of τ = record / 40.
            let tau = dur / 40.0;
            let mut y = w[0];
            let mut out = Vec::with_capacity(t.len());
            let mut prev = 0.0;
            for &x in t {
                let h = x - prev;
                let steps = 8;
                for s in 0..steps {
                    let tm = prev + h * (s as f64 + 0.5) / steps as f64;
                    y += (1.0 - (-(h / steps as f64) / tau).exp()) * (interp(&knots, tm) - y);
                }
                prev = x;
                out.push(y);
            }
            out
        }
    }
}

/// Unit vector.
fn unit_vec(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    [v[0] / n, v[1] / n, v[2] / n]
}

/// Position labels and specific-force vectors of the programme.
fn position_set(pos: Positions, rng: &mut ChaCha8Rng) -> Vec<(String, [f64; 3])> {
    let tp = [[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
    match pos {
        Positions::One => {
            if rng.random_bool(0.5) {
                vec![("TP1".into(), tp[0])]
            } else {
                let v = unit_vec([rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5), 1.0]);
                vec![("CP1".into(), v)]
            }
        }
        Positions::Six => tp.iter().enumerate().map(|(k, f)| (format!("TP{}", k + 1), *f)).collect(),
        Positions::Tilted => {
            let mut v: Vec<(String, [f64; 3])> =
                tp.iter().enumerate().map(|(k, f)| (format!("TP{}", k + 1), *f)).collect();
            for k in 0..6 {
                // Tilted ~15–40° off each principal axis.
                let base = tp[k];
                let a = rng.random_range(15f64..40.0).to_radians();
                let az = rng.random_range(0.0..std::f64::consts::TAU);
                let mut w = [0.0; 3];
                let (p, q) = match k {
                    0 | 2 => (0, 1),
                    1 | 3 => (0, 2),
                    _ => (1, 2),
                };
                for c in 0..3 {
                    w[c] = base[c] * a.cos();
                }
                w[p] += a.sin() * az.cos();
                w[q] += a.sin() * az.sin();
                v.push((format!("CP{}", k + 1), unit_vec(w)));
            }
            v
        }
    }
}

/// Play (backlash) of width `w` on the series `x`: the output moves only when the input is
/// more than `w/2` away, starting at the input.
fn backlash(x: &[f64], w: f64) -> Vec<f64> {
    let mut y = x[0];
    x.iter()
        .map(|&v| {
            if v > y + 0.5 * w {
                y = v - 0.5 * w;
            } else if v < y - 0.5 * w {
                y = v + 0.5 * w;
            }
            y
        })
        .collect()
}

/// Two cascaded first-order stages, integrated exactly over 16 sub-steps per sample with the
/// input interpolated linearly.
fn second_order_lag(t: &[f64], x: &[f64], tau1: f64, tau2: f64) -> Vec<f64> {
    let (mut a, mut b) = (x[0], x[0]);
    let mut out = Vec::with_capacity(x.len());
    out.push(b);
    for k in 1..x.len() {
        let h = (t[k] - t[k - 1]) / 16.0;
        let (e1, e2) = (1.0 - (-h / tau1).exp(), 1.0 - (-h / tau2).exp());
        for s in 0..16 {
            let xin = x[k - 1] + (x[k] - x[k - 1]) * (s as f64 + 0.5) / 16.0;
            a += e1 * (xin - a);
            b += e2 * (a - b);
        }
        out.push(b);
    }
    out
}

fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    StandardNormal.sample(rng)
}

fn std_about_mean(v: &[f64]) -> f64 {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / n).sqrt()
}

/// What the contributions are computed from.
struct Ctx<'a> {
    unit: &'a Unit,
    t: &'a [f64],
    temp: &'a [f64],
    f: &'a [[f64; 3]],
    power: &'a [f64],
    /// Temperature minus the tempco anchor [°C].
    d: &'a [f64],
    /// `K_ii` \[V/g\].
    kd: [f64; 3],
}

/// Per-axis random coefficient shapes of a mechanism (signs and weights).
fn draw_per_axis(rng: &mut ChaCha8Rng) -> [[f64; 3]; 3] {
    let mut per_axis = [[0.0f64; 3]; 3];
    for row in per_axis.iter_mut() {
        for v in row.iter_mut() {
            *v = if rng.random_bool(0.5) { 1.0 } else { -1.0 } * rng.random_range(0.5..1.0);
        }
    }
    per_axis
}

/// Least share of a warm-up's size at power-on that must change over the recording for it to
/// count as acting: a warm-up powered on hours of its time constant before the record starts
/// shows only a tail of e^(−P/τ) (10⁻¹¹ at P/τ = 25), which scaled up to a drawn size would be
/// a warm-up of kilo-g at power-on ([`MIN_DISPLACEMENT_C`] is the same bound for a lag or play).
pub const MIN_WARMUP_SHARE: f64 = 1e-3;

/// Least RMS variation of a member's contribution on a user profile, as a share of its largest
/// level, for it to be scaled to its drawn size. A tempco on a soak long after power-on varies
/// with the die's residual drift alone (a bias curve 35 °C from its anchor moving by 10⁻⁸ of
/// its level over µ°C); scaled to 16 σ its level would be kilo-g, so it contributes nothing, as
/// a warm-up seen below [`MIN_WARMUP_SHARE`] does. A term that varies with the rig's positions
/// (a cross-coupling tempco at a steady temperature, a cross-axis term) is not affected.
pub const MIN_VARIATION_SHARE: f64 = 1e-3;

/// Whether `te` moves at least [`MIN_DISPLACEMENT_C`] from `temp` on some row.
fn displaced(te: &[f64], temp: &[f64]) -> bool {
    te.iter().zip(temp).any(|(a, b)| (a - b).abs() >= MIN_DISPLACEMENT_C)
}

/// A mechanism's contribution per accelerometer, in V, before scaling.
fn contribution(mech: &Mech, x: &Ctx<'_>, per_axis: &[[f64; 3]; 3]) -> Vec<[f64; 3]> {
    let Ctx { unit, t, temp, f, power, d, kd } = *x;
    let n = t.len();
    let mut contrib = vec![[0.0f64; 3]; n];
    let through_temp = |te: &[f64], contrib: &mut [[f64; 3]]| {
        if !displaced(te, temp) {
            return;
        }
        for k in 0..n {
            let a = unit.signals(te[k], &f[k]);
            let b = unit.signals(temp[k], &f[k]);
            for i in 0..3 {
                contrib[k][i] = a[i] - b[i];
            }
        }
    };
    match mech {
        Mech::None => {}
        Mech::ThermalLag { tau1_s, tau2_s } => {
            let te = second_order_lag(t, temp, *tau1_s, *tau2_s);
            through_temp(&te, &mut contrib);
        }
        Mech::ThermalHysteresis { width_c } => {
            let te = backlash(temp, *width_c);
            through_temp(&te, &mut contrib);
        }
        Mech::SelfHeating { tau_s } => {
            let te: Vec<f64> = temp
                .iter()
                .zip(power)
                .map(|(x, p)| x + 1.0 - 0.8 * (-p / tau_s).exp() - 0.2 * (-4.0 * p / tau_s).exp())
                .collect();
            through_temp(&te, &mut contrib);
        }
        Mech::BiasHysteresis { width_c } => {
            let pl = backlash(temp, *width_c);
            if !displaced(&pl, temp) {
                return contrib;
            }
            for k in 0..n {
                let h = (pl[k] - temp[k]) / (0.5 * width_c);
                for i in 0..3 {
                    contrib[k][i] = kd[i] * h;
                }
            }
        }
        Mech::Warmup { tau_s } => {
            let w: Vec<f64> =
                power.iter().map(|p| 0.65 * (-p / tau_s).exp() + 0.35 * (-6.0 * p / tau_s).exp()).collect();
            let (lo, hi) = w.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
            if hi - lo < MIN_WARMUP_SHARE {
                return contrib;
            }
            for k in 0..n {
                for i in 0..3 {
                    contrib[k][i] = kd[i] * w[k];
                }
            }
        }
        Mech::BiasTempOrder { shape, theta_c } => {
            for k in 0..n {
                let x = d[k];
                let g = match *shape {
                    0 => x * x,
                    1 => x * x * x,
                    2 => x * x * x * x,
                    _ => (x / theta_c).exp(),
                };
                for i in 0..3 {
                    contrib[k][i] = kd[i] * g;
                }
            }
        }
        Mech::ScaleTemp { quad_mix } => {
            for k in 0..n {
                let x = d[k] / 40.0;
                for i in 0..3 {
                    let s = (1.0 - quad_mix) * x + quad_mix * per_axis[i][0] * x * x;
                    contrib[k][i] = kd[i] * f[k][i] * s;
                }
            }
        }
        Mech::CrossCouplingTemp { quadratic } => {
            for k in 0..n {
                let x = d[k] / 40.0;
                let s = if *quadratic { x * x } else { x };
                for i in 0..3 {
                    let (j1, j2) = ((i + 1) % 3, (i + 2) % 3);
                    // One partner at full weight, the other at a random share (may be 0).
                    let w2 = if per_axis[i][1] > 0.0 { per_axis[i][2] } else { 0.0 };
                    contrib[k][i] = kd[i] * s * (f[k][j1] + w2 * f[k][j2]);
                }
            }
        }
        Mech::CrossAxis => {
            // E: a rotation (skew part) plus a non-orthogonality (symmetric part).
            for k in 0..n {
                for i in 0..3 {
                    let (j1, j2) = ((i + 1) % 3, (i + 2) % 3);
                    contrib[k][i] = kd[i] * (per_axis[i][1] * f[k][j1] + per_axis[i][2] * f[k][j2]);
                }
            }
        }
        Mech::ScaleFactor => {
            for k in 0..n {
                for i in 0..3 {
                    contrib[k][i] = kd[i] * f[k][i];
                }
            }
        }
        Mech::SfAsymmetry => {
            for k in 0..n {
                for i in 0..3 {
                    contrib[k][i] = kd[i] * 0.5 * f[k][i].abs();
                }
            }
        }
        Mech::K2 => {
            for k in 0..n {
                for i in 0..3 {
                    contrib[k][i] = kd[i] * f[k][i] * f[k][i];
                }
            }
        }
        Mech::K3 => {
            for k in 0..n {
                for i in 0..3 {
                    contrib[k][i] = kd[i] * f[k][i].powi(3);
                }
            }
        }
    }
    contrib
}

/// Gains that scale a contribution to its drawn size (RMS about the mean in g on each applied
/// accelerometer; one scale for the common thermal ones), and the achieved size per
/// accelerometer [σ].
fn scale_to_size(
    mech: &Mech,
    size_sigma: f64,
    axis_weight: &[f64; 3],
    contrib: &[[f64; 3]],
    per_axis: &[[f64; 3]; 3],
    kd: [f64; 3],
    sigma_g: f64,
) -> ([f64; 3], [f64; 3]) {
    let mut raw = [0.0; 3];
    for i in 0..3 {
        let v: Vec<f64> = contrib.iter().map(|r| r[i] / kd[i]).collect();
        raw[i] = std_about_mean(&v);
    }
    let mut gain = [0.0; 3];
    if mech.common() {
        let m = raw.iter().copied().fold(0.0, f64::max);
        if m > 0.0 {
            gain = [size_sigma * sigma_g / m; 3];
        }
    } else {
        for i in 0..3 {
            if axis_weight[i] > 0.0 && raw[i] > 1e-15 {
                let sign = if per_axis[i][0] > 0.0 { 1.0 } else { -1.0 };
                gain[i] = sign * axis_weight[i] * size_sigma * sigma_g / raw[i];
            }
        }
    }
    let mut size = [0.0; 3];
    for i in 0..3 {
        size[i] = gain[i].abs() * raw[i] / sigma_g;
    }
    (gain, size)
}

/// What the generator knows about a generated pair.
#[derive(Clone, Debug)]
pub struct Truth {
    /// Achieved effect size per accelerometer (RMS about the mean / σ).
    pub axis_size_sigma: [f64; 3],
    /// Achieved size per accelerometer of every member, in the order of [`Case::members`].
    pub members: Vec<[f64; 3]>,
}

/// Generates the SIM and REAL rows of a case.
pub fn generate(c: &Case) -> (Vec<Row>, Vec<Row>, Truth) {
    if let Some(u) = &c.user {
        return generate_user(c, u);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(c.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xB11D);
    let unit = Unit::draw(&mut rng);
    let n = c.rows;
    let dt = 1.0 / c.rate_hz;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
    let temp = temperature(c.profile, &t, &mut rng);
    let read: Vec<f64> = temp.iter().map(|x| x + THERMISTOR_SIGMA_C * gauss(&mut rng)).collect();
    let set = position_set(c.positions, &mut rng);
    let dwell_rows = ((c.dwell_s * c.rate_hz).round() as usize).max(2);
    let pos_of: Vec<usize> = (0..n).map(|k| (k / dwell_rows) % set.len()).collect();
    let f: Vec<[f64; 3]> = pos_of.iter().map(|&p| set[p].1).collect();
    let power: Vec<f64> = t
        .iter()
        .map(|&x| {
            let on = c.power_on_s.iter().copied().filter(|&p| p <= x).fold(0.0, f64::max);
            x - on + if on == 0.0 { c.power_offset_s } else { 0.0 }
        })
        .collect();

    // Each mechanism's contribution per accelerometer, scaled to its drawn size. The first
    // member's coefficient shapes come from the case's stream (as they always did), the extra
    // members' from streams of their own.
    let kd = [unit.k[0][0], unit.k[1][1], unit.k[2][2]];
    let d: Vec<f64> = temp.iter().map(|x| x - c.anchor_c).collect();
    let ctx = Ctx { unit: &unit, t: &t, temp: &temp, f: &f, power: &power, d: &d, kd };
    let sigma_g = c.sigma_ug * 1e-6;
    let per_axis = draw_per_axis(&mut rng);
    let contrib = contribution(&c.mech, &ctx, &per_axis);
    let (gain, axis_size) = scale_to_size(&c.mech, c.size_sigma, &c.axis_weight, &contrib, &per_axis, kd, sigma_g);
    let mut truth = Truth { axis_size_sigma: axis_size, members: Vec::new() };
    if c.mech != Mech::None {
        truth.members.push(axis_size);
    }
    let mut extra = Vec::new();
    for (m, member) in c.extra.iter().enumerate() {
        let mut r = ChaCha8Rng::seed_from_u64(c.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (0xE0_B11D + m as u64));
        let pa = draw_per_axis(&mut r);
        let con = contribution(&member.mech, &ctx, &pa);
        let (g, size) = scale_to_size(&member.mech, member.size_sigma, &member.axis_weight, &con, &pa, kd, sigma_g);
        truth.members.push(size);
        extra.push((g, con));
    }

    // Noise: white σ, and a random walk reaching `rw_ratio·σ` (1 standard deviation) at the end.
    let dur = t[n - 1].max(dt);
    let q = c.rw_ratio * sigma_g / dur.sqrt();
    let mut rw = [0.0; 3];
    let mut sim = Vec::with_capacity(n);
    let mut real = Vec::with_capacity(n);
    for k in 0..n {
        let mut row = Row {
            line: k as u64 + 2,
            t_s: t[k],
            temp_c: read[k],
            f_g: f[k].map(Some),
            vib_kind: Some(VibKind::None),
            vib_g: [Some(0.0); 3],
            pos: Some(set[pos_of[k]].0.clone()),
            power_s: if c.power_column { Some(power[k]) } else { None },
            ..Row::default()
        };
        row.u_v = unit.signals(read[k], &f[k]);
        let mut r = row.clone();
        let base = unit.signals(temp[k], &f[k]);
        for i in 0..3 {
            if k > 0 {
                rw[i] += q * dt.sqrt() * gauss(&mut rng);
            }
            let noise_g: f64 = sigma_g * gauss(&mut rng) + rw[i];
            let mut v = base[i] + gain[i] * contrib[k][i];
            for (g, con) in &extra {
                v += g[i] * con[k][i];
            }
            r.u_v[i] = v + kd[i] * noise_g;
        }
        sim.push(row);
        real.push(r);
    }
    (sim, real, truth)
}

// ---------------------------------------------------------------------------------------------
// Profiles drawn the way users record (`Case::draw_user`): independent of the concealed members.
// ---------------------------------------------------------------------------------------------

/// One powered session of a user profile.
#[derive(Clone, Debug, PartialEq)]
pub struct UserSession {
    /// `t_s` of its first row \[s\].
    pub start_s: f64,
    /// Its length \[s\].
    pub dur_s: f64,
    /// `power_s` at its first row \[s\] (0: powered on at its start).
    pub power_offset_s: f64,
    /// What the chamber does: `ramp`, `reversal`, `soak` or `steps`.
    pub kind: &'static str,
}

/// A test profile as users record it: sessions joined in one file (unpowered gaps between), the
/// chamber's program over the whole time, and the unit's own thermal path (its case lags the
/// chamber, its die self-heats after each power-on, in SIM and REAL alike, and its thermistor
/// sits between case and die).
#[derive(Clone, Debug, PartialEq)]
pub struct UserPlan {
    /// The sessions, in time order.
    pub sessions: Vec<UserSession>,
    /// The chamber's temperature program, knots `(t_s, °C)` over the whole time.
    pub chamber: Vec<(f64, f64)>,
    /// The case's lag behind the chamber \[s\].
    pub case_tau_s: f64,
    /// The die's rise over the case after a power-on [°C].
    pub rise_c: f64,
    /// Its time constant \[s\].
    pub rise_tau_s: f64,
    /// Where the thermistor sits: `case + share·(die − case)`.
    pub thermistor_share: f64,
    /// The thermistor reading's step [°C] (0: none).
    pub quantum_c: f64,
}

impl UserPlan {
    /// Name for the tables: sessions and their kinds.
    pub fn name(&self) -> String {
        let kinds: Vec<&str> = self.sessions.iter().map(|s| s.kind).collect();
        format!("{}x[{}]", self.sessions.len(), kinds.join(","))
    }
}

impl Case {
    /// Draws a case whose test profile is drawn the way users record, independently of the
    /// concealed members (a stream of its own): one session (60 %) or 2–3 joined with unpowered
    /// gaps of 10–120 min; each powered on at its start (the first one already powered for
    /// 10–120 min in 30 % of cases); per session a single monotone ramp from a hot or cold
    /// start (40 %), a ramp with one reversal (25 %), a soak (15 %) or steps with holds (20 %), at
    /// 0.2–0.5 °C/min, with or without holds; the unit's case lagging the chamber by 5–25 min,
    /// its die self-heating 0.5–2 °C after each power-on, its thermistor between case and die;
    /// 1–100 Hz; one orientation (55 %), six (30 %) or tilted ones (15 %). `combined`: 2–3
    /// members, otherwise one or none (27 %), as [`Case::draw`] and [`Case::draw_combined`].
    pub fn draw_user(seed: u64, combined: bool) -> Case {
        // The members from one stream, the profile from another: the profile is the same
        // whatever is concealed.
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x05E2_F11E_B11D);
        let mut prng = ChaCha8Rng::seed_from_u64(seed ^ 0x05E2_9A0F_11E5);
        let mechs: Vec<Mech> = if combined {
            let k = rng.random_range(2..=3);
            let mut ids: Vec<&str> = MECH_IDS.to_vec();
            (0..k).map(|_| mech_of(ids.remove(rng.random_range(0..ids.len())), &mut rng)).collect()
        } else if rng.random_bool(0.27) {
            vec![Mech::None]
        } else {
            vec![mech_of(MECH_IDS[rng.random_range(0..MECH_IDS.len())], &mut rng)]
        };
        // The profile: nothing below looks at `mechs`.
        let n_sessions = if prng.random_bool(0.6) { 1 } else { prng.random_range(2..=3) };
        let mut sessions = Vec::new();
        let mut chamber: Vec<(f64, f64)> = Vec::new();
        let mut now = 0.0;
        let mut temp_c =
            if prng.random_bool(0.5) { prng.random_range(35.0..65.0) } else { prng.random_range(-30.0..5.0) };
        chamber.push((-4.0 * 3600.0, temp_c));
        for k in 0..n_sessions {
            if k > 0 {
                now += prng.random_range(600.0..7200.0);
            }
            let dur_s = prng.random_range(1800.0..14_400.0);
            let kind = match prng.random_range(0..100) {
                0..40 => "ramp",
                40..65 => "reversal",
                65..80 => "soak",
                _ => "steps",
            };
            let rate = prng.random_range(0.2..0.5) / 60.0;
            let hold =
                |r: &mut ChaCha8Rng| -> f64 { if r.random_bool(0.5) { r.random_range(600.0..2400.0) } else { 0.0 } };
            // Heading for the far side of the range from where the chamber is.
            let toward = |from: f64, r: &mut ChaCha8Rng| {
                if from > 20.0 { r.random_range(-30.0..5.0) } else { r.random_range(35.0..65.0) }
            };
            let end = now + dur_s;
            let mut t = now;
            chamber.push((t, temp_c));
            let go = |to: f64, t: &mut f64, temp_c: &mut f64, chamber: &mut Vec<(f64, f64)>| {
                let len = ((to - *temp_c).abs() / rate).min(end - *t).max(0.0);
                let reached = *temp_c + (to - *temp_c).signum() * rate * len;
                *t += len;
                *temp_c = reached;
                chamber.push((*t, *temp_c));
            };
            match kind {
                "soak" => {}
                "ramp" => {
                    t += hold(&mut prng).min(0.3 * dur_s);
                    chamber.push((t, temp_c));
                    let to = toward(temp_c, &mut prng);
                    go(to, &mut t, &mut temp_c, &mut chamber);
                }
                "reversal" => {
                    t += hold(&mut prng).min(0.2 * dur_s);
                    chamber.push((t, temp_c));
                    let from = temp_c;
                    let to = toward(temp_c, &mut prng);
                    let turn_at = temp_c + (to - temp_c) * prng.random_range(0.4..1.0);
                    let first = ((turn_at - temp_c).abs() / rate).min(0.6 * (end - t));
                    let turn = temp_c + (turn_at - temp_c).signum() * rate * first;
                    go(turn, &mut t, &mut temp_c, &mut chamber);
                    t += hold(&mut prng).min(0.2 * dur_s).min((end - t).max(0.0));
                    chamber.push((t, temp_c));
                    let back = temp_c - (turn - from) * prng.random_range(0.5..1.2);
                    go(back, &mut t, &mut temp_c, &mut chamber);
                }
                _ => {
                    let levels = prng.random_range(2..=4);
                    let to = toward(temp_c, &mut prng);
                    let step = (to - temp_c) / levels as f64;
                    for _ in 0..levels {
                        let target = temp_c + step;
                        go(target, &mut t, &mut temp_c, &mut chamber);
                        t += prng.random_range(600.0..2400.0_f64).min((end - t).max(0.0));
                        chamber.push((t, temp_c));
                    }
                }
            }
            chamber.push((end.max(t), temp_c));
            let power_offset_s = if k == 0 && prng.random_bool(0.3) { prng.random_range(600.0..7200.0) } else { 0.0 };
            sessions.push(UserSession { start_s: now, dur_s, power_offset_s, kind });
            now = end;
        }
        chamber.sort_by(|a, b| a.0.total_cmp(&b.0));
        let total_s: f64 = sessions.iter().map(|s| s.dur_s).sum();
        let rates = [1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0];
        let mut rate_hz = rates[prng.random_range(0..rates.len())];
        while rate_hz > 1.0 && total_s * rate_hz > 250_000.0 {
            rate_hz = rates.iter().copied().filter(|&r| r < rate_hz).fold(1.0, f64::max);
        }
        let positions = match prng.random_range(0..100) {
            0..55 => Positions::One,
            55..85 => Positions::Six,
            _ => Positions::Tilted,
        };
        let dwell_s = prng.random_range(30.0..240.0);
        let plan = UserPlan {
            case_tau_s: prng.random_range(300.0..1500.0),
            rise_c: prng.random_range(0.5..2.0),
            rise_tau_s: log_uniform(&mut prng, 200.0, 1200.0),
            thermistor_share: prng.random_range(0.2..0.9),
            quantum_c: [0.0, 0.0078125, 0.01, 0.0625][prng.random_range(0..4)],
            sessions,
            chamber,
        };
        let rw_ratio = if rng.random_bool(0.4) { log_uniform(&mut rng, 0.5, 3.0) } else { 0.0 };
        let sigma_ug = log_uniform(&mut rng, 5.0, 500.0);
        let mut members: Vec<Member> = mechs
            .iter()
            .map(|m| {
                let size_sigma = if *m == Mech::None { 0.0 } else { log_uniform(&mut rng, 0.5, 20.0) };
                Member { mech: m.clone(), size_sigma, axis_weight: draw_axis_weight(m, &mut rng) }
            })
            .collect();
        let first = members.remove(0);
        let rows = (total_s * rate_hz).round() as usize;
        Case {
            seed,
            mech: first.mech,
            size_sigma: first.size_sigma,
            axis_weight: first.axis_weight,
            sigma_ug,
            rw_ratio,
            profile: Profile::Constant,
            positions,
            power_column: true,
            power_on_s: Vec::new(),
            power_offset_s: 0.0,
            rows,
            rate_hz,
            dwell_s,
            anchor_c: anchor_c(),
            extra: members,
            user: Some(plan),
        }
    }
}

/// The rows' times, session by session, and each row's session.
fn user_times(u: &UserPlan, rate_hz: f64) -> (Vec<f64>, Vec<usize>) {
    let dt = 1.0 / rate_hz;
    let (mut t, mut sess) = (Vec::new(), Vec::new());
    for (k, s) in u.sessions.iter().enumerate() {
        let n = (s.dur_s * rate_hz).round() as usize;
        for i in 0..n {
            t.push(s.start_s + i as f64 * dt);
            sess.push(k);
        }
    }
    (t, sess)
}

/// The unit's thermal path at the rows: the case (first-order lag of the chamber, integrated
/// through the gaps too), the die (the case plus the self-heating since the session's
/// power-on) and the thermistor between them; and `power_s`.
fn user_thermal(u: &UserPlan, t: &[f64], sess: &[usize]) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let n = t.len();
    let mut case = Vec::with_capacity(n);
    let mut x = interp(&u.chamber, u.chamber[0].0);
    let mut prev = u.chamber[0].0;
    for &tk in t {
        // Sub-steps of at most 10 s (the gaps included), the chamber interpolated.
        let h = tk - prev;
        let steps = ((h / 10.0).ceil() as usize).max(1);
        for s in 0..steps {
            let tm = prev + h * (s as f64 + 0.5) / steps as f64;
            x += (1.0 - (-(h / steps as f64) / u.case_tau_s).exp()) * (interp(&u.chamber, tm) - x);
        }
        prev = tk;
        case.push(x);
    }
    let power: Vec<f64> = (0..n)
        .map(|k| {
            let s = &u.sessions[sess[k]];
            t[k] - s.start_s + s.power_offset_s
        })
        .collect();
    let die: Vec<f64> = (0..n)
        .map(|k| {
            let p = power[k] / u.rise_tau_s;
            case[k] + u.rise_c * (1.0 - 0.8 * (-p).exp() - 0.2 * (-4.0 * p).exp())
        })
        .collect();
    let therm: Vec<f64> = (0..n).map(|k| case[k] + u.thermistor_share * (die[k] - case[k])).collect();
    (die, therm, power)
}

/// RMS of `v` after each session's mean is removed.
fn rms_about_session_means(v: &[f64], sess: &[usize]) -> f64 {
    let k = sess.iter().copied().max().unwrap_or(0) + 1;
    let mut sum = vec![(0.0, 0usize); k];
    for (x, &s) in v.iter().zip(sess) {
        sum[s].0 += x;
        sum[s].1 += 1;
    }
    let ss: f64 = v.iter().zip(sess).map(|(x, &s)| (x - sum[s].0 / sum[s].1.max(1) as f64).powi(2)).sum();
    (ss / v.len().max(1) as f64).sqrt()
}

/// [`generate`] for a user profile: SIM is the unit at its die temperature (the twin knows its
/// own self-heating), REAL the same plus the concealed members, both recording the
/// thermistor's reading. The truth's sizes are what each member shows once each session's
/// offset is removed (the level restarts at a power-on): what the profile lets one see.
fn generate_user(c: &Case, u: &UserPlan) -> (Vec<Row>, Vec<Row>, Truth) {
    let mut rng = ChaCha8Rng::seed_from_u64(c.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x05E2_B11D);
    let unit = Unit::draw(&mut rng);
    let (t, sess) = user_times(u, c.rate_hz);
    let n = t.len();
    let (die, therm, power) = user_thermal(u, &t, &sess);
    let read: Vec<f64> = therm
        .iter()
        .map(|x| {
            let v = x + THERMISTOR_SIGMA_C * gauss(&mut rng);
            if u.quantum_c > 0.0 { (v / u.quantum_c).round() * u.quantum_c } else { v }
        })
        .collect();
    let set = position_set(c.positions, &mut rng);
    let dwell_rows = ((c.dwell_s * c.rate_hz).round() as usize).max(2);
    let pos_of: Vec<usize> = (0..n).map(|k| (k / dwell_rows) % set.len()).collect();
    let f: Vec<[f64; 3]> = pos_of.iter().map(|&p| set[p].1).collect();
    let kd = [unit.k[0][0], unit.k[1][1], unit.k[2][2]];
    let d: Vec<f64> = die.iter().map(|x| x - c.anchor_c).collect();
    let ctx = Ctx { unit: &unit, t: &t, temp: &die, f: &f, power: &power, d: &d, kd };
    let sigma_g = c.sigma_ug * 1e-6;
    let mut members = Vec::new();
    let mut truth = Truth { axis_size_sigma: [0.0; 3], members: Vec::new() };
    for (m, member) in c.members().iter().enumerate() {
        let mut r = ChaCha8Rng::seed_from_u64(c.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (0x05E2_0000 + m as u64));
        let pa = draw_per_axis(&mut r);
        let con = contribution(&member.mech, &ctx, &pa);
        let (mut g, _) = scale_to_size(&member.mech, member.size_sigma, &member.axis_weight, &con, &pa, kd, sigma_g);
        // A contribution this profile holds constant (a scale-factor term in one orientation,
        // a tempco on a soak long after power-on) has only rounding or the die's residual
        // drift about its mean: nothing to scale up ([`MIN_VARIATION_SHARE`]).
        for i in 0..3 {
            let v: Vec<f64> = con.iter().map(|row| row[i]).collect();
            let peak = v.iter().fold(0.0f64, |a, b| a.max(b.abs()));
            if !(std_about_mean(&v) > MIN_VARIATION_SHARE * peak) {
                g[i] = 0.0;
            }
        }
        let mut visible = [0.0; 3];
        for i in 0..3 {
            let v: Vec<f64> = con.iter().map(|row| g[i] * row[i] / kd[i]).collect();
            visible[i] = rms_about_session_means(&v, &sess) / sigma_g;
        }
        if m == 0 {
            truth.axis_size_sigma = visible;
        }
        truth.members.push(visible);
        members.push((g, con));
    }
    let dur = t[n - 1].max(1.0);
    let q = c.rw_ratio * sigma_g / dur.sqrt();
    let mut rw = [0.0; 3];
    let (mut sim, mut real) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for k in 0..n {
        let mut row = Row {
            line: k as u64 + 2,
            t_s: t[k],
            temp_c: read[k],
            f_g: f[k].map(Some),
            vib_kind: Some(VibKind::None),
            vib_g: [Some(0.0); 3],
            pos: Some(set[pos_of[k]].0.clone()),
            power_s: Some(power[k]),
            ..Row::default()
        };
        let base = unit.signals(die[k], &f[k]);
        row.u_v = base;
        let mut r = row.clone();
        for i in 0..3 {
            if k > 0 {
                // The bias's random walk goes on through an unpowered gap.
                rw[i] += q * (t[k] - t[k - 1]).sqrt() * gauss(&mut rng);
            }
            let mut v = base[i] + kd[i] * (sigma_g * gauss(&mut rng) + rw[i]);
            for (g, con) in &members {
                v += g[i] * con[k][i];
            }
            r.u_v[i] = v;
        }
        sim.push(row);
        real.push(r);
    }
    (sim, real, truth)
}
