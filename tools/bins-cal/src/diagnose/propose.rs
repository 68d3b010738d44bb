//! The test to run next when the recording cannot decide: candidate chamber programs built
//! from blocks, each one's expected evidence for every pair of explanations the diagnosis could
//! not separate, and their ranking (`docs/diagnosis.md`, "When the data cannot decide").
//!
//! The pairs are the diagnosis's ambiguous groups ([`super::fit::AxisFit::ambiguous`]): a term
//! `A` it modelled and a rival `B` that explains this recording about as well, or that this
//! recording's design would not let data drawn from `A` tell apart ([`super::separate`]).
//!
//! A candidate is a list of scenario steps (soaks at a rate of their own, power cycles, tilter
//! runs), kept within the chamber's [`Limits`]. Its design is its thermal path simulated with
//! the twin's tables (`bins-cal simulate` on the candidate), at a coarse
//! sample period with the recording's white-noise density carried over, so the whitened metric
//! is the recording's own. On that design `A`'s prediction with the coefficients fitted on this
//! recording (SIM's sensitivity as the recording's) is refitted by every rival
//! (`fit::separability_of`, the diagnosis's own list of rivals) under the recording's
//! noise model (its random walk `q` and deviance unit): what `B` cannot absorb is the expected
//! likelihood-ratio statistic of `A` against `B` were that test run. A candidate that lifts
//! every pair to [`super::separate::separation_needed`] ranks before one that does not; among
//! those alike, the worst pair's evidence (over what it needs) per hour of test decides.
//!
//! The expected evidence is checked against runs: [`realised_on`] gives what a run of a test
//! shows (the rival refitted on its data with and without the term, by the same refits),
//! [`evidence_interval`] the 90 % interval that draw falls in when the fitted model is true (a
//! noncentral χ²), [`run_on_design`] a run of a candidate with REAL's physics. Since the
//! recording could not tell a group's members apart, the proposed test's ranges are also given
//! were another member true ([`evidence_if_others_true`], [`group_intervals`]): on the 40
//! simulated cases of docs/diagnosis.md a run lands inside that set for 80.7 % of the pairs
//! (69.2 % inside the term's own interval).

use super::fit::{ALPHA, AxisFit, Term, naming_threshold, separability_of};
use super::mech::{Context, Mech};
use super::prep::{self, Prepared};
use super::{DiagnoseError, Diagnosis};
use std::path::Path;

/// The chamber's limits a candidate keeps within.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Lowest chamber set point [°C].
    pub temp_min_c: f64,
    /// Highest chamber set point [°C].
    pub temp_max_c: f64,
    /// Largest ramp rate [°C/min].
    pub max_rate_c_per_min: f64,
    /// Longest test \[s\].
    pub max_duration_s: f64,
}

impl Limits {
    /// The recording's own: the range of its `temp_C`, the largest rate its smoothed
    /// temperature moved at over a minute (at least 0.1 °C/min); a test up to twice its length
    /// (at least 4 h).
    pub fn from_recording(p: &Prepared) -> Limits {
        let (lo, hi) = p.temp.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
        let mut rate: f64 = 0.1;
        let mut j = 0;
        for k in 0..p.t.len() {
            while j < k && p.t[k] - p.t[j] > 60.0 {
                j += 1;
            }
            let dt = p.t[k] - p.t[j];
            if dt >= 30.0 {
                rate = rate.max((p.temp_s[k] - p.temp_s[j]).abs() / dt * 60.0);
            }
        }
        let span = p.t.last().copied().unwrap_or(0.0) - p.t.first().copied().unwrap_or(0.0);
        Limits {
            temp_min_c: (lo * 10.0).round() / 10.0,
            temp_max_c: (hi * 10.0).round() / 10.0,
            max_rate_c_per_min: (rate * 10.0).round().max(1.0) / 10.0,
            max_duration_s: (2.0 * span).max(4.0 * 3600.0),
        }
    }
}

/// A pair of explanations the diagnosis could not separate on one accelerometer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pair {
    /// Accelerometer index.
    pub axis: usize,
    /// The term modelled.
    pub a: Mech,
    /// The rival.
    pub b: Mech,
    /// The deviance `b` cannot absorb of what `a` predicts on this recording (NaN where the
    /// separability did not list it).
    pub recording: f64,
    /// What a name needs ([`super::separate::separation_needed`]).
    pub needed: f64,
    /// The naming threshold of the term: the likelihood-ratio statistic a run must exceed to
    /// name it over the rival ([`naming_threshold`] at the selection's per-test level).
    pub threshold: f64,
    /// The term's coefficients: the degrees of freedom of a run's statistic ([`realised_on`],
    /// θ held at the recording's).
    pub df: usize,
    /// The term's likelihood-ratio statistic on the recording (dropping it from the final
    /// model): what the recording knows of its size ([`predictive_interval`]).
    pub lr: f64,
}

/// The pairs of the diagnosis's ambiguous groups, per accelerometer.
pub fn pairs(d: &Diagnosis) -> Vec<Pair> {
    let mut out = Vec::new();
    for fit in &d.axes {
        for (a, alts) in &fit.ambiguous {
            for &(b, _) in alts {
                let recording = fit
                    .separability
                    .iter()
                    .find(|(m, _)| m == a)
                    .and_then(|(_, r)| r.iter().find(|x| x.0 == b))
                    .map_or(f64::NAN, |x| x.1);
                let (threshold, needed) = needed(fit, *a);
                let term = fit.terms.iter().find(|t| t.mech == *a);
                let df = term.map_or(1, |t| t.coef.len()).max(1);
                let lr = term.map_or(f64::NAN, |t| t.lr_drop);
                out.push(Pair { axis: fit.axis, a: *a, b, recording, needed, threshold, df, lr });
            }
        }
    }
    out
}

/// The naming threshold of the term `m` of `fit` and the separation it needs from a rival (as
/// the report's groups use them).
fn needed(fit: &AxisFit, m: Mech) -> (f64, f64) {
    let alpha = ALPHA / (Mech::ALL.len() * 3) as f64;
    let df = fit.terms.iter().find(|t| t.mech == m).map_or(1, |t| t.coef.len() + usize::from(t.theta.is_some()));
    let thr = naming_threshold(alpha, df);
    (thr, super::separate::separation_needed(thr, df))
}

/// One step of a candidate's chamber program (a `[[step]]` of the scenario).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    /// Move the chamber to `chamber_c` at `rate_c_per_min`, the step lasting `dwell_s` from
    /// its start (the move included).
    Soak {
        /// Set point [°C].
        chamber_c: f64,
        /// Rate [°C/min].
        rate_c_per_min: f64,
        /// Length \[s\].
        dwell_s: f64,
    },
    /// The unit off for `off_s` while the chamber moves to `chamber_c`, then on.
    Power {
        /// Time off \[s\].
        off_s: f64,
        /// Set point [°C].
        chamber_c: f64,
        /// Rate [°C/min].
        rate_c_per_min: f64,
    },
    /// Tilter positions TP1…TP6, 20 s each, 5 s turns.
    Tilter,
}

/// Length of a tilter run ([`Step::Tilter`]) \[s\].
const TILTER_S: f64 = 6.0 * 20.0 + 5.0 * 5.0;

impl Step {
    fn duration_s(&self) -> f64 {
        match *self {
            Step::Soak { dwell_s, .. } => dwell_s,
            Step::Power { off_s, .. } => off_s,
            Step::Tilter => TILTER_S,
        }
    }

    fn toml(&self) -> String {
        match *self {
            Step::Soak { chamber_c, rate_c_per_min, dwell_s } => format!(
                "[[step]]\nkind = \"soak\"\nchamber_C = {chamber_c:?}\nrate_C_per_min = {rate_c_per_min:?}\ndwell_s = {dwell_s:?}\n"
            ),
            Step::Power { off_s, chamber_c, rate_c_per_min } => format!(
                "[[step]]\nkind = \"power\"\noff_s = {off_s:?}\nchamber_C = {chamber_c:?}\nrate_C_per_min = {rate_c_per_min:?}\n"
            ),
            Step::Tilter => "[[step]]\nkind = \"tilter\"\ndwell_s = 20.0\nmove_s = 5.0\n".into(),
        }
    }
}

/// A candidate test.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    /// Short name.
    pub name: String,
    /// What it is, in words.
    pub what: String,
    /// The chamber (and the unit, in equilibrium, powered on) at the start [°C].
    pub start_c: f64,
    /// The program.
    pub steps: Vec<Step>,
}

impl Candidate {
    /// Length \[s\].
    pub fn duration_s(&self) -> f64 {
        self.steps.iter().map(Step::duration_s).sum()
    }

    /// Whether a power cycle is in it.
    pub fn has_power_cycle(&self) -> bool {
        self.steps.iter().any(|s| matches!(s, Step::Power { .. }))
    }

    /// The `[[step]]` tables.
    pub fn steps_toml(&self) -> String {
        self.steps.iter().map(|s| s.toml()).collect::<Vec<_>>().join("\n")
    }
}

/// The hold after a move: five of the longest time constant among the terms of the pairs
/// (turn-on, lag, drift), 600 s where none has one, within 15 min … 2 h.
pub fn hold_s(d: &Diagnosis, pairs: &[Pair]) -> f64 {
    let tau = pairs
        .iter()
        .filter_map(|p| d.axes[p.axis].terms.iter().find(|t| t.mech == p.a))
        .filter(|t| matches!(t.mech, Mech::Warmup | Mech::SelfHeating | Mech::ThermalLag | Mech::Drift))
        .filter_map(|t| t.theta)
        .fold(f64::NAN, f64::max);
    (5.0 * if tau.is_finite() { tau } else { 600.0 }).clamp(900.0, 7200.0)
}

/// The candidates for chamber `lim`, starting at `start_c` (clamped to the limits), holds of
/// `hold_s` after each move (shortened, not below a third of it, to keep within the longest
/// test; a candidate that still does not fit is left out): a power cycle at one temperature, a
/// power cycle at two, ramps at two rates with holds at their ends, a reversal followed by
/// holds reached by cooling and by heating, a staircase with a tilter run at each hold, and
/// ramps at two rates followed by a power cycle.
pub fn candidates(lim: &Limits, start_c: f64, hold_s: f64) -> Vec<Candidate> {
    let (lo, hi) = (lim.temp_min_c, lim.temp_max_c);
    let start = ((start_c * 10.0).round() / 10.0).clamp(lo, hi);
    let far = if (start - lo).abs() >= (hi - start).abs() { lo } else { hi };
    let mid = 0.5 * (start + far);
    let r = lim.max_rate_c_per_min;
    let r2 = 0.5 * r;
    let ramp = |a: f64, b: f64, rate: f64| (b - a).abs() / rate * 60.0;
    let soak = |chamber_c: f64, rate_c_per_min: f64, dwell_s: f64| Step::Soak { chamber_c, rate_c_per_min, dwell_s };
    let off_s = 1800.0;
    type Build = Box<dyn Fn(f64) -> Vec<Step>>;
    let plans: Vec<(&str, String, Build)> = vec![
        (
            "power-cycle",
            format!("power on at {start:.0} °C, off {:.0} min with the chamber holding, on again there", off_s / 60.0),
            Box::new(move |h| {
                vec![soak(start, r, h), Step::Power { off_s, chamber_c: start, rate_c_per_min: r }, soak(start, r, h)]
            }),
        ),
        (
            "power-cycle-two-temperatures",
            format!(
                "power on at {start:.0} °C, off while the chamber goes to {far:.0} °C at {r} °C/min, on there; back at {r2} °C/min"
            ),
            Box::new(move |h| {
                vec![
                    soak(start, r, h),
                    Step::Power { off_s: ramp(start, far, r) + 600.0, chamber_c: far, rate_c_per_min: r },
                    soak(far, r, h),
                    soak(start, r2, ramp(far, start, r2) + h),
                ]
            }),
        ),
        (
            "two-rates",
            format!("ramp {start:.0} → {far:.0} °C at {r} °C/min and back at {r2} °C/min, holding at each end"),
            Box::new(move |h| {
                vec![
                    soak(start, r, h),
                    soak(far, r, ramp(start, far, r) + h),
                    soak(start, r2, ramp(far, start, r2) + h),
                ]
            }),
        ),
        (
            "reversal-holds",
            format!(
                "ramp to {far:.0} °C, reverse at once to {mid:.0} °C and hold; to {far:.0} °C and back to {mid:.0} °C, holding (at {r} °C/min)"
            ),
            Box::new(move |h| {
                vec![
                    soak(start, r, h),
                    soak(far, r, ramp(start, far, r)),
                    soak(mid, r, ramp(far, mid, r) + h),
                    soak(far, r, ramp(mid, far, r) + h),
                    soak(mid, r, ramp(far, mid, r) + h),
                ]
            }),
        ),
        (
            "staircase-tilter",
            format!("holds at {start:.0}, {mid:.0}, {far:.0}, {mid:.0} and {start:.0} °C with a tilter run at each"),
            Box::new(move |h| {
                let mut v = Vec::new();
                let mut prev = start;
                for tc in [start, mid, far, mid, start] {
                    v.push(soak(tc, r, ramp(prev, tc, r) + h));
                    v.push(Step::Tilter);
                    prev = tc;
                }
                v
            }),
        ),
        (
            "two-rates-power-cycle",
            format!(
                "ramp {start:.0} → {far:.0} °C at {r} °C/min and back at {r2} °C/min, holding at each end; then a power cycle at {start:.0} °C"
            ),
            Box::new(move |h| {
                vec![
                    soak(start, r, h),
                    soak(far, r, ramp(start, far, r) + h),
                    soak(start, r2, ramp(far, start, r2) + h),
                    Step::Power { off_s, chamber_c: start, rate_c_per_min: r },
                    soak(start, r, h),
                ]
            }),
        ),
    ];
    let dur = |steps: &[Step]| steps.iter().map(Step::duration_s).sum::<f64>();
    let mut out = Vec::new();
    for (name, what, build) in plans {
        let (d0, d1) = (dur(&build(0.0)), dur(&build(1.0)));
        let mut h = hold_s;
        if d0 + (d1 - d0) * h > lim.max_duration_s {
            h = ((lim.max_duration_s - d0) / (d1 - d0)).floor();
        }
        if !(h >= hold_s / 3.0) {
            continue;
        }
        out.push(Candidate { name: name.to_string(), what, start_c: start, steps: build(h) });
    }
    out
}

/// The twin scenario: its tables with the `[[step]]`s and `[recording]` replaced.
pub struct Twin {
    /// The scenario's text as parsed (TOML).
    pub table: toml::Table,
    /// Where its tables come from (a file, or the recording's identified thermal path).
    pub source: String,
}

/// The unit's thermal path identified from a recording ([`identify_thermal`]): the case
/// follows `chamber_C` with one time constant, the die follows the case with another and is
/// heated by a step at each power-on (the simulator's `[thermal]` model, `docs/simulator.md`),
/// and the thermistor reads the case plus a share of the die's departure from it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThermalPath {
    /// Chamber → case time constant \[s\].
    pub case_tau_s: f64,
    /// Case → die time constant, also the self-heating's \[s\].
    pub die_tau_s: f64,
    /// The die's rise over the case when powered [°C].
    pub self_heating_c: f64,
    /// The thermistor's share of the die's departure from the case (0 = case, 1 = die).
    pub thermistor_at: f64,
    /// RMS of `temp_C` about the fitted path [°C].
    pub rms_c: f64,
}

/// The largest self-heating an identified twin is given [°C] (the simulator's bound on a
/// width or rise).
const MAX_RISE_C: f64 = bins_comp::dynamics::MAX_WIDTH_C;

/// The most rows [`identify_thermal`] fits (every k-th of a longer recording).
const IDENT_ROWS: usize = 20_000;

/// Grid of the time constants [`identify_thermal`] tries \[s\]: geometric, `n` values from
/// `lo` to `hi`.
fn tau_grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n).map(|i| lo * (hi / lo).powf(i as f64 / (n - 1) as f64)).collect()
}

/// The response `e` of a first-order lag (time constant `tau_s`) to an input `x` linear between
/// the rows, as its departure from the input: `e_k = a·e_{k−1} − ẋ·τ·(1 − a)`, `a = e^(−Δt/τ)`,
/// exact for that input; at rest (`e = 0`) at the first row of each session (`starts`): what
/// the input did in the unrecorded time before it is not known.
fn lag_departure(t: &[f64], x: &[f64], tau_s: f64, starts: &[usize]) -> Vec<f64> {
    let mut e = vec![0.0; t.len()];
    for k in 1..t.len() {
        let dt = t[k] - t[k - 1];
        if starts.binary_search(&k).is_ok() {
            continue;
        }
        if !(dt > 0.0) {
            e[k] = e[k - 1];
            continue;
        }
        let a = (-dt / tau_s).exp();
        let rate = (x[k] - x[k - 1]) / dt;
        e[k] = a * e[k - 1] - rate * tau_s * (1.0 - a);
    }
    e
}

/// The die's heating over the case for a unit rise (time constant `tau_s`), from `power_s`:
/// it charges while powered and decays while off (the off time is the time step less the
/// `power_s` the row reports after a power-on); the first row has been on for its `power_s`.
fn heating_unit(t: &[f64], power: &[f64], tau_s: f64) -> Vec<f64> {
    let mut h = vec![0.0; t.len()];
    for k in 0..t.len() {
        h[k] = if k == 0 {
            -(-power[0].max(0.0) / tau_s).exp_m1()
        } else if power[k] >= power[k - 1] {
            1.0 - (1.0 - h[k - 1]) * (-(t[k] - t[k - 1]).max(0.0) / tau_s).exp()
        } else {
            let on = power[k].max(0.0);
            let off = (t[k] - t[k - 1] - on).max(0.0);
            let left = h[k - 1] * (-off / tau_s).exp();
            1.0 - (1.0 - left) * (-on / tau_s).exp()
        };
    }
    h
}

/// The thermal path of recording `p` from its `temp_C`, `chamber_C` and `power_s`: `None`
/// without `chamber_C` (nothing drives the case that the recording shows). The two time
/// constants are searched on geometric grids (case 30 s–30 000 s, die 5 s–3 000 s, by a
/// factor of about 1.35 and 1.5); at each pair `temp_C − case` is fitted by least squares as
/// `b + s·h + a·g` plus, per session, the case's unknown departure from the chamber at its
/// start decaying with the case's time constant (`e^(−(t − t_s)/τ_case)`; the die starts each
/// session at the case, heated from its power-on): `case` the chamber through the case's lag
/// (`lag_departure`), `h` the heating of a unit rise (`heating_unit`; left out without
/// `power_s`, or where it does not change: a unit powered long before the record), `g` the
/// die's lag behind the case. The thermistor's share is `a`
/// (clamped to [0.05, 1]) and the rise `s/a`. The pair with the least squared residual is
/// kept. On ramps the data fix the thermistor's total lag (`τ_case + a·τ_die`) better than its
/// split. A longer recording is fitted on every k-th row, at most 20 000 (with every
/// session's first row and every power-on).
pub fn identify_thermal(p: &Prepared) -> Option<ThermalPath> {
    let chamber = p.chamber.as_ref()?;
    if p.t.len() < 8 {
        return None;
    }
    // Every k-th row, at most IDENT_ROWS (the paths are exact for inputs linear between the
    // rows kept), and every session's first row and every power-on.
    let stride = p.t.len().div_ceil(IDENT_ROWS).max(1);
    let on = |i: usize| p.power.as_ref().is_some_and(|pw| i > 0 && pw[i] < pw[i - 1]);
    let first = |i: usize| p.session_starts.binary_search(&i).is_ok();
    let keep: Vec<usize> = (0..p.t.len()).filter(|&i| i % stride == 0 || first(i) || on(i)).collect();
    let pick = |v: &[f64]| -> Vec<f64> { keep.iter().map(|&i| v[i]).collect() };
    let (t, chamber, temp) = (pick(&p.t), pick(chamber), pick(&p.temp));
    let power = p.power.as_deref().map(pick);
    let of_row = p.session_of_rows();
    let session: Vec<usize> = keep.iter().map(|&i| of_row[i]).collect();
    let mut starts = vec![0; p.session_starts.len().max(1)];
    for (k, &s) in session.iter().enumerate().rev() {
        starts[s] = k;
    }
    let (t, n) = (&t[..], keep.len());
    let mut best: Option<(f64, ThermalPath)> = None;
    for &tc in &tau_grid(30.0, 30_000.0, 24) {
        let case_dep = lag_departure(t, &chamber, tc, &starts);
        let case: Vec<f64> = chamber.iter().zip(&case_dep).map(|(c, e)| c + e).collect();
        let y: Vec<f64> = temp.iter().zip(&case).map(|(a, b)| a - b).collect();
        for &td in &tau_grid(5.0, 3000.0, 16) {
            let g = lag_departure(t, &case, td, &starts);
            let h = power.as_ref().map(|pw| heating_unit(t, pw, td)).filter(|h| {
                let (lo, hi) = h.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
                hi - lo > 0.01
            });
            let dense = if h.is_some() { 3 } else { 2 };
            let q = dense + starts.len();
            // Normal equations over the nonzero entries of each row: 1, g, (h), and its
            // session's start column.
            let mut ata = vec![0.0; q * q];
            let mut aty = vec![0.0; q];
            let mut sy2 = 0.0;
            for k in 0..n {
                let s = session[k];
                let since = t[k] - t[starts[s]];
                let mut e = [(0, 1.0), (1, g[k]), (0, 0.0), (0, 0.0)];
                let mut m = 2;
                if let Some(h) = &h {
                    e[2] = (2, h[k]);
                    m = 3;
                }
                e[m] = (dense + s, (-since / tc).exp());
                let row = &e[..m + 1];
                for &(i, vi) in row {
                    aty[i] += vi * y[k];
                    for &(j, vj) in row {
                        ata[i * q + j] += vi * vj;
                    }
                }
                sy2 += y[k] * y[k];
            }
            let Some((x, _)) = super::stats::chol_solve(&ata, &aty, q, 1e-12) else { continue };
            let sse = (sy2 - x.iter().zip(&aty).map(|(a, b)| a * b).sum::<f64>()).max(0.0);
            if best.as_ref().is_some_and(|(b, _)| *b <= sse) {
                continue;
            }
            // A share below 5 % is taken as 5 % (the rise it implies stays finite).
            let at = x[1].clamp(0.05, 1.0);
            let path = ThermalPath {
                case_tau_s: tc,
                die_tau_s: td,
                self_heating_c: if h.is_some() { x[2] / at } else { 0.0 },
                thermistor_at: at,
                rms_c: (sse / n as f64).sqrt(),
            };
            best = Some((sse, path));
        }
    }
    best.map(|b| b.1)
}

impl Twin {
    /// Reads a scenario file (checked as `bins-cal simulate` checks it).
    pub fn read(path: &Path) -> Result<Twin, DiagnoseError> {
        let text = crate::fsio::read_text(path).map_err(|e| DiagnoseError(e.to_string()))?;
        crate::sim::scenario::ScenarioFile::parse(&text, path).map_err(|e| DiagnoseError(e.to_string()))?;
        let table: toml::Table = text.parse().map_err(|e| DiagnoseError(format!("{}: {e}", path.display())))?;
        Ok(Twin { table, source: path.display().to_string() })
    }

    /// A twin made from recording `p` itself: the thermal path [`identify_thermal`] finds
    /// (without `chamber_C`, the thermistor following the program: no case, die or
    /// self-heating), the paper's unit (the proposal's columns use the recording's own fitted
    /// sensitivity, not the unit's constants), the chamber's largest rate from `lim`, and the
    /// recording's temperature resolution. The second value says what was identified.
    pub fn identified(p: &Prepared, lim: &Limits) -> Result<(Twin, String), DiagnoseError> {
        let path = identify_thermal(p);
        let (th, what) = match path {
            Some(th) => {
                let what = format!(
                    "thermal path identified from the recording's temp_C, chamber_C{}: case τ {:.0} s, die τ {:.0} s, self-heating {:.2} °C, thermistor at {:.2} of the die (rms {:.3} °C)",
                    if p.power.is_some() { " and power_s" } else { "" },
                    th.case_tau_s,
                    th.die_tau_s,
                    th.self_heating_c,
                    th.thermistor_at,
                    th.rms_c
                );
                (th, what)
            }
            None => (
                ThermalPath { case_tau_s: 0.0, die_tau_s: 0.0, self_heating_c: 0.0, thermistor_at: 0.0, rms_c: f64::NAN },
                "no chamber_C in the recording: the proposal's temperatures are the thermistor's, following the program (give --twin SCENARIO for the unit's thermal path)".to_string(),
            ),
        };
        let resolution = p.temp_resolution_c.unwrap_or(0.01);
        let rate_hz = if p.dt > 0.0 { (1.0 / p.dt).min(100.0) } else { 1.0 };
        let text = format!(
            "[recording]\nrate_Hz = {rate_hz:?}\n\n[unit]\npreset = \"paper\"\n\n[thermal]\nstart_C = 20.0\nrate_C_per_min = {:?}\ncase_tau_s = {:?}\ndie_tau_s = {:?}\nself_heating_C = {:?}\nthermistor_at = {:?}\n\n[noise]\nwhite_V = 1.0e-6\ntemp_noise_C = {:?}\ntemp_resolution_C = {resolution:?}\n\n[[step]]\nkind = \"soak\"\nchamber_C = 20.0\ndwell_s = 60.0\n",
            lim.max_rate_c_per_min,
            th.case_tau_s,
            th.die_tau_s,
            th.self_heating_c.clamp(-MAX_RISE_C, MAX_RISE_C),
            th.thermistor_at,
            0.5 * resolution,
        );
        let name = Path::new("identified twin");
        crate::sim::scenario::ScenarioFile::parse(&text, name).map_err(|e| DiagnoseError(e.to_string()))?;
        let table: toml::Table = text.parse().map_err(|e| DiagnoseError(format!("identified twin: {e}")))?;
        Ok((Twin { table, source: "the recording (the paper's unit; thermal path identified)".into() }, what))
    }

    /// The twin's logger rate \[Hz\] (1 where it has none).
    fn rate_hz(&self) -> f64 {
        self.table.get("recording").and_then(|r| r.get("rate_Hz")).and_then(toml::Value::as_float).unwrap_or(1.0)
    }

    /// The scenario of `c` with the twin's unit, thermal and (`with_noise`) noise tables, at
    /// `rate_hz`.
    pub fn scenario(&self, c: &Candidate, rate_hz: f64, with_noise: bool) -> String {
        let mut t = self.table.clone();
        t.remove("step");
        t.remove("description");
        if !with_noise {
            t.remove("noise");
        }
        let mut rec = toml::Table::new();
        rec.insert("rate_Hz".into(), toml::Value::Float(rate_hz));
        rec.insert("power_on_s".into(), toml::Value::Float(0.0));
        t.insert("recording".into(), toml::Value::Table(rec));
        let thermal = t.entry("thermal").or_insert_with(|| toml::Value::Table(toml::Table::new()));
        if let Some(th) = thermal.as_table_mut() {
            th.insert("start_C".into(), toml::Value::Float(c.start_c));
        }
        let head = format!(
            "# Proposed by bins-cal diagnose --propose: {} ({:.1} h). Unit, thermal and noise tables from {}.\n#\n#   bins-cal simulate THIS.toml -o next.csv --seed 1\ndescription = {:?}\n",
            c.name,
            c.duration_s() / 3600.0,
            self.source,
            format!("{}: {}", c.name, c.what)
        );
        let body = toml::to_string(&t).unwrap_or_default();
        format!("{head}{body}\n{}", c.steps_toml())
    }
}

/// A candidate's expected evidence.
#[derive(Clone, Debug, PartialEq)]
pub struct Evidence {
    /// The candidate.
    pub candidate: Candidate,
    /// Per pair (as in [`pairs`]): the deviance the rival cannot absorb on the candidate (NaN
    /// where the rival has no column on it: it cannot mimic the term there, and counts as
    /// separated).
    pub deviance: Vec<f64>,
    /// Whether every pair reaches what it needs.
    pub separates_all: bool,
    /// The worst pair's deviance over what it needs (of the pairs whose rival has a column).
    pub worst_ratio: f64,
    /// `worst_ratio` per hour of test.
    pub worst_ratio_per_h: f64,
    /// Per pair, the expected evidence were each other member of its group true
    /// ([`evidence_if_others_true`]); filled for the best candidate (the test proposed),
    /// empty for the rest.
    pub if_others: Vec<Vec<(Mech, f64)>>,
    /// Per pair, where a run's evidence falls nine times in ten ([`group_intervals`]; `None`
    /// where the rival has no column on the candidate); filled for the [`REPORTED`] best
    /// candidates, empty for the rest.
    pub intervals: Vec<Option<Vec<(f64, f64)>>>,
}

/// How many of the best candidates the proposal reports.
pub const REPORTED: usize = 3;

/// Where a run's evidence for pair `k` of candidate `e` falls nine times in ten
/// ([`group_intervals`]: about the term's expected evidence and, where [`Evidence::if_others`]
/// holds them, about the other members'); `None` where the rival has no column on it.
fn intervals_of(e: &Evidence, k: usize, pair: &Pair) -> Option<Vec<(f64, f64)>> {
    let v = *e.deviance.get(k)?;
    let others = e.if_others.get(k).map_or(&[][..], Vec::as_slice);
    v.is_finite().then(|| group_intervals(v, others, pair.df, 0.9, pair.lr))
}

/// Rows of a candidate's design (its thermal path at the twin's physics).
const DESIGN_ROWS: f64 = 4000.0;

/// The design of candidate `c`: the twin's physics (its noise too, so no column is constant)
/// run on its program at a sample period of about its length over `DESIGN_ROWS` (4 000) rows,
/// as SIM and as REAL, prepared as the diagnosis prepares a pair; the white noise per row set
/// from the recording's density (`white_density`, g²·s per axis).
pub fn design(twin: &Twin, c: &Candidate, white_density: [f64; 3]) -> Result<Prepared, DiagnoseError> {
    let rate = (DESIGN_ROWS / c.duration_s()).min(twin.rate_hz());
    let text = twin.scenario(c, rate, true);
    let name = Path::new("proposed test");
    let sc = crate::sim::scenario::ScenarioFile::parse(&text, name).map_err(|e| DiagnoseError(e.to_string()))?;
    let sim = sc.build(name).map_err(|e| DiagnoseError(e.to_string()))?;
    let rows = sim.all_rows(1);
    let mut p = prep::prepare_blocks(&rows, &rows, name, name, Some(0.0))?;
    for (axis, d) in white_density.iter().enumerate() {
        p.r_white[axis] = vec![d * rate; p.t.len()];
    }
    Ok(p)
}

/// The recording's white-noise density per axis (g²·s: the per-row white variance times the
/// row spacing, median over the rows; the same for rows and for blocks of them).
pub fn white_density(p: &Prepared) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (axis, o) in out.iter_mut().enumerate() {
        let mut v: Vec<f64> = (1..p.t.len()).map(|k| p.r_white[axis][k] * (p.t[k] - p.t[k - 1])).collect();
        v.retain(|x| x.is_finite() && *x > 0.0);
        v.sort_by(f64::total_cmp);
        *o = v.get(v.len() / 2).copied().unwrap_or(0.0);
    }
    out
}

/// The context of accelerometer `axis` on the rows `p` (the recording's own, or a design's)
/// with SIM's sensitivity as `d` fitted it on the recording: the terms' columns there are
/// those of the fit.
pub fn context_on<'p>(d: &Diagnosis, p: &'p Prepared, axis: usize) -> Context<'p> {
    let mut ctx = Context::new(p, axis);
    ctx.gm = d.axes[axis].gm;
    ctx.lag_rise_c = d.axes[axis].lag_rise_c;
    ctx.s = d.sensitivity[axis].clone();
    ctx.s_now = (0..p.t.len()).map(|k| ctx.s.eval(p.temp_s[k], &p.f[k])).collect();
    ctx
}

/// The fit of accelerometer `axis` of `d` carried to the design `cp`: its context (SIM's
/// sensitivity as fitted on the recording) and its terms with their coefficients and θ as
/// fitted, their columns and contributions on the design, the recording's noise model (a term
/// with no column on the design, a lag at a constant temperature, left out).
fn carried<'p>(d: &Diagnosis, cp: &'p Prepared, axis: usize) -> (Context<'p>, AxisFit) {
    let fit = &d.axes[axis];
    let ctx = context_on(d, cp, axis);
    let terms: Vec<Term> = fit
        .terms
        .iter()
        .filter_map(|t| {
            let columns = ctx.member_columns(t.mech, t.theta.unwrap_or(0.0), t.fast_ratio);
            if columns.iter().all(|c| c.iter().all(|v| v.abs() < 1e-15)) {
                return None;
            }
            let mut contribution = vec![0.0; cp.t.len()];
            for (c, b) in columns.iter().zip(&t.coef) {
                for (x, v) in contribution.iter_mut().zip(c) {
                    *x += b * v;
                }
            }
            Some(Term {
                mech: t.mech,
                theta: t.theta,
                theta_ci: None,
                coef: t.coef.clone(),
                se: Vec::new(),
                lr_drop: f64::NAN,
                p_drop: f64::NAN,
                contribution,
                columns,
                fast_ratio: t.fast_ratio,
            })
        })
        .collect();
    let on_design = AxisFit {
        axis,
        q: fit.q,
        gm: fit.gm,
        inflation: fit.inflation,
        terms,
        ambiguous: Vec::new(),
        separability: Vec::new(),
        deviance_scale: fit.deviance_scale,
        n_used: fit.n_used,
        trace: Vec::new(),
        passes_alone: Vec::new(),
        drift: Vec::new(),
        drift_rms: 0.0,
        prediction: Vec::new(),
        rms: (0.0, 0.0),
        heldout_rms: (0.0, 0.0),
        heldout_resid: (Vec::new(), Vec::new()),
        heldout_gain: Vec::new(),
        lag_rise_c: fit.lag_rise_c,
    };
    (ctx, on_design)
}

/// Per pair, the deviance its rival cannot absorb on the design `cp` of what its term, as
/// fitted on the recording, predicts there (NaN where the rival has no column on it).
pub fn evidence_on(d: &Diagnosis, cp: &Prepared, pairs: &[Pair]) -> Vec<f64> {
    let mut out = vec![f64::NAN; pairs.len()];
    for axis in 0..3 {
        if !pairs.iter().any(|p| p.axis == axis) {
            continue;
        }
        let (ctx, on_design) = carried(d, cp, axis);
        let sep = separability_of(&ctx, &on_design);
        for (k, p) in pairs.iter().enumerate().filter(|(_, p)| p.axis == axis) {
            if !on_design.terms.iter().any(|t| t.mech == p.a) {
                out[k] = 0.0;
            } else if let Some(v) =
                sep.iter().find(|(m, _)| *m == p.a).and_then(|(_, r)| r.iter().find(|x| x.0 == p.b)).map(|x| x.1)
            {
                out[k] = v;
            }
        }
    }
    out
}

/// Per pair, the evidence a run of a test gives (`run`: its residual REAL − SIM, prepared as
/// the diagnosis prepares a pair): the likelihood-ratio statistic of adding the term, at the θ
/// fitted on the recording, to its rival refitted on the run's data, `D(B) − D(B + A)`, each
/// the least over the rival's forms and θ, with the nuisance and the other terms free, under the
/// recording's noise model, in its deviance unit (`fit::rivals_of` on the data instead of the
/// term's prediction). With the term's columns linear and the model true, it is a noncentral
/// χ² of [`Pair::df`] degrees of freedom whose noncentrality is [`evidence_on`] on the run's
/// design ([`evidence_interval`]). NaN where the rival has no column on the run; 0 where the
/// term has none.
pub fn realised_on(d: &Diagnosis, run: &Prepared, pairs: &[Pair]) -> Vec<f64> {
    let mut out = vec![f64::NAN; pairs.len()];
    for axis in 0..3 {
        if !pairs.iter().any(|p| p.axis == axis) {
            continue;
        }
        let (ctx, on_design) = carried(d, run, axis);
        for (k, term) in on_design.terms.iter().enumerate() {
            if !pairs.iter().any(|p| p.axis == axis && p.a == term.mech) {
                continue;
            }
            let beside = term_beside_rivals(&ctx, &on_design, k, &run.r[axis]);
            for (j, p) in pairs.iter().enumerate().filter(|(_, p)| p.axis == axis && p.a == term.mech) {
                out[j] = beside(p.b);
            }
        }
        for (j, p) in pairs.iter().enumerate().filter(|(_, p)| p.axis == axis) {
            if !on_design.terms.iter().any(|t| t.mech == p.a) {
                out[j] = 0.0;
            }
        }
    }
    out
}

/// The likelihood-ratio statistic of adding term `k` of `on_design` (at its θ) to each rival
/// refitted on `y` (a residual on the design `ctx`): `D(B) − D(B + A)`, each the least over the
/// rival's forms and θ, the nuisance and the other terms free ([`realised_on`]); per rival,
/// NaN where it has no column.
fn term_beside_rivals(ctx: &Context, on_design: &AxisFit, k: usize, y: &[f64]) -> impl Fn(Mech) -> f64 {
    use super::separate::Refit;
    let shared = super::fit::shared_with(ctx, on_design, k);
    let without = Refit::new(ctx, on_design.q, on_design.deviance_scale, y, &shared);
    let rivals = super::fit::rivals_of(ctx, on_design, k, &without);
    let mut shared = shared;
    shared.extend(on_design.terms[k].columns.iter().cloned());
    let with = Refit::new(ctx, on_design.q, on_design.deviance_scale, y, &shared);
    let beside = super::fit::rivals_of(ctx, on_design, k, &with);
    move |b: Mech| {
        let of = |r: &[(Mech, f64)]| r.iter().find(|x| x.0 == b).map(|x| x.1);
        match (of(&rivals), of(&beside)) {
            (Some(b), Some(ab)) => (b - ab).max(0.0),
            _ => f64::NAN,
        }
    }
}

/// How many other members of a pair's group, besides its rival, are taken as possible truths
/// ([`evidence_if_others_true`]): those the recording's data favour most after the term.
pub const PLAUSIBLE_OTHERS: usize = 3;

/// Per pair, the expected evidence of a run of the design `cp` were another member of the
/// pair's group true instead of the term, as `(member, evidence)`. The recording could not
/// tell the group's members apart, so each is a possible truth:
///
/// - the pair's own rival: then the term adds nothing a run can see beyond it, and the
///   statistic is central (expected evidence 0);
/// - the [`PLAUSIBLE_OTHERS`] other members with the least deviance difference on the
///   recording's data: each refitted to the data in the term's place (θ searched, the nuisance
///   and the other terms free; [`super::separate::Refit::fitted_mechanism`]), carried to the
///   design ([`predict`](super::separate::predict)), and the run's statistic
///   ([`realised_on`]) computed on that prediction without noise — its noncentrality under
///   that hypothesis.
pub fn evidence_if_others_true(d: &Diagnosis, cp: &Prepared, pairs: &[Pair]) -> Vec<Vec<(Mech, f64)>> {
    use super::separate::predict;
    let mut out: Vec<Vec<(Mech, f64)>> = pairs.iter().map(|p| vec![(p.b, 0.0)]).collect();
    for axis in 0..3 {
        if !pairs.iter().any(|p| p.axis == axis) {
            continue;
        }
        let (ctx, on_design) = carried(d, cp, axis);
        for term in &d.axes[axis].terms {
            let mine: Vec<usize> =
                (0..pairs.len()).filter(|&j| pairs[j].axis == axis && pairs[j].a == term.mech).collect();
            let Some(kd) = on_design.terms.iter().position(|t| t.mech == term.mech) else { continue };
            if mine.is_empty() {
                continue;
            }
            for other in plausible_others(d, axis, term.mech) {
                let h = other.mech;
                let eta = predict(&ctx, &[other]);
                let beside = term_beside_rivals(&ctx, &on_design, kd, &eta);
                for &j in mine.iter().filter(|&&j| pairs[j].b != h) {
                    let v = beside(pairs[j].b);
                    if v.is_finite() {
                        out[j].push((h, v));
                    }
                }
            }
        }
    }
    out
}

/// The [`PLAUSIBLE_OTHERS`] members of the group of term `m` on accelerometer `axis` that the
/// recording's data favour most after it (least deviance difference; a non-finite one last),
/// each refitted to the data in the term's place: θ searched, the nuisance and the other terms
/// free ([`super::separate::Refit::fitted_mechanism`]). Empty where `m` is in no group.
pub fn plausible_others(d: &Diagnosis, axis: usize, m: Mech) -> Vec<super::separate::Fitted> {
    use super::separate::Refit;
    let fit = &d.axes[axis];
    let (Some(k), Some((_, alts))) =
        (fit.terms.iter().position(|t| t.mech == m), fit.ambiguous.iter().find(|(a, _)| *a == m))
    else {
        return Vec::new();
    };
    let mut plausible: Vec<(Mech, f64)> =
        alts.iter().map(|&(b, v)| (b, if v.is_finite() { v } else { f64::INFINITY })).collect();
    plausible.sort_by(|x, y| x.1.total_cmp(&y.1));
    plausible.truncate(PLAUSIBLE_OTHERS);
    let rec = context_on(d, &d.prepared, axis);
    let on_data =
        Refit::new(&rec, fit.q, fit.deviance_scale, &d.prepared.r[axis], &super::fit::shared_with(&rec, fit, k));
    plausible.into_iter().filter_map(|(b, _)| on_data.fitted_mechanism(b)).collect()
}

/// Where a run's evidence for a pair falls with probability `level` when the recording could
/// not tell its group's members apart: [`predictive_interval`] about the term's own expected
/// evidence and about each other member's ([`evidence_if_others_true`]), the intervals that
/// overlap merged; ascending. Whichever member is true, the run lands in one of them.
pub fn group_intervals(expected: f64, if_others: &[(Mech, f64)], df: usize, level: f64, lr: f64) -> Vec<(f64, f64)> {
    let mut iv: Vec<(f64, f64)> = std::iter::once(expected)
        .chain(if_others.iter().map(|x| x.1))
        .filter(|v| v.is_finite())
        .map(|v| predictive_interval(v, df, level, lr))
        .collect();
    iv.sort_by(|x, y| x.0.total_cmp(&y.0));
    let mut out: Vec<(f64, f64)> = Vec::new();
    for (lo, hi) in iv {
        match out.last_mut() {
            Some(last) if lo <= last.1 => last.1 = last.1.max(hi),
            _ => out.push((lo, hi)),
        }
    }
    out
}

/// The interval a run's realised evidence falls in with probability `level` when the expected
/// evidence is `expected` with `df` degrees of freedom: the noncentral χ²'s quantiles at
/// `(1 − level)/2` and `(1 + level)/2` (noncentrality `expected`). With no expected evidence
/// (below 10⁻⁹) the interval starts at 0: the term's columns may then lie in the rival's span
/// on this test, and the statistic is 0 whatever the noise.
pub fn evidence_interval(expected: f64, df: usize, level: f64) -> (f64, f64) {
    let k = df.max(1) as f64;
    let lambda = expected.max(0.0);
    let lo = if lambda < 1e-9 { 0.0 } else { super::stats::ncx2_quantile(0.5 * (1.0 - level), k, lambda) };
    (lo, super::stats::ncx2_quantile(0.5 * (1.0 + level), k, lambda))
}

/// [`evidence_interval`] with the uncertainty of the term as the recording fitted it: its
/// amplitude is known to a relative standard error of about `1/√lr` (`lr`, [`Pair::lr`]: the
/// term's likelihood-ratio statistic there), and the noncentrality scales with the amplitude
/// squared, so the run's statistic is a noncentral χ² of noncentrality `expected·(1 + ε)²`,
/// `ε ~ N(0, 1/lr)`; the interval is that mixture's quantiles (ε on 33 points over ±4σ).
/// Where `lr` is not finite and positive, [`evidence_interval`].
pub fn predictive_interval(expected: f64, df: usize, level: f64, lr: f64) -> (f64, f64) {
    if !(lr > 0.0 && lr.is_finite() && expected > 1e-9) {
        return evidence_interval(expected, df, level);
    }
    let (k, sigma) = (df.max(1) as f64, 1.0 / lr.sqrt());
    const POINTS: usize = 33;
    let z: Vec<f64> = (0..POINTS).map(|i| -4.0 + 8.0 * i as f64 / (POINTS - 1) as f64).collect();
    let w: Vec<f64> = z.iter().map(|z| (-0.5 * z * z).exp()).collect();
    let wsum: f64 = w.iter().sum();
    let lambdas: Vec<f64> = z.iter().map(|z| expected * (1.0 + sigma * z).powi(2)).collect();
    let cdf = |x: f64| -> f64 {
        lambdas.iter().zip(&w).map(|(l, w)| w * super::stats::ncx2_cdf(x, k, *l)).sum::<f64>() / wsum
    };
    let top = lambdas.iter().copied().fold(0.0, f64::max);
    let quantile = |p: f64| super::stats::quantile_of(&cdf, p, k + top);
    (quantile(0.5 * (1.0 - level)), quantile(0.5 * (1.0 + level)))
}

/// A run of candidate `c` on the design's rows ([`design`]): SIM the twin `sim` (seed
/// `seeds.0`), REAL the scenario `real` (seed `seeds.1`; its unit, thermal and, with `noise`,
/// noise tables), each one's white noise per row scaled to the mean of a row's worth of its
/// own logger's samples (so a row carries the density of the recording), prepared as the
/// diagnosis prepares a pair; the white-noise variance per row set as the design's
/// (`white_density`). Without `noise` the residual is what REAL's physics makes of the test
/// beside SIM's: [`realised_on`] then gives the evidence's true noncentrality.
pub fn run_on_design(
    sim: &Twin,
    real: &Twin,
    c: &Candidate,
    white_density: [f64; 3],
    seeds: (u64, u64),
    noise: bool,
) -> Result<Prepared, DiagnoseError> {
    let rate = (DESIGN_ROWS / c.duration_s()).min(sim.rate_hz());
    let rows = |tw: &Twin, seed: u64| -> Result<Vec<crate::recording::Row>, DiagnoseError> {
        let mut t: toml::Table =
            tw.scenario(c, rate, noise).parse().map_err(|e| DiagnoseError(format!("{}: {e}", tw.source)))?;
        let shrink = (rate / tw.rate_hz()).min(1.0).sqrt();
        if let Some(w) = t.get_mut("noise").and_then(|n| n.as_table_mut()).and_then(|n| n.get_mut("white_V")) {
            let num = |v: &toml::Value| v.as_float().or_else(|| v.as_integer().map(|i| i as f64));
            let scaled = match &*w {
                toml::Value::Array(a) => {
                    toml::Value::Array(a.iter().map(|v| toml::Value::Float(num(v).unwrap_or(0.0) * shrink)).collect())
                }
                v => toml::Value::Float(num(v).unwrap_or(0.0) * shrink),
            };
            *w = scaled;
        }
        let text = toml::to_string(&t).map_err(|e| DiagnoseError(e.to_string()))?;
        let name = Path::new(&tw.source);
        let sc = crate::sim::scenario::ScenarioFile::parse(&text, name).map_err(|e| DiagnoseError(e.to_string()))?;
        Ok(sc.build(name).map_err(|e| DiagnoseError(e.to_string()))?.all_rows(seed))
    };
    let (s, r) = (rows(sim, seeds.0)?, rows(real, seeds.1)?);
    let mut p = prep::prepare_blocks(&s, &r, Path::new(&sim.source), Path::new(&real.source), Some(0.0))?;
    for (axis, d) in white_density.iter().enumerate() {
        p.r_white[axis] = vec![d * rate; p.t.len()];
    }
    Ok(p)
}

/// Every candidate's expected evidence, best first (those that lift every pair to what it
/// needs first, then by the worst pair's evidence over what it needs, per hour). Candidates
/// whose rivals have no column at all are left out.
pub fn rank(
    d: &Diagnosis,
    twin: &Twin,
    pairs: &[Pair],
    cands: Vec<Candidate>,
    progress: &dyn Fn(usize, usize),
) -> Result<Vec<Evidence>, DiagnoseError> {
    let dens = white_density(&d.prepared);
    let mut out = Vec::new();
    let n = cands.len();
    for (i, c) in cands.into_iter().enumerate() {
        progress(i, n);
        let cp = design(twin, &c, dens)?;
        let deviance = evidence_on(d, &cp, pairs);
        // A rival with no column on the test (a cross-axis term in one orientation) cannot
        // mimic anything there: the test alone would never name it.
        let ratios: Vec<f64> =
            deviance.iter().zip(pairs).filter(|(v, _)| v.is_finite()).map(|(v, p)| v / p.needed).collect();
        if ratios.is_empty() {
            continue;
        }
        let worst = ratios.iter().copied().fold(f64::INFINITY, f64::min);
        let hours = c.duration_s() / 3600.0;
        out.push(Evidence {
            separates_all: worst >= 1.0,
            worst_ratio: worst,
            worst_ratio_per_h: worst / hours,
            deviance,
            candidate: c,
            if_others: Vec::new(),
            intervals: Vec::new(),
        });
    }
    progress(n, n);
    out.sort_by(|a, b| b.separates_all.cmp(&a.separates_all).then(b.worst_ratio_per_h.total_cmp(&a.worst_ratio_per_h)));
    Ok(out)
}

/// What `--propose` found.
pub struct Proposal {
    /// The pairs.
    pub pairs: Vec<Pair>,
    /// The limits used.
    pub limits: Limits,
    /// The candidates, best first.
    pub ranked: Vec<Evidence>,
}

/// The proposal for diagnosis `d` with the twin `twin` within `limits` (`None`: the
/// recording's, [`Limits::from_recording`]); `None` when nothing is left to separate.
pub fn propose(
    d: &Diagnosis,
    twin: &Twin,
    limits: Option<Limits>,
    progress: &dyn Fn(usize, usize),
) -> Result<Option<Proposal>, DiagnoseError> {
    let pairs = pairs(d);
    if pairs.is_empty() {
        return Ok(None);
    }
    let limits = limits.unwrap_or_else(|| Limits::from_recording(&d.prepared));
    let start = d.prepared.temp_s.first().copied().unwrap_or(20.0);
    let cands = candidates(&limits, start, hold_s(d, &pairs));
    let mut ranked = rank(d, twin, &pairs, cands, progress)?;
    if let Some(best) = ranked.first_mut() {
        let cp = design(twin, &best.candidate, white_density(&d.prepared))?;
        best.if_others = evidence_if_others_true(d, &cp, &pairs);
    }
    for e in ranked.iter_mut().take(REPORTED) {
        e.intervals = pairs.iter().enumerate().map(|(k, q)| intervals_of(e, k, q)).collect();
    }
    Ok(Some(Proposal { pairs, limits, ranked }))
}

/// The report's `proposal`: the limits, the pairs, every candidate with its length and its
/// evidence per pair, best first, and the file written (`None`: nothing to separate).
pub fn to_json(prop: Option<&Proposal>, file: Option<&Path>) -> serde_json::Value {
    use serde_json::json;
    let Some(p) = prop else {
        return json!({ "pairs": [], "candidates": [], "note": "nothing to separate: no test proposed" });
    };
    let num = |v: f64| if v.is_finite() { json!(v) } else { serde_json::Value::Null };
    let pairs: Vec<_> = p
        .pairs
        .iter()
        .map(|q| {
            json!({
                "axis": prep::AXES[q.axis], "modelled": q.a.id(), "rival": q.b.id(),
                "on_recording": num(q.recording), "needed": q.needed,
            })
        })
        .collect();
    let cands: Vec<_> = p
        .ranked
        .iter()
        .map(|e| {
            json!({
                "name": e.candidate.name, "what": e.candidate.what,
                "duration_h": e.candidate.duration_s() / 3600.0,
                "separates_all": e.separates_all, "worst_ratio": num(e.worst_ratio),
                "worst_ratio_per_h": num(e.worst_ratio_per_h),
                "deviance": e.deviance.iter().map(|v| num(*v)).collect::<Vec<_>>(),
                "deviance_90": (0..p.pairs.len()).map(|k| {
                    e.intervals.get(k).cloned().flatten().map_or(serde_json::Value::Null, |iv| json!(iv))
                }).collect::<Vec<_>>(),
                "deviance_if_others_true": e.if_others.iter().map(|v| {
                    v.iter().map(|(m, x)| json!({ "true": m.id(), "deviance": num(*x) })).collect::<Vec<_>>()
                }).collect::<Vec<_>>(),
            })
        })
        .collect();
    json!({
        "limits": {
            "chamber_min_C": p.limits.temp_min_c, "chamber_max_C": p.limits.temp_max_c,
            "max_rate_C_per_min": p.limits.max_rate_c_per_min, "max_test_h": p.limits.max_duration_s / 3600.0,
        },
        "pairs": pairs,
        "candidates": cands,
        "file": file.map(|f| f.display().to_string()),
    })
}

/// The plot of the best candidate: its temperature (`temp_C`, smoothed) and `power_s` against
/// time, and below them, for its worst pair, what the modelled term predicts on that test (as
/// fitted on the recording) beside the rival refitted to it as the separability refits it
/// (generalised least squares under the recording's noise model with the nuisance columns
/// free, the rival's θ where it fits best; absent where the rival is not one of the library's
/// mechanisms), in mg; each curve broken at the unpowered gaps (one line per session). PNG
/// bytes, written by the caller with its other outputs.
pub fn plot(d: &Diagnosis, twin: &Twin, prop: &Proposal, path: &Path) -> Result<Vec<u8>, DiagnoseError> {
    use super::plot::{drawing_error, render_png};
    use plotters::prelude::*;
    use plotters::style::{FontStyle, register_font};
    let _ = register_font("sans-serif", FontStyle::Normal, super::plot::FONT);
    let best = prop.ranked.first().ok_or_else(|| DiagnoseError(format!("{}: no candidate", path.display())))?;
    let cp = design(twin, &best.candidate, white_density(&d.prepared))?;
    let k = (0..prop.pairs.len())
        .filter(|&k| best.deviance[k].is_finite())
        .min_by(|&i, &j| {
            (best.deviance[i] / prop.pairs[i].needed).total_cmp(&(best.deviance[j] / prop.pairs[j].needed))
        })
        .unwrap_or(0);
    let pair = prop.pairs[k];
    let ctx = context_on(d, &cp, pair.axis);
    let fit = &d.axes[pair.axis];
    let term = fit.terms.iter().find(|t| t.mech == pair.a);
    let eta: Vec<f64> = match term {
        Some(t) => super::separate::predict(
            &ctx,
            &[super::separate::Fitted { mech: t.mech, theta: t.theta, coef: t.coef.clone() }],
        ),
        None => vec![0.0; cp.t.len()],
    };
    let rival: Option<Vec<f64>> = {
        let refit = super::separate::Refit::new(&ctx, fit.q, fit.deviance_scale, &eta, &ctx.nuisance);
        refit
            .mechanism(pair.b)
            .and_then(|s| refit.fitted(&ctx.nuisance, &ctx.columns(pair.b, s.rival_theta.unwrap_or(0.0))))
    };
    let hours: Vec<f64> = cp.t.iter().map(|t| t / 3600.0).collect();
    let power_h: Vec<f64> = cp.power.clone().unwrap_or_default().iter().map(|p| p / 3600.0).collect();
    let rng = |v: &mut dyn Iterator<Item = f64>| {
        let (a, b) =
            v.filter(|x| x.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
        if b > a { (a - 0.05 * (b - a), b + 0.05 * (b - a)) } else { (a - 1.0, a + 1.0) }
    };
    let x1 = hours.last().copied().unwrap_or(1.0).max(1e-3);
    let mg = |v: &[f64]| -> Vec<f64> {
        let m = v.iter().sum::<f64>() / v.len().max(1) as f64;
        v.iter().map(|x| (x - m) * 1e3).collect()
    };
    let (ea, eb) = (mg(&eta), rival.as_deref().map(mg));
    let c = &best.candidate;
    let sessions = cp.sessions();
    // One line per session: nothing is drawn across an unpowered gap.
    let by_session = |v: &[f64]| -> Vec<Vec<(f64, f64)>> {
        sessions.iter().map(|r| r.clone().map(|i| (hours[i], v[i])).collect()).collect()
    };
    render_png(path, (1000, 900), |root| {
        let panels = root.split_evenly((3, 1));
        type Panel<'a> = (&'a str, String, Vec<Vec<(f64, f64)>>);
        let series: [Panel; 2] = [
            (
                "temp_C [°C]",
                format!("{}: {:.1} h — {}", c.name, c.duration_s() / 3600.0, c.what),
                by_session(&cp.temp_s),
            ),
            ("power_s [h]", "time since power-on".into(), by_session(&power_h)),
        ];
        for (area, (ylab, title, segments)) in panels.iter().zip(series) {
            let (y0, y1) = rng(&mut segments.iter().flatten().map(|p| p.1));
            let mut ch = ChartBuilder::on(area)
                .caption(title, ("sans-serif", 15))
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..x1, y0..y1)
                .map_err(drawing_error)?;
            ch.configure_mesh().x_desc("time [h]").y_desc(ylab).draw().map_err(drawing_error)?;
            for pts in segments {
                ch.draw_series(LineSeries::new(pts, RGBColor(31, 119, 180).stroke_width(2))).map_err(drawing_error)?;
            }
        }
        let (y0, y1) = rng(&mut ea.iter().chain(eb.iter().flatten()).copied());
        let mut ch = ChartBuilder::on(&panels[2])
            .caption(
                format!(
                    "accelerometer {}: {} as fitted vs {} refitted (expected deviance {:.1}, a name needs {:.1})",
                    prep::AXES[pair.axis],
                    pair.a.id(),
                    pair.b.id(),
                    best.deviance[k],
                    pair.needed
                ),
                ("sans-serif", 15),
            )
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..x1, y0..y1)
            .map_err(drawing_error)?;
        ch.configure_mesh().x_desc("time [h]").y_desc("predicted [mg]").draw().map_err(drawing_error)?;
        let ca = RGBColor(214, 39, 40);
        for (s, pts) in by_session(&ea).into_iter().enumerate() {
            let drawn = ch.draw_series(LineSeries::new(pts, ca.stroke_width(2))).map_err(drawing_error)?;
            if s == 0 {
                drawn
                    .label(pair.a.id())
                    .legend(move |(x, y)| PathElement::new([(x, y), (x + 14, y)], ca.stroke_width(2)));
            }
        }
        if let Some(eb) = &eb {
            let cb = RGBColor(44, 160, 44);
            for (s, pts) in by_session(eb).into_iter().enumerate() {
                let drawn = ch.draw_series(LineSeries::new(pts, cb.stroke_width(2))).map_err(drawing_error)?;
                if s == 0 {
                    drawn
                        .label(format!("{} refitted", pair.b.id()))
                        .legend(move |(x, y)| PathElement::new([(x, y), (x + 14, y)], cb.stroke_width(2)));
                }
            }
        }
        ch.configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(drawing_error)
    })
}

#[cfg(test)]
mod tests {
    use super::{evidence_interval, predictive_interval};
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    /// The predictive interval against draws made as it describes them, independently: an
    /// amplitude off by `ε ~ N(0, 1/lr)`, then the run's noise on each of the term's `df`
    /// columns. Also: it tends to the noise-only interval as the recording knows the term
    /// exactly, and is wider than it otherwise.
    #[test]
    fn predictive_interval_covers_the_amplitude_and_the_noise() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let n = 100_000;
        for (expected, df, lr) in [(60.0, 1usize, 40.0), (150.0, 2, 400.0), (20.0, 3, 15.0)] {
            let (lo, hi) = predictive_interval(expected, df, 0.9, lr);
            let (nlo, nhi) = evidence_interval(expected, df, 0.9);
            assert!(lo < nlo && hi > nhi, "({expected}, {df}, {lr}): {lo}–{hi} vs noise alone {nlo}–{nhi}");
            let mut inside = 0usize;
            for _ in 0..n {
                let e: f64 = StandardNormal.sample(&mut rng);
                let m = (expected * (1.0 + e / lr.sqrt()).powi(2)).sqrt();
                let x: f64 = (0..df)
                    .map(|j| {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        if j == 0 { (z + m).powi(2) } else { z * z }
                    })
                    .sum();
                inside += usize::from((lo..=hi).contains(&x));
            }
            // Binomial standard error of a 90 % share over 100 000 draws: 0.00095.
            let share = inside as f64 / n as f64;
            assert!((share - 0.9).abs() < 0.005, "({expected}, {df}, {lr}): {share}");
        }
        let (lo, hi) = predictive_interval(80.0, 2, 0.9, 1e12);
        let (nlo, nhi) = evidence_interval(80.0, 2, 0.9);
        assert!((lo / nlo - 1.0).abs() < 1e-3 && (hi / nhi - 1.0).abs() < 1e-3, "{lo}–{hi} vs {nlo}–{nhi}");
    }
}
