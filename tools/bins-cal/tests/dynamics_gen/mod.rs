//! A blind generator of tilter recordings with thermal dynamics, for the checks of
//! `calibrate --dynamics identify`. It shares no code with `calib::dynamics`, the simulator
//! (`bins_cal::sim`) or the core: its own random numbers, its own lag, play and bias play, its
//! own constants quadratic in the die temperature, its own chamber program and CSV writer.
//!
//! A unit: K (3×3) and U0 at 20 °C, each element with its own relative linear and quadratic
//! temperature coefficients; a die lagging the thermistor by τ; the constants following the
//! die through a play of width h; an additive bias of ±b_i (per axis) beyond a play of width
//! h_b on that temperature (−b_i after heating, +b_i after cooling); white noise and a random
//! walk on each signal; a thermistor lagging the chamber by 60 s, with noise and a 0.01 °C
//! resolution. The recordings: a calibration run (soaks at four temperatures, ramps between
//! them both ways, sometimes a reversal mid-ramp) and a separate check run (faster ramps, with
//! tilted positions `CP1`…`CP6`), the tilter cycling through its positions all along.

#![allow(dead_code)]

use std::fmt::Write as _;

/// SplitMix64 with Box–Muller normals.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed ^ 0x5DEE_CE66_D1CE_4E5B)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn unif(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unif()
    }
    pub fn normal(&mut self) -> f64 {
        let u1 = self.unif().max(1e-300);
        let u2 = self.unif();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
    pub fn sign(&mut self) -> f64 {
        if self.unif() < 0.5 { -1.0 } else { 1.0 }
    }
}

/// One drawn unit: its constants, its dynamics and its noise.
#[derive(Clone, Debug)]
pub struct Unit {
    pub seed: u64,
    /// K at 20 °C [V/g].
    pub k0: [[f64; 3]; 3],
    /// Relative linear and quadratic coefficients of each K element [1/°C, 1/°C²].
    pub k1: [[f64; 3]; 3],
    pub k2: [[f64; 3]; 3],
    /// U0 at 20 °C [V] and its linear and quadratic coefficients [g/°C, g/°C²] (times K_ii).
    pub u0: [f64; 3],
    pub u1_g: [f64; 3],
    pub u2_g: [f64; 3],
    /// Die lag behind the thermistor [s] (0: none).
    pub tau_s: f64,
    /// Play of the temperature the constants follow [°C] (0: none).
    pub h_c: f64,
    /// Bias play width [°C] (0: none) and amplitude per axis [g].
    pub hb_c: f64,
    pub b_g: [f64; 3],
    /// White noise σ per row [g] and random walk [g/√s] per axis.
    pub white_g: f64,
    pub rw_g_per_sqrt_s: f64,
    /// Ramp rates of the calibration run [°C/min] and whether one ramp reverses.
    pub rates_c_per_min: [f64; 4],
    pub reversal: bool,
    /// Soak temperatures of the calibration run (20 °C first) [°C].
    pub soaks_c: [f64; 4],
}

impl Unit {
    /// A unit with dynamics (`null` false) or without (`null` true), drawn from `seed`.
    pub fn draw(seed: u64, null: bool) -> Unit {
        let mut r = Rng::new(seed.wrapping_mul(0x2545_F491_4F6C_DD1D).wrapping_add(17));
        let mut k0 = [[0.0; 3]; 3];
        let (mut k1, mut k2) = ([[0.0; 3]; 3], [[0.0; 3]; 3]);
        for i in 0..3 {
            for j in 0..3 {
                k0[i][j] = if i == j { r.range(0.8, 1.2) } else { r.range(-3e-3, 3e-3) };
                k1[i][j] = r.range(-150e-6, 150e-6);
                k2[i][j] = r.range(-1.5e-6, 1.5e-6);
            }
        }
        let u0 = [r.range(-0.05, 0.05), r.range(-0.05, 0.05), r.range(-0.05, 0.05)];
        let u1_g = [0; 3].map(|_| r.sign() * r.range(20e-6, 150e-6));
        let u2_g = [0; 3].map(|_| r.sign() * r.range(0.2e-6, 2e-6));
        let tau_s = (30f64.ln() + r.unif() * (600f64 / 30.0).ln()).exp();
        let h_c = r.range(0.0, 2.0);
        let with_bias = r.unif() < 0.8;
        let hb_c = r.range(0.5, 10.0);
        let b_g = [0; 3].map(|_| r.sign() * r.range(0.2e-3, 2e-3));
        let rw = r.range(0.0, 0.5e-6);
        let rates_c_per_min = [0; 4].map(|_| r.range(0.5, 3.0));
        let reversal = r.unif() < 0.5;
        let soaks_c = [20.0, r.range(-35.0, -15.0), r.range(50.0, 70.0), r.range(0.0, 8.0)];
        let (tau_s, h_c, hb_c, b_g) = if null {
            (0.0, 0.0, 0.0, [0.0; 3])
        } else if with_bias {
            (tau_s, h_c, hb_c, b_g)
        } else {
            (tau_s, h_c, 0.0, [0.0; 3])
        };
        Unit {
            seed,
            k0,
            k1,
            k2,
            u0,
            u1_g,
            u2_g,
            tau_s,
            h_c,
            hb_c,
            b_g,
            white_g: 35e-6,
            rw_g_per_sqrt_s: rw,
            rates_c_per_min,
            reversal,
            soaks_c,
        }
    }

    /// The signals [V] at die-side effective temperature `te` and bias fraction `d` for the
    /// specific force `f` (no noise).
    pub fn signal(&self, f: [f64; 3], te: f64, d: f64) -> [f64; 3] {
        let x = te - 20.0;
        let mut u = [0.0; 3];
        for i in 0..3 {
            let kii = self.k0[i][i] * (1.0 + self.k1[i][i] * x + self.k2[i][i] * x * x);
            let mut s = self.u0[i] + self.k0[i][i] * (self.u1_g[i] * x + self.u2_g[i] * x * x);
            for j in 0..3 {
                s += self.k0[i][j] * (1.0 + self.k1[i][j] * x + self.k2[i][j] * x * x) * f[j];
            }
            u[i] = s + kii * self.b_g[i] * d;
        }
        u
    }
}

/// The six tilter positions (labels `TP1`…`TP6`).
pub const TP: [[f64; 3]; 6] =
    [[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]];

/// The check positions `CP1`…`CP6`: each axis direction tilted by 25° towards the next axis.
pub fn cp() -> [[f64; 3]; 6] {
    let (s, c) = 25f64.to_radians().sin_cos();
    [[c, s, 0.0], [0.0, c, s], [s, 0.0, c], [-c, 0.0, -s], [0.0, -c, s], [-s, -c, 0.0]]
}

/// A chamber program: segments of (target °C, rate °C/min; 0 = soak for `hold_s`).
#[derive(Clone, Debug)]
pub enum Step {
    /// Ramp to this temperature at this rate.
    Ramp(f64, f64),
    /// Hold for this long [s].
    Hold(f64),
}

/// The chamber temperature of every second of a program starting at `start_c`.
pub fn chamber(start_c: f64, steps: &[Step]) -> Vec<f64> {
    let mut out = vec![start_c];
    let mut t = start_c;
    for s in steps {
        match *s {
            Step::Ramp(target, rate) => {
                let per_s = rate / 60.0;
                let n = ((target - t).abs() / per_s).ceil() as usize;
                let t_from = t;
                for k in 1..=n {
                    out.push(t_from + (target - t_from) * k as f64 / n as f64);
                }
                t = target;
            }
            Step::Hold(d) => {
                for _ in 0..d as usize {
                    out.push(t);
                }
            }
        }
    }
    out
}

/// The calibration run's program: soaks at the four temperatures, each at least 45 min and
/// six die lags, ramps between them, one reversing by 5–15 °C midway when `u.reversal`.
pub fn calibration_program(u: &Unit, r: &mut Rng) -> Vec<Step> {
    let soak = (6.0 * u.tau_s).max(2700.0);
    let [t20, cold, hot, mid] = u.soaks_c;
    let _ = t20;
    let mut steps = vec![Step::Hold(soak), Step::Ramp(cold, u.rates_c_per_min[0]), Step::Hold(soak)];
    if u.reversal {
        let at = cold + (hot - cold) * r.range(0.35, 0.65);
        let back = r.range(5.0, 15.0);
        steps.push(Step::Ramp(at, u.rates_c_per_min[1]));
        steps.push(Step::Ramp(at - back, u.rates_c_per_min[1]));
    }
    steps.extend([
        Step::Ramp(hot, u.rates_c_per_min[1]),
        Step::Hold(soak),
        Step::Ramp(mid, u.rates_c_per_min[2]),
        Step::Hold(soak),
        Step::Ramp(20.0, u.rates_c_per_min[3]),
        Step::Hold(600.0),
    ]);
    steps
}

/// The check run's program: holds at 20 °C, a cold and a hot temperature 3–10 °C inside the
/// calibration's soaks, ramps of 2–3 °C/min.
pub fn check_program(u: &Unit, r: &mut Rng) -> Vec<Step> {
    let soak = (6.0 * u.tau_s).max(1800.0);
    vec![
        Step::Hold(soak),
        Step::Ramp(u.soaks_c[1] + r.range(3.0, 10.0), r.range(2.0, 3.0)),
        Step::Hold(soak),
        Step::Ramp(u.soaks_c[2] - r.range(3.0, 10.0), r.range(2.0, 3.0)),
        Step::Hold(soak),
        Step::Ramp(20.0, r.range(2.0, 3.0)),
        Step::Hold(600.0),
    ]
}

/// The recording (CSV, format v1) of `u` through the chamber temperatures `chamber_c` (one per
/// second), the tilter cycling through `positions` (labels `prefix1`…) with dwells of 40 s and
/// moves of 10 s. `with_vibration_columns` false leaves out `vib_*`.
pub fn record(
    u: &Unit,
    chamber_c: &[f64],
    positions: &[[f64; 3]; 6],
    prefix: &str,
    noise_seed: u64,
    with_vibration_columns: bool,
) -> String {
    let mut r = Rng::new(noise_seed.wrapping_mul(0x9E37_79B9).wrapping_add(u.seed));
    let mut out = String::with_capacity(chamber_c.len() * 90);
    let _ = writeln!(out, "# blind dynamics generator, unit seed {}", u.seed);
    out.push_str("t_s,ux_V,uy_V,uz_V,temp_C,fx_g,fy_g,fz_g");
    if with_vibration_columns {
        out.push_str(",vib_kind,vib_x_g,vib_y_g,vib_z_g,vib_hz,vib_bw_hz");
    }
    out.push_str(",chamber_C,pos\n");
    let case_tau = 60.0;
    let (mut case, mut die, mut te) = (chamber_c[0], chamber_c[0], chamber_c[0]);
    let mut bp = te;
    let mut walk = [0.0; 3];
    for (k, &ch) in chamber_c.iter().enumerate() {
        if k > 0 {
            // Exact first-order steps for a linear input over the second.
            let step = |x: f64, a: f64, b: f64, tau: f64| {
                if tau <= 0.0 {
                    return b;
                }
                let e = (-1.0 / tau).exp();
                let g = b - a;
                b - g * tau + (x - a + g * tau) * e
            };
            let case_prev = case;
            case = step(case, chamber_c[k - 1], ch, case_tau);
            die = step(die, case_prev, case, u.tau_s);
            for w in walk.iter_mut() {
                *w += u.rw_g_per_sqrt_s * r.normal();
            }
        } else {
            die = case;
        }
        // The play on the die temperature, then the bias play on what the constants follow.
        if u.h_c > 0.0 {
            te = te.max(die - 0.5 * u.h_c).min(die + 0.5 * u.h_c);
        } else {
            te = die;
        }
        let d = if u.hb_c > 0.0 {
            bp = bp.max(te - 0.5 * u.hb_c).min(te + 0.5 * u.hb_c);
            (bp - te) / (0.5 * u.hb_c)
        } else {
            0.0
        };
        // Tilter: 40 s dwell, 10 s move, positions in turn.
        let phase = k % 50;
        let p = (k / 50) % 6;
        let (f, label) = if phase < 40 {
            (positions[p], Some(format!("{prefix}{}", p + 1)))
        } else {
            // Moving: halfway between this position and the next, not labelled.
            let q = positions[(p + 1) % 6];
            let m = [0, 1, 2].map(|i| positions[p][i] + (q[i] - positions[p][i]) * (phase - 39) as f64 / 11.0);
            let n = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt().max(1e-9);
            (m.map(|x| x / n), None)
        };
        let clean = u.signal(f, te, d);
        let uv: Vec<f64> = (0..3)
            .map(|i| {
                clean[i]
                    + u.k0[i][i] * (u.white_g * r.normal() + walk[i])
                    + if label.is_none() { 0.05 * r.normal() } else { 0.0 }
            })
            .collect();
        let temp = ((case + 0.005 * r.normal()) / 0.01).round() * 0.01;
        let _ = write!(out, "{k},{:.7},{:.7},{:.7},{temp:.2}", uv[0], uv[1], uv[2]);
        match &label {
            Some(_) => {
                let _ = write!(out, ",{},{},{}", f[0], f[1], f[2]);
            }
            None => out.push_str(",,,"),
        }
        if with_vibration_columns {
            out.push_str(if label.is_some() { ",none,0,0,0,," } else { ",,,,,," });
        }
        let _ = writeln!(out, ",{ch:.3},{}", label.unwrap_or_default());
    }
    out
}

/// The calibration and check recordings of `u` (CSV texts).
pub fn recordings(u: &Unit) -> (String, String) {
    let mut r = Rng::new(u.seed ^ 0xC0FF_EE00);
    let cal = chamber(20.0, &calibration_program(u, &mut r));
    let chk = chamber(20.0, &check_program(u, &mut r));
    (record(u, &cal, &TP, "TP", 1, true), record(u, &chk, &cp(), "CP", 2, true))
}
