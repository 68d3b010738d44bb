//! The JSON report and the augmented model (the found terms, calibration-style TOML).

use super::fit::AxisFit;
use super::locate::Stratum;
use super::mech::{Mech, Sensitivity, separating_test};
use super::noise::{ScalePoint, short_tau_q, structure, structure_scales};
use super::prep::{AXES, Prepared};
use super::stats::allan_dev;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;

/// Values per accelerometer, keyed `x`, `y`, `z`.
pub type PerAxis<T> = BTreeMap<String, T>;

/// One found effect.
#[derive(Clone, Debug, Serialize)]
pub struct Effect {
    /// Mechanism id.
    pub id: String,
    /// Accelerometers it was found on.
    pub axes: Vec<String>,
    /// Fitted parameters per accelerometer (names carry the unit).
    pub params: PerAxis<BTreeMap<String, f64>>,
    /// 95 % intervals of the parameters.
    pub ci: PerAxis<BTreeMap<String, [f64; 2]>>,
    /// What the mechanism is.
    pub explanation: String,
    /// Likelihood-ratio statistic and p-value for dropping it, per accelerometer.
    pub significance: PerAxis<[f64; 2]>,
    /// Per accelerometer: the cut of the raw held-out RMS it brings (the model without it, or
    /// the offset alone where that is lower, minus the model: never more than the printed
    /// "before" minus "after") and that cut's fold-to-fold standard error \[mg\]; a term is
    /// named only when the cut exceeds its standard error.
    pub heldout_cut_mg: PerAxis<[f64; 2]>,
    /// Per accelerometer, parameters the data does not determine: a 95 % interval spanning
    /// [`UNDETERMINED_RATIO`] or more. Their values are not findings.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub undetermined: PerAxis<Vec<String>>,
    /// Per accelerometer, the closest rivals (at most three) and the deviance each, refitted,
    /// cannot absorb of what the term predicts on this recording ([`super::separate`]): how
    /// far the recording separates the name from the next explanation.
    pub separability: PerAxis<BTreeMap<String, f64>>,
}

/// A time constant or width whose 95 % interval spans this ratio (two decades) or more is
/// reported as undetermined.
pub const UNDETERMINED_RATIO: f64 = 100.0;

/// Mechanisms the data cannot separate.
#[derive(Clone, Debug, Serialize)]
pub struct Ambiguous {
    /// The mechanism ids (sorted).
    pub ids: Vec<String>,
    /// Accelerometers.
    pub axes: Vec<String>,
    /// The test that would separate them.
    pub separating_test: String,
    /// Which one the model carries (for the RMS figures and the augmented model).
    pub modelled_as: String,
    /// Deviance difference of the alternatives on the data, per accelerometer (absent where
    /// an alternative joined on its separability alone).
    pub deviance_difference: PerAxis<BTreeMap<String, f64>>,
    /// Per accelerometer, the deviance each alternative, refitted, cannot absorb of what the
    /// modelled member predicts on this recording ([`super::separate`]); below the separation
    /// a name needs the two are one group whatever the data's ranking says.
    pub separability: PerAxis<BTreeMap<String, f64>>,
    /// The separation a name needs, per accelerometer: the expected deviance at which data
    /// drawn from the modelled member pass its naming threshold against the rival with 95 %
    /// probability ([`super::separate::separation_needed`]).
    pub separation_needed: PerAxis<f64>,
}

/// A term the selection keeps (it passes the tests) whose held-out cut is not material: below
/// [`MATERIAL_FLOOR_SHARE`] of the axis's noise floor or under [`MATERIAL_SE`] standard errors.
/// It stays in the fitted model and its figures; it is not an effect a user acts on.
#[derive(Clone, Debug, Serialize)]
pub struct Negligible {
    /// Mechanism id (or the ids of an ambiguous group, joined by `/`).
    pub id: String,
    /// Accelerometer.
    pub axis: String,
    /// The cut of the raw held-out RMS it brings \[mg\].
    pub heldout_cut_mg: f64,
    /// That cut's fold-to-fold standard error \[mg\].
    pub heldout_cut_se_mg: f64,
    /// The axis's noise floor \[mg\].
    pub noise_floor_mg: f64,
}

/// An effect is printed only where its held-out cut is at least this share of the axis's noise
/// floor ([`Report::noise_floor_mg`]) …
pub const MATERIAL_FLOOR_SHARE: f64 = 0.05;

/// … and at least this many of its fold-to-fold standard errors.
pub const MATERIAL_SE: f64 = 2.0;

/// Whether a held-out cut `(cut, se)` \[g\] is material against the noise floor `floor_g`.
pub fn material(cut: (f64, f64), floor_g: f64) -> bool {
    cut.0 >= MATERIAL_FLOOR_SHARE * floor_g && cut.0 >= MATERIAL_SE * cut.1
}

/// One point of the Allan deviation of the residual in the static segments
/// ([`crate::allan`]'s overlapping estimator).
#[derive(Clone, Debug, Serialize)]
pub struct AllanPoint {
    /// Averaging time \[s\].
    pub tau_s: f64,
    /// Allan deviation per accelerometer before the named terms (REAL − SIM) \[mg\] (absent
    /// where no segment is long enough).
    pub adev_mg: PerAxis<f64>,
    /// After the named terms (and located bias steps) \[mg\].
    pub after_mg: PerAxis<f64>,
    /// The noise model's line: white noise at the floor and the random walk the mechanisms
    /// were tested against ([`allan_curves`]) \[mg\].
    pub model_mg: PerAxis<f64>,
}

/// One averaging time of [`Report::scales`].
#[derive(Clone, Debug, Serialize)]
pub struct ScaleRow {
    /// Averaging time \[s\].
    pub tau_s: f64,
    /// Standard deviation of the block means of the held-out residual before the model \[mg\].
    pub before_mg: f64,
    /// After the model \[mg\].
    pub after_mg: f64,
    /// What the measured short-τ noise (coloured noise included) gives there \[mg\].
    pub noise_mg: f64,
    /// Above this the spread is structure \[mg\].
    pub limit_mg: f64,
}

/// One step of the forward search.
#[derive(Clone, Debug, Serialize)]
pub struct SearchStep {
    /// Mechanism.
    pub id: String,
    /// Its best grid θ.
    pub theta: Option<f64>,
    /// LR statistic (autocorrelation-inflated).
    pub lr: f64,
    /// Degrees of freedom.
    pub df: usize,
    /// p-value.
    pub p: f64,
    /// BIC improvement.
    pub dbic: f64,
    /// Held-out improvement / residual variance.
    pub dcv: f64,
    /// Accepted.
    pub accepted: bool,
}

/// One located bias step.
#[derive(Clone, Debug, Serialize)]
pub struct StepReport {
    /// Accelerometer.
    pub axis: String,
    /// Time of the first sample at the new level \[s\].
    pub time_s: f64,
    /// REAL's line of that sample.
    pub line: u64,
    /// Size (new level − old level) \[mg\].
    pub size_mg: f64,
    /// Its standard error \[mg\].
    pub se_mg: f64,
    /// The scan statistic (robustly standardised) with the other steps in the model; NaN
    /// (`null` in the JSON) when the steps located against the final model still differed
    /// from those fitted after three rounds (the fitted ones are reported).
    pub z: f64,
}

impl StepReport {
    /// The report's entry for `step` on accelerometer `axis`.
    pub fn new(p: &Prepared, axis: usize, step: &super::steps::BiasStep) -> Self {
        StepReport {
            axis: AXES[axis].into(),
            time_s: step.time_s,
            line: p.line[step.row],
            size_mg: step.size_g * 1e3,
            se_mg: step.se_g * 1e3,
            z: step.z,
        }
    }
}

/// A term of the augmented model.
#[derive(Clone, Debug, Serialize)]
pub struct ModelTerm {
    /// Mechanism id.
    pub id: String,
    /// Accelerometer.
    pub axis: String,
    /// Parameters (as in the effect).
    pub params: BTreeMap<String, f64>,
    /// Whether the data could not tell it from another mechanism.
    pub ambiguous: bool,
    /// Parameters the data does not determine (see [`Effect::undetermined`]); left out of
    /// the `[thermal_dynamics]` table.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub undetermined: Vec<String>,
    /// Its held-out cut is not material ([`Negligible`]): left out of the
    /// `[thermal_dynamics]` table.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub negligible: bool,
}

/// The augmented model: the found terms, to add to the simulation.
#[derive(Clone, Debug, Serialize)]
pub struct AugmentedModel {
    /// Reference temperature of the polynomial terms [°C].
    pub t0_c: f64,
    /// SIM's temperature sensitivity used by the thermal terms, per accelerometer:
    /// `S = Σ_p ΔTᵖ (c_p0 + c_px f_x + c_py f_y + c_pz f_z)` \[g\]; absent: free form `S = ΔT`.
    pub sensitivity: PerAxis<Vec<[f64; 4]>>,
    /// The terms.
    pub term: Vec<ModelTerm>,
    /// The thermal dynamics the terms name, as the calibration file's `[thermal_dynamics]`
    /// (`bins-cal calibrate --dynamics MODEL.toml` merges it): absent when none is named.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub thermal_dynamics: Option<crate::calfile::DynamicsSpec>,
}

/// The `[thermal_dynamics]` table of the named terms: `thermal_lag` → `lag_tau_s`,
/// `thermal_hysteresis` → `hysteresis_width_C`, `self_heating` → `self_heating_C` and
/// `self_heating_tau_s` (in °C only when SIM's temperature sensitivity was fitted),
/// `bias_hysteresis` → `bias_play_width_C` and `bias_play_mg` (its constant amplitude; the
/// term linear in ΔT has no counterpart in the core). The core has one lag, one play and one
/// self-heating for the unit: a parameter found on several accelerometers is their median.
/// Terms the data could not tell from another mechanism are left out.
pub fn dynamics_table(terms: &[ModelTerm]) -> Option<crate::calfile::DynamicsSpec> {
    let median = |id: &str, key: &str| -> Option<f64> {
        let mut v: Vec<f64> = terms
            .iter()
            .filter(|t| t.id == id && !t.ambiguous && !t.negligible && t.undetermined.is_empty())
            .filter_map(|t| t.params.get(key).copied())
            .filter(|x| x.is_finite())
            .collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        Some(if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) })
    };
    let mut d = crate::calfile::DynamicsSpec::default();
    let mut any = false;
    if let Some(tau) = median("thermal_lag", "tau_s") {
        d.lag_tau_s = tau;
        any = true;
    }
    if let Some(h) = median("thermal_hysteresis", "width_C") {
        d.hysteresis_width_c = h;
        any = true;
    }
    if let (Some(rise), Some(tau)) = (median("self_heating", "rise_C"), median("self_heating", "tau_s")) {
        d.self_heating_c = rise;
        d.self_heating_tau_s = tau;
        any = true;
    }
    if let Some(hb) = median("bias_hysteresis", "width_C") {
        d.bias_play_width_c = hb;
        for t in terms
            .iter()
            .filter(|t| t.id == "bias_hysteresis" && !t.ambiguous && !t.negligible && t.undetermined.is_empty())
        {
            if let (Some(k), Some(a)) = (AXES.iter().position(|a| *a == t.axis), t.params.get("amp_mg")) {
                d.bias_play_mg[k] = *a;
            }
        }
        any = true;
    }
    any.then_some(d)
}

/// The report.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// SIM file.
    pub sim: String,
    /// REAL file.
    pub real: String,
    /// Data rows.
    pub rows: usize,
    /// Rows with a known reference (used).
    pub rows_used: usize,
    /// Scale factors used [V/g].
    pub scale_v_per_g: PerAxis<f64>,
    /// Notes (fallbacks, skipped rows).
    pub notes: Vec<String>,
    /// Per-sample white noise of the residual in the static segments (Allan deviation at the
    /// sample period) \[mg\].
    pub noise_floor_mg: PerAxis<f64>,
    /// Allan deviation of the residual in the static segments.
    pub allan: Vec<AllanPoint>,
    /// Random-walk intensity the mechanisms were tested against, as drift per √hour [mg/√h].
    pub random_walk_mg_per_sqrt_h: PerAxis<f64>,
    /// Where that random walk comes from: `given` (`--random-walk`), the noise file's path
    /// (`--noise`, scaled to the residual: [`super::noise::SensorNoise`]) or `estimated`
    /// (restricted maximum likelihood with the richest model in).
    pub random_walk_source: String,
    /// The bias instability given (`--bias-instability` with `--bias-tau`, or `--noise`), per
    /// accelerometer: its standard deviation \[mg\] and correlation time \[s\], a state of the
    /// noise model beside the random walk; absent where none was given.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub bias_instability_mg_tau_s: PerAxis<(f64, f64)>,
    /// The die's rise over the thermistor after each power-on that SIM shows
    /// ([`super::mech::die_rise`]): the temperature and thermal terms act on the thermistor's
    /// reading plus this rise. Absent when SIM shows none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sim_die_rise: Option<super::mech::DieRise>,
    /// The sensor's own random walk [mg/√h]: from the Hadamard variance of what the model
    /// leaves in the static segments, at averaging times up to a minute
    /// ([`short_tau_q`]); absent when no segment is long enough.
    pub sensor_random_walk_mg_per_sqrt_h: PerAxis<f64>,
    /// RMS of the drift (the random-walk level of what the model leaves, smoothed) \[mg\]:
    /// reported and drawn on its own, never subtracted from the figures.
    pub drift_rms_mg: PerAxis<f64>,
    /// Structure above the noise that the model does not explain, at the time scale where it
    /// stands out most ([`structure`]): `√(sd² − noise²)` of the block means of the held-out
    /// residual after the model \[mg\]; 0 where no time scale shows structure.
    pub unexplained_rms_mg: PerAxis<f64>,
    /// The averaging time of [`Report::unexplained_rms_mg`] \[s\] (absent: none).
    pub unexplained_scale_s: PerAxis<f64>,
    /// The held-out residual at every averaging time from 1 s to a tenth of the record, before
    /// and after the model, against the noise there ([`structure_scales`]).
    pub scales: PerAxis<Vec<ScaleRow>>,
    /// Per accelerometer, one of `at the noise` (nothing named, and no time scale shows
    /// structure above the noise), `explained` (named terms, and what they leave shows none),
    /// `partly explained` (they cut the structure by ≥ 30 %), `unexplained`.
    pub verdict: PerAxis<String>,
    /// SIM's own calibration terms re-fitted with every model, per accelerometer (when SIM is
    /// a least-squares calibration of this very recording); never named as a mechanism.
    pub sim_terms_refitted: PerAxis<Vec<String>>,
    /// Strata where the raw residual departs from its mean beyond the noise model.
    pub located: Vec<Stratum>,
    /// Strata where what the model leaves departs from its mean beyond the noise model: where
    /// the unexplained structure is.
    pub unexplained_located: Vec<Stratum>,
    /// The named mechanisms.
    pub effects: Vec<Effect>,
    /// Groups the data cannot separate.
    pub ambiguous: Vec<Ambiguous>,
    /// Terms (or groups) kept by the selection whose held-out cut is not material
    /// ([`material`]): listed with their figures, not effects.
    pub negligible: Vec<Negligible>,
    /// RMS of the raw residual (one offset removed) before the model \[mg\].
    pub rms_before_mg: PerAxis<f64>,
    /// After the model \[mg\].
    pub rms_after_mg: PerAxis<f64>,
    /// Held-out (coefficients and offset fitted without the block) before \[mg\].
    pub heldout_rms_before_mg: PerAxis<f64>,
    /// Held-out after \[mg\].
    pub heldout_rms_after_mg: PerAxis<f64>,
    /// Bias steps located in the residual (a jump of its level at one time), fitted jointly
    /// with the named mechanisms ([`super::steps`]).
    pub steps: Vec<StepReport>,
    /// The forward search per accelerometer.
    pub search: PerAxis<Vec<SearchStep>>,
    /// The augmented model.
    pub model: AugmentedModel,
}

/// Cluster sizes of the diagnosis's Allan curve: octaves while two clusters fit the longest of
/// `runs`.
fn curve_sizes(runs: &[(usize, usize)]) -> Vec<usize> {
    let longest = runs.iter().map(|(a, b)| b - a).max().unwrap_or(0);
    let mut ms = Vec::new();
    let mut m = 1;
    while 2 * m < longest {
        ms.push(m);
        m *= 2;
    }
    ms
}

/// Noise floor per accelerometer \[g\] and the Allan curve before the model, from the static
/// segments without vibration (all segments when there are none).
pub fn noise_floor(p: &Prepared) -> ([f64; 3], Vec<AllanPoint>) {
    let n = p.t.len();
    let use_runs = p.static_runs();
    let ms = curve_sizes(&use_runs);
    let mut floor = [0.0; 3];
    let mut curve: BTreeMap<usize, PerAxis<f64>> = BTreeMap::new();
    for axis in 0..3 {
        let segs: Vec<&[f64]> = use_runs.iter().map(|&(a, b)| &p.r[axis][a..b]).collect();
        let ad = allan_dev(&segs, &ms);
        for (m, a, _) in &ad {
            curve.entry(*m).or_default().insert(AXES[axis].into(), a * 1e3);
        }
        floor[axis] = match p.row_floor {
            // Blocks: the rows' own differences; the curve starts at one block.
            Some(f) => f[axis],
            None => ad.first().map_or_else(|| p.r_white[axis].iter().sum::<f64>().sqrt() / (n as f64).sqrt(), |x| x.1),
        };
    }
    let allan = curve
        .into_iter()
        .map(|(m, a)| AllanPoint {
            tau_s: m as f64 * p.dt,
            adev_mg: a,
            after_mg: PerAxis::new(),
            model_mg: PerAxis::new(),
        })
        .collect();
    (floor, allan)
}

/// The Allan curve `before` ([`noise_floor`]'s) completed with the deviation after the named
/// terms (the residual less each axis's prediction, in the same static segments) and the noise
/// model's line, `σ²(m) = σ_w²/m + q·τ₀(2m² + 1)/(6m)`: the white floor `σ_w` of a row and the
/// random walk `q` \[g²/s\] the mechanisms were tested against
/// ([`crate::allan::twin::rw_avar`], the exact Allan variance of a sampled random walk), plus
/// the given bias instability's ([`crate::allan::twin::gm_avar`]) where there is one.
pub fn allan_curves(p: &Prepared, floor: &[f64; 3], before: Vec<AllanPoint>, axes: &[AxisFit]) -> Vec<AllanPoint> {
    let runs = p.static_runs();
    let ms = curve_sizes(&runs);
    let mut out = before;
    for fit in axes {
        let ax = AXES[fit.axis];
        let e: Vec<f64> = p.r[fit.axis].iter().zip(&fit.prediction).map(|(a, b)| a - b).collect();
        let segs: Vec<&[f64]> = runs.iter().map(|&(a, b)| &e[a..b]).collect();
        for (m, a, _) in allan_dev(&segs, &ms) {
            let tau_s = m as f64 * p.dt;
            let gm = fit.gm.map_or(0.0, |g| g.var_g2 * crate::allan::twin::gm_avar(m as f64, p.dt, g.tau_s));
            let model =
                (floor[fit.axis].powi(2) / m as f64 + fit.q * crate::allan::twin::rw_avar(m as f64, p.dt) + gm).sqrt();
            if let Some(pt) = out.iter_mut().find(|pt| (pt.tau_s - tau_s).abs() <= 1e-9 * tau_s) {
                pt.after_mg.insert(ax.into(), a * 1e3);
                pt.model_mg.insert(ax.into(), model * 1e3);
            }
        }
    }
    out
}

fn per_axis<T>(f: impl Fn(usize) -> T) -> PerAxis<T> {
    (0..3).map(|i| (AXES[i].to_string(), f(i))).collect()
}

/// Parameters and 95 % intervals of a term, in report units.
pub fn term_params(
    term: &super::fit::Term,
    s: &Sensitivity,
    axis: usize,
) -> (BTreeMap<String, f64>, BTreeMap<String, [f64; 2]>) {
    let names = coef_names(term.mech, s, axis);
    let mut params = BTreeMap::new();
    let mut ci = BTreeMap::new();
    if let (Some(name), Some(th)) = (term.mech.theta(), term.theta) {
        params.insert(name.to_string(), th);
        if let Some((lo, hi)) = term.theta_ci {
            ci.insert(name.to_string(), [lo, hi]);
        }
    }
    if let (Some(ratio), Some(th)) = (term.fast_ratio, term.theta) {
        params.insert("tau_fast_s".to_string(), th / ratio);
    }
    for ((name, factor), (c, se)) in names.iter().zip(term.coef.iter().zip(&term.se)) {
        params.insert(name.clone(), c * factor);
        ci.insert(name.clone(), [(c - 1.96 * se) * factor, (c + 1.96 * se) * factor]);
    }
    (params, ci)
}

/// Coefficient names of a mechanism on `axis`, with the scale each is reported in.
pub fn coef_names(m: Mech, s: &Sensitivity, axis: usize) -> Vec<(String, f64)> {
    // Built without data: the names depend only on the mechanism, the axis and the form of S.
    let ax = ["x", "y", "z"];
    let i = axis;
    let (j, k) = ((i + 1) % 3, (i + 2) % 3);
    match m {
        Mech::ThermalLag | Mech::ThermalHysteresis => {
            if s.from_sim {
                vec![("gain".into(), 1.0)]
            } else {
                vec![("coef_mg_per_C".into(), 1e3)]
            }
        }
        Mech::SelfHeating => {
            if s.from_sim {
                vec![("rise_C".into(), 1.0)]
            } else {
                vec![("amp_mg".into(), 1e3)]
            }
        }
        Mech::Warmup => vec![("amp_mg".into(), 1e3), ("amp_fast_mg".into(), 1e3)],
        Mech::BiasHysteresis => vec![("amp_mg".into(), 1e3), ("amp_mg_per_C".into(), 1e3)],
        Mech::BiasTempOrder => {
            vec![("b1_mg_per_C".into(), 1e3), ("b2_mg_per_C2".into(), 1e3), ("b3_mg_per_C3".into(), 1e3)]
        }
        Mech::ScaleTemp => vec![("s1_ppm_per_C".into(), 1e6), ("s2_ppm_per_C2".into(), 1e6)],
        Mech::CrossCouplingTemp => vec![
            (format!("c_{}{}_ppm_per_C", ax[i], ax[j]), 1e6),
            (format!("c_{}{}_ppm_per_C", ax[i], ax[k]), 1e6),
            (format!("c_{}{}_ppm_per_C2", ax[i], ax[j]), 1e6),
            (format!("c_{}{}_ppm_per_C2", ax[i], ax[k]), 1e6),
        ],
        Mech::CrossAxis => vec![(format!("m_{}{}_ppm", ax[i], ax[j]), 1e6), (format!("m_{}{}_ppm", ax[i], ax[k]), 1e6)],
        Mech::ScaleFactor => vec![("sf_ppm".into(), 1e6)],
        Mech::SfAsymmetry => vec![("delta_1a_ppm".into(), 1e6)],
        Mech::NonlinearityK2 => vec![("k2_ug_per_g2".into(), 1e6)],
        Mech::NonlinearityK3 => vec![("k3_ug_per_g3".into(), 1e6)],
        Mech::VibrationCross => vec![("m31_ug_per_g2".into(), 1e6), ("m32_ug_per_g2".into(), 1e6)],
        Mech::Drift => vec![("amp_mg".into(), 1e3)],
    }
}

/// The static term a tempco folds in when both are found on an accelerometer.
fn folds(m: Mech) -> Option<Mech> {
    match m {
        Mech::ScaleTemp => Some(Mech::ScaleFactor),
        Mech::CrossCouplingTemp => Some(Mech::CrossAxis),
        _ => None,
    }
}

/// Structure left after the model is within what the random walk the mechanisms were tested
/// against could make when its size is at most this many times the walk's wander `√(q·T)` over
/// the longest session `T`: a smooth structure of RMS `s` over `T` is a drift of range about
/// `√12·s`, which that random walk makes with a likelihood ratio of about `12·s²/(q·T)`; at
/// twice the wander that is 48, beyond the 20–30 the selection asks of a mechanism, so below it
/// the random walk can hide a mechanism of that size (the report then says so).
pub const RANDOM_WALK_HIDES: f64 = 2.0;

/// The verdict on one accelerometer from the structure above the noise (its size at the
/// scale where it stands out most, [`structure`]) before and after the model, and whether a
/// term is named: one story per axis ("at the noise" never beside a named term or structure).
pub fn verdict(before: Option<f64>, after: Option<f64>, named: bool) -> &'static str {
    match (named, before, after) {
        (false, None, None) => "at the noise",
        (true, _, None) => "explained",
        (true, Some(b), Some(a)) if a <= 0.7 * b => "partly explained",
        _ => "unexplained",
    }
}

/// The structure scales of one accelerometer: the held-out residuals of `fit`, the noise
/// level measured at ≈ 1 s (the Allan variance of the raw residual in the static segments,
/// or of the held-out residual over all rows when none is long enough) against the white
/// variances of [`Prepared::r_white`].
pub fn axis_scales(p: &Prepared, fit: &AxisFit) -> Vec<ScalePoint> {
    let axis = fit.axis;
    let m0 = ((1.0 / p.dt.max(1e-9)).round() as usize).max(1);
    let runs: Vec<(usize, usize)> = p.static_runs().into_iter().filter(|(a, b)| b - a > 2 * m0).collect();
    let (segs, rw): (Vec<&[f64]>, Vec<&[f64]>) = if runs.is_empty() {
        (vec![fit.heldout_resid.1.as_slice()], vec![p.r_white[axis].as_slice()])
    } else {
        runs.iter().map(|&(a, b)| (&p.r[axis][a..b], &p.r_white[axis][a..b])).unzip()
    };
    let measured = allan_dev(&segs, &[m0]).first().map(|x| x.1 * x.1);
    let (sr, nr) = rw.iter().fold((0.0, 0usize), |(s, c), v| (s + v.iter().sum::<f64>(), c + v.len()));
    let white = sr / nr.max(1) as f64 / m0 as f64;
    let kappa = match measured {
        Some(v) if white > 0.0 && v.is_finite() => v / white,
        _ => 1.0,
    };
    structure_scales(&fit.heldout_resid.0, &fit.heldout_resid.1, &p.r_white[axis], kappa, m0, p.dt)
}

/// What the report names besides the data.
pub struct Inputs<'a> {
    /// SIM's file.
    pub sim: &'a Path,
    /// REAL's file.
    pub real: &'a Path,
    /// The options the diagnosis ran with.
    pub opt: &'a super::Options,
    /// Per accelerometer, SIM's own terms re-fitted as a nuisance.
    pub nuisance: &'a [Vec<String>],
}

/// Accelerometers, the mechanism modelled, deviance differences per accelerometer.
/// A group being built: its axes, the member modelled, the data's deviance differences, the
/// separabilities and the naming thresholds, per axis.
type AmbGroup = (Vec<String>, String, PerAxis<BTreeMap<String, f64>>, PerAxis<BTreeMap<String, f64>>, PerAxis<f64>);

/// A group being built on one accelerometer: the members modelled, every id, the data's
/// deviance differences, the separabilities, the naming threshold (NaN: none).
type Local = (Vec<Mech>, Vec<Mech>, BTreeMap<String, f64>, BTreeMap<String, f64>, f64);

/// Merges group `g` into `e`: members and ids once each, in order; the figures of both; the
/// larger threshold.
fn absorb(e: &mut Local, g: Local) {
    for m in g.0 {
        if !e.0.contains(&m) {
            e.0.push(m);
        }
    }
    for m in g.1 {
        if !e.1.contains(&m) {
            e.1.push(m);
        }
    }
    e.2.extend(g.2);
    e.3.extend(g.3);
    e.4 = if e.4.is_nan() { g.4 } else { e.4.max(g.4) };
}

/// Removes the groups at `ks` (ascending) from `local` and returns them and `more` as one group
/// ([`absorb`]), its members in the library's order.
fn merge_out(local: &mut Vec<Local>, ks: &[usize], more: impl IntoIterator<Item = Local>) -> Local {
    let mut joined: Local = (Vec::new(), Vec::new(), BTreeMap::new(), BTreeMap::new(), f64::NAN);
    for &k in ks.iter().rev() {
        absorb(&mut joined, local.remove(k));
    }
    for g in more {
        absorb(&mut joined, g);
    }
    joined.0.sort_by_key(|m| Mech::ALL.iter().position(|a| a == m));
    joined
}

/// The separability of rival `b` against the term `m` of `fit` ([`AxisFit::separability`]).
fn separability_of(fit: &AxisFit, m: Mech, b: Mech) -> Option<f64> {
    fit.separability.iter().find(|(a, _)| *a == m).and_then(|(_, r)| r.iter().find(|x| x.0 == b)).map(|x| x.1)
}

/// The separation term `m` of `fit` needs from a rival to be named alone
/// ([`super::separate::separation_needed`] of its naming threshold,
/// [`super::fit::naming_threshold`] at the selection's per-test level).
fn threshold_of(fit: &AxisFit, m: Mech) -> f64 {
    let alpha = super::fit::ALPHA / (Mech::ALL.len() * 3) as f64;
    let df = fit.terms.iter().find(|t| t.mech == m).map_or(1, |t| t.coef.len() + usize::from(t.theta.is_some()));
    super::separate::separation_needed(super::fit::naming_threshold(alpha, df), df)
}

/// Whether `m` is a play whose width `theta` is below [`PLAY_MIN_STEPS`] steps of REAL's
/// `temp_C` ([`Prepared::temp_resolution_c`]). A stepped reading shows a reversal only once the
/// temperature has come back by somewhere between zero and one step, so where a play engages is
/// known to within a step: a width under two steps is known to no better than ±50 %, and below
/// one step such a play is ±1 wherever the temperature moves, a sign of the rate.
fn unresolved_play(p: &Prepared, m: Mech, theta: Option<f64>) -> bool {
    matches!(m, Mech::ThermalHysteresis | Mech::BiasHysteresis)
        && matches!((theta, p.temp_resolution_c), (Some(w), Some(res)) if w < PLAY_MIN_STEPS * res)
}

/// A play's width is reported only from this many steps of REAL's temperature reading up
/// ([`Prepared::temp_resolution_c`]): below, it is undetermined and not flown.
pub const PLAY_MIN_STEPS: f64 = 2.0;

/// An accelerometer whose held-out RMS after the model stays above this multiple of its noise
/// floor is one the model does not fit; there, two or more thermal-history findings
/// ([`Mech::thermal_history`]: named terms, or groups with such a member, a negligible one
/// among them where one is shown) are reported as one group. Each was selected beside the
/// others on a thermal path the model does not have exactly (the die between case and
/// thermistor, its self-heating), so their split between forms is not what the recording
/// shows. On the user-profile draws (docs/diagnosis-blind.md),
/// a thermal-history finding beside another on its accelerometer is false five to ten times as
/// often as a lone one (effects 16 of 124 against 5 of 395, groups 20 of 118 against 16 of 541).
pub const THERMAL_JOIN_RATIO: f64 = 1.25;

/// A group's members cancel where the largest member's contribution is this many times what
/// they contribute together (the report's `cancelling`).
pub const CANCEL_RATIO: f64 = 10.0;

/// The RMS [g] about its mean of the largest of a group's contributions `parts` (one per
/// modelled member) and of their sum, where the first is at least [`CANCEL_RATIO`] times the
/// second: members collinear on the recording, fitted with large opposite values (a warm-up of
/// −15.8 mg beside a self-heating rise of 269 °C at nearly one τ, on the 3-hour proposal's test
/// run alone with the noise specification given: 6.5 mg RMS cancelling to 0.023 mg).
fn cancelling(parts: &[&[f64]]) -> Option<(f64, f64)> {
    let n = parts.iter().map(|c| c.len()).min()?;
    if parts.len() < 2 || n == 0 {
        return None;
    }
    // About the mean: a constant is the offset of the noise model's level, not a member's.
    let sd = |v: &[f64]| {
        let mean = v.iter().sum::<f64>() / n as f64;
        (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64).sqrt()
    };
    let largest = parts.iter().map(|c| sd(&c[..n])).fold(0.0, f64::max);
    let sum: Vec<f64> = (0..n).map(|k| parts.iter().map(|c| c[k]).sum()).collect();
    let together = sd(&sum);
    (largest > CANCEL_RATIO * together).then_some((largest, together))
}

/// Builds the report.
pub fn build(
    p: &Prepared,
    axes: &[AxisFit],
    sens: &[Sensitivity],
    floor: ([f64; 3], Vec<AllanPoint>),
    located: Vec<Stratum>,
    unexplained_located: Vec<Stratum>,
    input: &Inputs,
) -> Report {
    let (sim, real) = (input.sim, input.real);
    // A tempco and the static term it reduces to at the reference temperature are one finding:
    // the temperature SIM was calibrated at is not known, and a tempco about another
    // temperature is exactly the two together. Per axis, the members folded into a tempco: its
    // static term, or a member the data cannot tell from that static term.
    let folded: Vec<Vec<(Mech, Mech)>> = axes
        .iter()
        .map(|fit| {
            let mut out = Vec::new();
            for t in [Mech::ScaleTemp, Mech::CrossCouplingTemp] {
                let Some(part) = folds(t) else { continue };
                let plain = |m: Mech| fit.ambiguous.iter().all(|(a, _)| *a != m);
                if !fit.terms.iter().any(|u| u.mech == t) || !plain(t) {
                    continue;
                }
                for u in fit.terms.iter().filter(|u| u.mech != t) {
                    let alike = fit.ambiguous.iter().any(|(a, alts)| *a == u.mech && alts.iter().any(|x| x.0 == part));
                    if u.mech == part || alike {
                        out.push((u.mech, t));
                    }
                }
            }
            out
        })
        .collect();
    let is_folded = |axis: usize, m: Mech| folded[axis].iter().any(|f| f.0 == m);
    // Materiality: the held-out cut of each selected term against the axis's noise floor.
    let cut_of = |axis: usize, m: Mech| {
        let fit = &axes[axis];
        fit.terms.iter().position(|t| t.mech == m).and_then(|k| fit.heldout_gain.get(k).copied())
    };
    let immaterial = |axis: usize, m: Mech| cut_of(axis, m).is_some_and(|c| !material(c, floor.0[axis]));
    let mut negligible: Vec<Negligible> = Vec::new();
    let mut add_negligible = |axis: usize, id: String, m: Mech| {
        if let Some((cut, se)) = cut_of(axis, m) {
            negligible.push(Negligible {
                id,
                axis: AXES[axis].into(),
                heldout_cut_mg: cut * 1e3,
                heldout_cut_se_mg: se * 1e3,
                noise_floor_mg: floor.0[axis] * 1e3,
            });
        }
    };
    // Ambiguous groups per axis: each member and its alternatives; groups on one axis that
    // share a mechanism are one group (two members each "a drift, or …" are not two findings).
    let mut amb_groups: BTreeMap<Vec<String>, AmbGroup> = BTreeMap::new();
    let mut ambiguous_member: Vec<Vec<Mech>> = vec![Vec::new(); 3];
    let mut joined_notes: Vec<String> = Vec::new();
    let shown = |axis: usize, ms: &[Mech]| !ms.iter().all(|m| immaterial(axis, *m));
    let mut locals: Vec<Vec<Local>> = Vec::with_capacity(axes.len());
    for fit in axes {
        let mut local: Vec<Local> = Vec::new();
        for (m, alts) in &fit.ambiguous {
            if is_folded(fit.axis, *m) {
                continue;
            }
            let ids: Vec<Mech> = std::iter::once(*m).chain(alts.iter().map(|a| a.0)).collect();
            let dev = alts.iter().filter(|a| a.1.is_finite()).map(|a| (a.0.id().to_string(), a.1)).collect();
            let sep =
                alts.iter().filter_map(|a| separability_of(fit, *m, a.0).map(|d| (a.0.id().to_string(), d))).collect();
            local.push((vec![*m], ids, dev, sep, threshold_of(fit, *m)));
        }
        // Both turn-on terms found on one accelerometer: a power-on transient with two time
        // constants is explained as well by a warm-up plus self-heating as by either with a
        // second exponential, so the pair is reported as one group the data cannot split (the
        // separating test: power-ons in other positions or at other temperatures).
        let has = |m: Mech| fit.terms.iter().any(|t| t.mech == m);
        if has(Mech::SelfHeating) && has(Mech::Warmup) {
            let pair = vec![Mech::SelfHeating, Mech::Warmup];
            local.push((pair.clone(), pair, BTreeMap::new(), BTreeMap::new(), f64::NAN));
        }
        // Merge what shares a mechanism, until nothing does.
        let mut merged = true;
        while merged {
            merged = false;
            'outer: for a in 0..local.len() {
                for b in a + 1..local.len() {
                    if local[a].1.iter().any(|m| local[b].1.contains(m)) {
                        let g = local.remove(b);
                        absorb(&mut local[a], g);
                        merged = true;
                        break 'outer;
                    }
                }
            }
        }
        // On an accelerometer the model does not fit, the thermal-history findings are one.
        let shown = |ms: &[Mech]| shown(fit.axis, ms);
        let thermal_group = |l: &Local| shown(&l.0) && l.1.iter().any(|m| m.thermal_history());
        if fit.heldout_rms.1 > THERMAL_JOIN_RATIO * floor.0[fit.axis] {
            // A negligible one counts as well: the finding shown was selected beside it, and
            // their split is no more what the recording shows than between two shown ones.
            let touching: Vec<usize> = (0..local.len())
                .filter(|&k| {
                    let l = &local[k];
                    thermal_group(l) || (!shown(&l.0) && l.0.iter().any(|m| m.thermal_history()))
                })
                .collect();
            let named: Vec<Mech> = fit
                .terms
                .iter()
                .map(|t| t.mech)
                .filter(|m| m.thermal_history() && !is_folded(fit.axis, *m))
                .filter(|m| local.iter().all(|l| !l.0.contains(m)))
                .collect();
            let any_shown = touching.iter().any(|&k| shown(&local[k].0)) || named.iter().any(|m| shown(&[*m]));
            if any_shown && touching.len() + named.len() >= 2 {
                // A negligible group joins with what was modelled of it, not its alternatives:
                // the shown finding was selected beside that term.
                for &k in &touching {
                    if !shown(&local[k].0) {
                        local[k].1 = local[k].0.clone();
                    }
                }
                let singles = named
                    .into_iter()
                    .map(|m| (vec![m], vec![m], BTreeMap::new(), BTreeMap::new(), threshold_of(fit, m)));
                let joined = merge_out(&mut local, &touching, singles);
                let names: Vec<&str> = joined.0.iter().map(|m| m.id()).collect();
                joined_notes.push(format!(
                    "accelerometer {}: {} modelled together on an accelerometer left at {:.2}× its noise floor: one group, since each stands in for the others on a thermal path the model does not have exactly",
                    AXES[fit.axis],
                    names.join(" + "),
                    fit.heldout_rms.1 / floor.0[fit.axis]
                ));
                local.push(joined);
            }
        }
        // Two groups on one accelerometer, each with a thermal-history member, are one: each
        // term was fitted beside the other, and what one cannot pin the other takes.
        let thermal: Vec<usize> = (0..local.len()).filter(|&k| thermal_group(&local[k])).collect();
        if thermal.len() >= 2 {
            let joined = merge_out(&mut local, &thermal, []);
            local.push(joined);
        }
        locals.push(local);
    }
    // The thermal path is the unit's: a lag, play, self-heating or warm-up that one
    // accelerometer shows (named, or in a group) is also a member of every thermal-history
    // group of the others, which their own data could not pin.
    let on_path: Vec<Vec<Mech>> = axes
        .iter()
        .zip(&locals)
        .map(|(fit, local)| {
            let mut ms: Vec<Mech> = fit
                .terms
                .iter()
                .map(|t| t.mech)
                .filter(|m| m.thermal_path() && shown(fit.axis, &[*m]) && !is_folded(fit.axis, *m))
                .collect();
            for l in local.iter().filter(|l| shown(fit.axis, &l.0)) {
                ms.extend(l.1.iter().copied().filter(|m| m.thermal_path()));
            }
            ms
        })
        .collect();
    for (a, fit) in axes.iter().enumerate() {
        for l in locals[a].iter_mut() {
            if !shown(fit.axis, &l.0) || !l.1.iter().any(|m| m.thermal_history()) {
                continue;
            }
            let mut added: Vec<(Mech, usize)> = Vec::new();
            for (b, other) in axes.iter().enumerate().filter(|(b, _)| *b != a) {
                for &m in &on_path[b] {
                    if !l.1.contains(&m) && fit.passes_alone.contains(&m) && !added.iter().any(|x| x.0 == m) {
                        added.push((m, other.axis));
                    }
                }
            }
            if added.is_empty() {
                continue;
            }
            l.1.extend(added.iter().map(|x| x.0));
            l.1.sort_by_key(|m| Mech::ALL.iter().position(|a| a == m));
            let from: Vec<String> = added.iter().map(|(m, b)| format!("{} (on {})", m.id(), AXES[*b])).collect();
            joined_notes.push(format!(
                "accelerometer {}: the thermal-history group modelled as {} also holds {}: the thermal path is the unit's, each of these passes this accelerometer's test on its own, and its data did not pin which thermal-history form acts on it",
                AXES[fit.axis],
                l.0.iter().map(|m| m.id()).collect::<Vec<_>>().join(" + "),
                from.join(", ")
            ));
        }
    }
    // A scale-factor or cross-coupling tempco beside the unit's thermal path: where this
    // accelerometer names a lag, play or self-heating (the forms through SIM's sensitivity), or
    // its groups hold a lag, play, self-heating or warm-up, or another accelerometer shows one
    // that passes this accelerometer's test on its own, a tempco named here may be that path's
    // part in f_i, f_j acting through a sensitivity fitted on SIM's thermistor. It joins this
    // accelerometer's thermal-history group, or forms one with those mechanisms (a named one
    // stays named beside it), unless it cuts more of the held-out RMS than the thermal-path
    // terms modelled beside it on an accelerometer the model fits (within
    // `THERMAL_JOIN_RATIO` of its floor): then it is a finding of its own, not the remainder
    // of their shape. Where the model does not fit, a larger cut is no sign of that: the
    // path is not modelled exactly, and the tempco takes what the path's terms leave.
    for (a, fit) in axes.iter().enumerate() {
        let named_here = |m: Mech| fit.terms.iter().any(|t| t.mech == m);
        let mut path: Vec<(Mech, Option<usize>)> = Vec::new();
        let mut offer = |m: Mech, from: Option<usize>| {
            if !path.iter().any(|x| x.0 == m) {
                path.push((m, from));
            }
        };
        fit.terms
            .iter()
            .map(|t| t.mech)
            .filter(|m| m.positive_through_sim() && shown(fit.axis, &[*m]) && !is_folded(fit.axis, *m))
            .for_each(|m| offer(m, None));
        for l in locals[a].iter().filter(|l| shown(fit.axis, &l.0)) {
            l.1.iter().filter(|m| m.thermal_path()).for_each(|m| offer(*m, None));
        }
        for (b, other) in axes.iter().enumerate().filter(|(b, _)| *b != a) {
            for &m in on_path[b].iter().filter(|m| fit.passes_alone.contains(m) && !named_here(**m)) {
                offer(m, Some(other.axis));
            }
        }
        if path.is_empty() {
            continue;
        }
        let in_group = |local: &[Local], m: Mech| local.iter().any(|l| l.0.contains(&m) || l.1.contains(&m));
        let tempcos: Vec<Mech> = fit
            .terms
            .iter()
            .map(|t| t.mech)
            .filter(|m| matches!(m, Mech::ScaleTemp | Mech::CrossCouplingTemp))
            .filter(|m| shown(fit.axis, &[*m]) && !in_group(&locals[a], *m))
            .collect();
        let cut = |m: Mech| cut_of(fit.axis, m).map_or(0.0, |c| c.0);
        let path_cut: f64 =
            fit.terms.iter().filter(|t| t.mech.thermal_path() && shown(fit.axis, &[t.mech])).map(|t| cut(t.mech)).sum();
        let tempco_cut: f64 = tempcos.iter().map(|m| cut(*m)).sum();
        let fits = fit.heldout_rms.1 <= THERMAL_JOIN_RATIO * floor.0[fit.axis];
        if tempcos.is_empty() || (path_cut > 0.0 && tempco_cut > path_cut && fits) {
            continue;
        }
        let mut members = tempcos.clone();
        members.extend(folded[a].iter().filter(|f| tempcos.contains(&f.1)).map(|f| f.0));
        let ids: Vec<Mech> = members.iter().copied().chain(path.iter().map(|x| x.0)).collect();
        let thr = members.iter().map(|m| threshold_of(fit, *m)).fold(f64::NAN, f64::max);
        let g: Local = (members, ids, BTreeMap::new(), BTreeMap::new(), thr);
        let local = &mut locals[a];
        let thermal: Vec<usize> = (0..local.len())
            .filter(|&k| shown(fit.axis, &local[k].0) && local[k].1.iter().any(|m| m.thermal_history()))
            .collect();
        let mut joined = merge_out(local, &thermal, [g]);
        joined.1.sort_by_key(|m| Mech::ALL.iter().position(|x| x == m));
        let from: Vec<String> = path
            .iter()
            .map(|(m, b)| match b {
                Some(b) => format!("{} (on {})", m.id(), AXES[*b]),
                None => m.id().to_string(),
            })
            .collect();
        joined_notes.push(format!(
            "accelerometer {}: {} in one group with {}: a tempco beside the unit's thermal path may be that path's part in f_i, f_j through a sensitivity fitted on SIM's thermistor; the recording does not tell the two apart",
            AXES[fit.axis],
            tempcos.iter().map(|m| m.id()).collect::<Vec<_>>().join(" + "),
            from.join(", ")
        ));
        local.push(joined);
    }
    for (fit, local) in axes.iter().zip(locals) {
        let ax = AXES[fit.axis].to_string();
        for (members, mechs, dev, sep, thr) in local {
            let mut ids: Vec<String> = mechs.iter().map(|m| m.id().to_string()).collect();
            ids.sort();
            ids.dedup();
            ambiguous_member[fit.axis].extend(members.iter().copied());
            if members.iter().all(|m| immaterial(fit.axis, *m)) {
                let names: Vec<&str> = members.iter().map(|m| m.id()).collect();
                add_negligible(fit.axis, names.join(" + "), members[0]);
                continue;
            }
            let modelled: Vec<&str> = members.iter().map(|m| m.id()).collect();
            let parts: Vec<&[f64]> =
                fit.terms.iter().filter(|t| members.contains(&t.mech)).map(|t| t.contribution.as_slice()).collect();
            if let Some((largest, together)) = cancelling(&parts) {
                joined_notes.push(format!(
                    "accelerometer {ax}: the group modelled as {} is collinear on this recording: its members' contributions (up to {:.4} mg RMS) cancel to {:.4} mg; read the group's figures, not its members' values",
                    modelled.join(" + "),
                    largest * 1e3,
                    together * 1e3
                ));
            }
            let e = amb_groups.entry(ids).or_insert_with(|| {
                (Vec::new(), modelled.join(" + "), BTreeMap::new(), BTreeMap::new(), BTreeMap::new())
            });
            e.0.push(ax.clone());
            e.2.insert(ax.clone(), dev);
            e.3.insert(ax.clone(), sep);
            if thr.is_finite() {
                e.4.insert(ax.clone(), thr);
            }
        }
    }
    let ambiguous: Vec<Ambiguous> = amb_groups
        .into_iter()
        .map(|(ids, (axes, modelled_as, dev, sep, thr))| {
            let ms: Vec<Mech> = ids.iter().filter_map(|i| Mech::from_id(i)).collect();
            let separating_test = if ms.len() == 2 {
                separating_test(ms[0], ms[1])
            } else {
                // Each test once: several neighbours are separated by the same one.
                let mut tests: Vec<String> = Vec::new();
                for t in ms.windows(2).map(|w| separating_test(w[0], w[1])) {
                    if !tests.contains(&t) {
                        tests.push(t);
                    }
                }
                tests.join("; ")
            };
            Ambiguous {
                ids,
                axes,
                separating_test,
                modelled_as,
                deviance_difference: dev,
                separability: sep,
                separation_needed: thr,
            }
        })
        .collect();
    let mut effects: Vec<Effect> = Vec::new();
    let mut terms = Vec::new();
    for m in Mech::ALL {
        let mut e = Effect {
            id: m.id().into(),
            axes: Vec::new(),
            params: BTreeMap::new(),
            ci: BTreeMap::new(),
            explanation: m.explanation().into(),
            significance: BTreeMap::new(),
            heldout_cut_mg: BTreeMap::new(),
            undetermined: BTreeMap::new(),
            separability: BTreeMap::new(),
        };
        for fit in axes {
            for t in fit.terms.iter().filter(|t| t.mech == m) {
                let (mut params, mut ci) = term_params(t, &sens[fit.axis], fit.axis);
                if m == Mech::ThermalLag && fit.lag_rise_c > 0.0 {
                    // The die's rise at power-on the lag carries ([`super::mech::missed_die_rise`]).
                    params.insert("missed_rise_C".into(), fit.lag_rise_c);
                }
                let amb = ambiguous_member[fit.axis].contains(&m);
                let small = immaterial(fit.axis, m);
                let undetermined: Vec<String> = match (m.theta(), t.theta_ci) {
                    (Some(name), Some((lo, hi))) if !(hi < UNDETERMINED_RATIO * lo) => vec![name.to_string()],
                    (Some(name), _) if unresolved_play(p, m, t.theta) => vec![name.to_string()],
                    _ => Vec::new(),
                };
                terms.push(ModelTerm {
                    id: m.id().into(),
                    axis: AXES[fit.axis].into(),
                    params: params.clone(),
                    ambiguous: amb,
                    undetermined: undetermined.clone(),
                    negligible: small,
                });
                if amb {
                    continue;
                }
                if small {
                    add_negligible(fit.axis, m.id().into(), m);
                    continue;
                }
                if is_folded(fit.axis, m) {
                    continue;
                }
                for (x, _) in folded[fit.axis].iter().filter(|f| f.1 == m) {
                    if let Some(u) = fit.terms.iter().find(|u| u.mech == *x) {
                        let (pp, pc) = term_params(u, &sens[fit.axis], fit.axis);
                        params.extend(pp.into_iter().map(|(k, v)| (format!("{k} (at T0)"), v)));
                        ci.extend(pc.into_iter().map(|(k, v)| (format!("{k} (at T0)"), v)));
                    }
                }
                let ax = AXES[fit.axis].to_string();
                e.axes.push(ax.clone());
                e.params.insert(ax.clone(), params);
                e.ci.insert(ax.clone(), ci);
                e.significance.insert(ax.clone(), [t.lr_drop, t.p_drop]);
                if let Some(k) = fit.terms.iter().position(|u| std::ptr::eq(u, t))
                    && let Some(g) = fit.heldout_gain.get(k)
                {
                    e.heldout_cut_mg.insert(ax.clone(), [g.0 * 1e3, g.1 * 1e3]);
                }
                if let Some((_, rivals)) = fit.separability.iter().find(|(a, _)| *a == m) {
                    e.separability
                        .insert(ax.clone(), rivals.iter().take(3).map(|(b, d)| (b.id().to_string(), *d)).collect());
                }
                if !undetermined.is_empty() {
                    e.undetermined.insert(ax, undetermined);
                }
            }
        }
        if !e.axes.is_empty() {
            effects.push(e);
        }
    }
    let search = per_axis(|i| {
        axes[i]
            .trace
            .iter()
            .map(|s| SearchStep {
                id: s.mech.id().into(),
                theta: s.theta,
                lr: s.lr,
                df: s.df,
                p: s.p,
                dbic: s.dbic,
                dcv: s.dcv,
                accepted: s.accepted,
            })
            .collect()
    });
    let mut notes = p.notes.clone();
    notes.extend(joined_notes);
    for (fit, t) in axes.iter().flat_map(|f| f.terms.iter().map(move |t| (f, t))) {
        if unresolved_play(p, t.mech, t.theta) {
            notes.push(format!(
                "accelerometer {}: {}'s width {:.4} °C is under {PLAY_MIN_STEPS} steps of REAL's temp_C (a step is {:.4} °C): reported as undetermined, a heating/cooling difference rather than a measured play",
                AXES[fit.axis],
                t.mech.id(),
                t.theta.unwrap_or(0.0),
                p.temp_resolution_c.unwrap_or(0.0)
            ));
        }
    }
    for (i, s) in sens.iter().enumerate() {
        if !s.from_sim {
            notes.push(format!(
                "accelerometer {}: SIM shows no temperature sensitivity; thermal terms in the free form T_e − T [g/°C]",
                AXES[i]
            ));
        }
    }
    let runs = p.static_runs();
    let sensor_rw: PerAxis<f64> = (0..3)
        .filter_map(|i| {
            let e: Vec<f64> = p.r[i].iter().zip(&axes[i].prediction).map(|(a, b)| a - b).collect();
            let segs: Vec<&[f64]> = runs.iter().map(|&(a, b)| &e[a..b]).collect();
            short_tau_q(&segs, p.dt).map(|q| (AXES[i].to_string(), (q.0 * 3600.0).sqrt() * 1e3))
        })
        .collect();
    let named = |i: usize| !axes[i].terms.is_empty();
    let scales: Vec<Vec<ScalePoint>> = axes.iter().map(|f| axis_scales(p, f)).collect();
    let left = |i: usize| structure(&scales[i], true);
    // Structure left on an accelerometer the model does not fit (above `THERMAL_JOIN_RATIO` of
    // its floor) that the random walk estimated from this very record could make: the sensor's
    // own noise figures are the sharper test of it.
    if !input.opt.noise_given() {
        let span_s =
            p.sessions().iter().filter(|r| !r.is_empty()).map(|r| p.t[r.end - 1] - p.t[r.start]).fold(0.0, f64::max);
        for (i, fit) in axes.iter().enumerate() {
            let wander = (fit.q * span_s).sqrt();
            if let Some((size, tau)) = left(i)
                && size <= RANDOM_WALK_HIDES * wander
                && fit.heldout_rms.1 > THERMAL_JOIN_RATIO * floor.0[i]
            {
                notes.push(format!(
                    "accelerometer {}: {:.4} mg of structure is left at {:.0} s, within what the random walk estimated from this record ({:.4} mg/√h) wanders over it (±{:.4} mg in {:.0} min): what is left cannot be told from that random walk here, and one record cannot tell that random walk from a bias instability of the same short-time slope, which stays within ±σ: the sensor's own noise (`--noise` with what `bins-cal allan --noise-toml` fits to a quiet recording of the unit, or its datasheet's `--random-walk`, `--bias-instability` with `--bias-tau`) is the sharper test",
                    AXES[i],
                    size * 1e3,
                    tau,
                    (fit.q * 3600.0).sqrt() * 1e3,
                    wander * 1e3,
                    span_s / 60.0
                ));
            }
        }
    }
    for (i, names) in input.nuisance.iter().enumerate() {
        if !names.is_empty() {
            notes.push(format!(
                "accelerometer {}: REAL − SIM is orthogonal to SIM's own temperature terms ({}): SIM is a least-squares calibration of this recording; those terms are re-fitted with every model and never named",
                AXES[i],
                names.join(", ")
            ));
        }
    }
    Report {
        sim: sim.display().to_string(),
        real: real.display().to_string(),
        rows: p.n_total,
        rows_used: if p.weight.is_empty() { p.t.len() } else { p.weight.iter().sum::<f64>() as usize },
        scale_v_per_g: per_axis(|i| p.k_diag[i]),
        notes,
        noise_floor_mg: per_axis(|i| floor.0[i] * 1e3),
        allan: allan_curves(p, &floor.0, floor.1, axes),
        random_walk_mg_per_sqrt_h: per_axis(|i| (axes[i].q * 3600.0).sqrt() * 1e3),
        random_walk_source: match (&input.opt.sensor_noise, input.opt.random_walk_mg_per_sqrt_h) {
            (Some(n), _) => n.file.display().to_string(),
            (None, Some(_)) => "given".into(),
            (None, None) => "estimated".into(),
        },
        bias_instability_mg_tau_s: (0..3)
            .filter_map(|i| axes[i].gm.map(|g| (AXES[i].to_string(), (g.var_g2.sqrt() * 1e3, g.tau_s))))
            .collect(),
        sim_die_rise: p.die_rise,
        sensor_random_walk_mg_per_sqrt_h: sensor_rw,
        drift_rms_mg: per_axis(|i| axes[i].drift_rms * 1e3),
        unexplained_rms_mg: per_axis(|i| left(i).map_or(0.0, |s| s.0 * 1e3)),
        unexplained_scale_s: (0..3).filter_map(|i| left(i).map(|s| (AXES[i].to_string(), s.1))).collect(),
        scales: per_axis(|i| {
            scales[i]
                .iter()
                .map(|s| ScaleRow {
                    tau_s: s.tau_s,
                    before_mg: s.before * 1e3,
                    after_mg: s.after * 1e3,
                    noise_mg: s.noise * 1e3,
                    limit_mg: s.limit * 1e3,
                })
                .collect()
        }),
        verdict: per_axis(|i| {
            verdict(structure(&scales[i], false).map(|s| s.0), left(i).map(|s| s.0), named(i)).to_string()
        }),
        sim_terms_refitted: per_axis(|i| input.nuisance[i].clone()),
        located,
        unexplained_located,
        effects,
        ambiguous,
        negligible,
        rms_before_mg: per_axis(|i| axes[i].rms.0 * 1e3),
        rms_after_mg: per_axis(|i| axes[i].rms.1 * 1e3),
        heldout_rms_before_mg: per_axis(|i| axes[i].heldout_rms.0 * 1e3),
        heldout_rms_after_mg: per_axis(|i| axes[i].heldout_rms.1 * 1e3),
        steps: Vec::new(),
        search,
        model: AugmentedModel {
            t0_c: super::mech::T0_C,
            sensitivity: (0..3)
                .filter(|&i| sens[i].from_sim)
                .map(|i| (AXES[i].to_string(), sens[i].c.to_vec()))
                .collect(),
            thermal_dynamics: dynamics_table(&terms),
            term: terms,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn members_that_cancel_are_told_from_members_that_add() {
        let n = 1000;
        let decay: Vec<f64> = (0..n).map(|k| (-(k as f64) / 200.0).exp()).collect();
        let ramp: Vec<f64> = (0..n).map(|k| k as f64 / n as f64).collect();
        // A large turn-on term against its near copy plus a constant: the sum is 1 % of either.
        let big: Vec<f64> = decay.iter().map(|d| -15e-3 * d).collect();
        let copy: Vec<f64> = decay.iter().map(|d| 15.6e-3 + 14.85e-3 * d).collect();
        let (largest, together) = cancelling(&[&big, &copy]).expect("cancelling members");
        assert!((largest / together - 100.0).abs() < 1.0, "{largest} / {together}");
        // Two members of different shapes add: no note; nor for a single member.
        assert_eq!(cancelling(&[&big, &ramp]), None);
        assert_eq!(cancelling(&[&big]), None);
    }
}
