//! Blind harness of `bins-cal diagnose` (docs/diagnosis-blind.md): cases drawn at random by an
//! independent generator ([`generator`], `gen.rs`), diagnosed, classified, summarised per mechanism, written as
//! CSV and drawn as a detectability curve. Combined cases (2–3 mechanisms at once) are classified
//! per member ([`classify_members`]), summarised per member, per combination of mechanism kinds
//! and per pair ([`summarize_combined`]), and drawn against the record-length-aware size
//! ([`plot_snr`]).

#[path = "gen.rs"]
pub mod generator;

use bins_cal::diagnose::report::Report;
use bins_cal::diagnose::{Options, diagnose_with};
use generator::{Case, MECH_IDS, Mech};
use plotters::prelude::*;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// Effect size (in noise units) from which a mechanism must be named.
pub const STRONG_SIGMA: f64 = 5.0;

/// How a case came out.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Outcome {
    /// Null, nothing named.
    Clean,
    /// The true mechanism named on an axis where it acts, nothing else.
    Exact,
    /// The true mechanism only inside an ambiguous group (on an axis where it acts), nothing
    /// else named.
    Ambiguous,
    /// The true mechanism named (or in a group), and something else too.
    HitPlusFalse,
    /// Nothing named.
    Missed,
    /// Something else named, the true mechanism not.
    Misnamed,
    /// Null with a name.
    FalseOnNull,
    /// Combined case: some members named, not all, nothing false.
    Partial,
}

impl Outcome {
    /// Text for tables.
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Clean => "clean",
            Outcome::Exact => "exact",
            Outcome::Ambiguous => "ambiguous",
            Outcome::HitPlusFalse => "hit+false",
            Outcome::Missed => "missed",
            Outcome::Misnamed => "misnamed",
            Outcome::FalseOnNull => "false_on_null",
            Outcome::Partial => "partial",
        }
    }

    /// Named exactly in the sense of the done-when (exact, or ambiguous with the truth in the
    /// set), or a clean null.
    pub fn named(self) -> bool {
        matches!(self, Outcome::Exact | Outcome::Ambiguous)
    }

    /// At least one name that is not the truth.
    pub fn false_discovery(self) -> bool {
        matches!(self, Outcome::HitPlusFalse | Outcome::Misnamed | Outcome::FalseOnNull)
    }
}

/// Result of one case.
#[derive(Clone, Debug)]
pub struct CaseResult {
    /// The case.
    pub case: Case,
    /// Achieved size per accelerometer [σ].
    pub axis_size_sigma: [f64; 3],
    /// Outcome.
    pub outcome: Outcome,
    /// Named effects, `id:axes`.
    pub effects: Vec<String>,
    /// Ambiguous groups, `id|id:axes`.
    pub ambiguous: Vec<String>,
    /// Ids named that are not the truth.
    pub false_ids: Vec<String>,
    /// Held-out RMS before → after per accelerometer \[mg\].
    pub heldout_mg: [(f64, f64); 3],
    /// Noise floor per accelerometer \[mg\].
    pub floor_mg: [f64; 3],
    /// Diagnosis time \[s\].
    pub secs: f64,
    /// The diagnosis failed (error text).
    pub error: Option<String>,
    /// Every concealed mechanism, in the order of [`Case::members`], and whether it was named.
    pub members: Vec<MemberResult>,
}

/// One concealed mechanism of a case and how it came out.
#[derive(Clone, Debug)]
pub struct MemberResult {
    /// Mechanism id.
    pub id: &'static str,
    /// Drawn size (RMS about the mean on its strongest accelerometer / σ).
    pub size_sigma: f64,
    /// Record-length-aware size `size_sigma·√rows`.
    pub snr: f64,
    /// Achieved size per accelerometer [σ].
    pub axis_size_sigma: [f64; 3],
    /// Named in `effects`, or inside an ambiguous group, on an accelerometer where it acts.
    pub named: bool,
    /// Named only inside an ambiguous group.
    pub ambiguous: bool,
}

const AX: [&str; 3] = ["x", "y", "z"];

/// Classifies a report against the case's truth.
pub fn classify(case: &Case, axis_size: &[f64; 3], r: &Report) -> (Outcome, Vec<String>) {
    let truth = case.mech.id();
    let applied: Vec<&str> = (0..3).filter(|&i| axis_size[i] > 0.0).map(|i| AX[i]).collect();
    let on_applied = |axes: &[String]| axes.iter().any(|a| applied.contains(&a.as_str()));
    let mut hit_exact = false;
    let mut hit_amb = false;
    let mut false_ids = Vec::new();
    for e in &r.effects {
        if e.id == truth {
            hit_exact |= on_applied(&e.axes);
        } else {
            false_ids.push(e.id.clone());
        }
    }
    for g in &r.ambiguous {
        if g.ids.iter().any(|i| i == truth) {
            hit_amb |= on_applied(&g.axes);
        } else {
            false_ids.extend(g.ids.iter().cloned());
        }
    }
    false_ids.sort();
    false_ids.dedup();
    let outcome = if truth == "none" {
        if false_ids.is_empty() { Outcome::Clean } else { Outcome::FalseOnNull }
    } else {
        match (hit_exact || hit_amb, false_ids.is_empty()) {
            (true, true) if hit_exact => Outcome::Exact,
            (true, true) => Outcome::Ambiguous,
            (true, false) => Outcome::HitPlusFalse,
            (false, true) => Outcome::Missed,
            (false, false) => Outcome::Misnamed,
        }
    };
    (outcome, false_ids)
}

/// Classifies a report against every member of a (combined) case: per member whether it was
/// named (in `effects` or in an ambiguous group, on an accelerometer where it acts) and whether
/// only through a group; and the ids named that are no member (an ambiguous group holding a
/// member is not false, nor is a member named on an accelerometer where it does not act).
pub fn classify_members(case: &Case, member_axis: &[[f64; 3]], r: &Report) -> (Vec<(bool, bool)>, Vec<String>) {
    let members = case.members();
    let truth: Vec<&str> = members.iter().map(|m| m.mech.id()).collect();
    let mut named = Vec::new();
    for (m, axis) in members.iter().zip(member_axis) {
        let applied: Vec<&str> = (0..3).filter(|&i| axis[i] > 0.0).map(|i| AX[i]).collect();
        let on_applied = |axes: &[String]| axes.iter().any(|a| applied.contains(&a.as_str()));
        let id = m.mech.id();
        let exact = r.effects.iter().any(|e| e.id == id && on_applied(&e.axes));
        let amb = r.ambiguous.iter().any(|g| g.ids.iter().any(|i| i == id) && on_applied(&g.axes));
        named.push((exact || amb, amb && !exact));
    }
    let mut false_ids: Vec<String> = Vec::new();
    for e in &r.effects {
        if !truth.contains(&e.id.as_str()) {
            false_ids.push(e.id.clone());
        }
    }
    for g in &r.ambiguous {
        if !g.ids.iter().any(|i| truth.contains(&i.as_str())) {
            false_ids.extend(g.ids.iter().cloned());
        }
    }
    false_ids.sort();
    false_ids.dedup();
    (named, false_ids)
}

/// Outcome of a combined case from its members' results and its false ids.
fn combined_outcome(named: &[(bool, bool)], false_ids: &[String]) -> Outcome {
    let all = named.iter().all(|n| n.0);
    let some = named.iter().any(|n| n.0);
    match (all, some, false_ids.is_empty()) {
        (true, _, true) if named.iter().all(|n| !n.1) => Outcome::Exact,
        (true, _, true) => Outcome::Ambiguous,
        (false, true, true) => Outcome::Partial,
        (_, true, false) => Outcome::HitPlusFalse,
        (_, false, true) => Outcome::Missed,
        (_, false, false) => Outcome::Misnamed,
    }
}

/// The case as drawn, or sampled `BLIND_FASTER` times faster over the same span (that many
/// times the rows; the dwells, profile and power-ons in seconds unchanged): the blind cases at
/// rates where the diagnosis reduces the rows to blocks.
fn sampled(case: &Case) -> Case {
    let mut c = case.clone();
    if let Some(k) = std::env::var("BLIND_FASTER").ok().and_then(|v| v.parse::<f64>().ok()) {
        c.rate_hz *= k;
        c.rows = (c.rows as f64 * k).round() as usize;
    }
    c
}

/// The diagnosis with the block length of `BLIND_BLOCK_S` (`diagnose --block-s`; unset: the
/// default, the length the data allow).
fn diagnose_env(
    sim: &[bins_cal::recording::Row],
    real: &[bins_cal::recording::Row],
) -> Result<bins_cal::diagnose::Diagnosis, bins_cal::diagnose::DiagnoseError> {
    let block_s = std::env::var("BLIND_BLOCK_S").ok().and_then(|v| v.parse::<f64>().ok());
    diagnose_with(sim, real, Path::new("sim.csv"), Path::new("real.csv"), &Options { block_s, ..Options::default() })
}

/// The diagnosis's report of one case as run ([`CaseResult::case`], already sampled at
/// `BLIND_FASTER`) as JSON (or the error), for looking into a failure.
pub fn report_json(case: &Case) -> String {
    let (sim, real, _) = generator::generate(case);
    match diagnose_env(&sim, &real) {
        Ok(d) => serde_json::to_string_pretty(&d.report).unwrap_or_else(|e| e.to_string()),
        Err(e) => e.to_string(),
    }
}

/// Generates, diagnoses and classifies one case.
pub fn run_case(case: &Case) -> CaseResult {
    let case = &sampled(case);
    let (sim, real, truth) = generator::generate(case);
    let t0 = Instant::now();
    let d = diagnose_env(&sim, &real);
    let secs = t0.elapsed().as_secs_f64();
    let mut res = CaseResult {
        case: case.clone(),
        axis_size_sigma: truth.axis_size_sigma,
        outcome: Outcome::Missed,
        effects: Vec::new(),
        ambiguous: Vec::new(),
        false_ids: Vec::new(),
        heldout_mg: [(0.0, 0.0); 3],
        floor_mg: [0.0; 3],
        secs,
        error: None,
        members: case
            .members()
            .iter()
            .zip(&truth.members)
            .map(|(m, a)| MemberResult {
                id: m.mech.id(),
                size_sigma: m.size_sigma,
                snr: case.snr(m.size_sigma),
                axis_size_sigma: *a,
                named: false,
                ambiguous: false,
            })
            .collect(),
    };
    match d {
        Err(e) => {
            res.error = Some(e.to_string());
            if case.mech.id() == "none" {
                res.outcome = Outcome::Clean;
            }
        }
        Ok(d) => {
            let r = &d.report;
            let (named, f_members) = classify_members(case, &truth.members, r);
            for (m, n) in res.members.iter_mut().zip(&named) {
                (m.named, m.ambiguous) = *n;
            }
            if case.extra.is_empty() {
                let (o, f) = classify(case, &truth.axis_size_sigma, r);
                res.outcome = o;
                res.false_ids = f;
            } else {
                res.outcome = combined_outcome(&named, &f_members);
                res.false_ids = f_members;
            }
            res.effects = r.effects.iter().map(|e| format!("{}:{}", e.id, e.axes.join(""))).collect();
            res.ambiguous = r.ambiguous.iter().map(|g| format!("{}:{}", g.ids.join("|"), g.axes.join(""))).collect();
            for i in 0..3 {
                let g = |m: &BTreeMap<String, f64>| m.get(AX[i]).copied().unwrap_or(f64::NAN);
                res.heldout_mg[i] = (g(&r.heldout_rms_before_mg), g(&r.heldout_rms_after_mg));
                res.floor_mg[i] = g(&r.noise_floor_mg);
            }
        }
    }
    res
}

/// Cases `seed0 .. seed0 + n`, drawn with [`Case::draw`], diagnosed on `threads` threads (in
/// seed order in the result).
pub fn run_cases(n: usize, seed0: u64, threads: usize, progress: bool) -> Vec<CaseResult> {
    let cases: Vec<Case> = (0..n as u64).map(|k| Case::draw(seed0 + k)).collect();
    run_list(&cases, threads, progress)
}

/// Combined cases `seed0 .. seed0 + n`, drawn with [`Case::draw_combined`], diagnosed on
/// `threads` threads (in seed order in the result).
pub fn run_combined(
    n: usize,
    seed0: u64,
    sizes: generator::SizeDraw,
    threads: usize,
    progress: bool,
) -> Vec<CaseResult> {
    let cases: Vec<Case> = (0..n as u64).map(|k| Case::draw_combined(seed0 + k, sizes)).collect();
    run_list(&cases, threads, progress)
}

/// Runs a list of cases on `threads` threads; `progress` prints one line per case to stderr.
pub fn run_list(cases: &[Case], threads: usize, progress: bool) -> Vec<CaseResult> {
    let next = AtomicUsize::new(0);
    let out: Mutex<Vec<Option<CaseResult>>> = Mutex::new(vec![None; cases.len()]);
    std::thread::scope(|s| {
        for _ in 0..threads.max(1) {
            s.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    if k >= cases.len() {
                        break;
                    }
                    let r = run_case(&cases[k]);
                    if progress {
                        eprintln!("{}", line(&r));
                    }
                    if let Ok(mut o) = out.lock() {
                        o[k] = Some(r);
                    }
                }
            });
        }
    });
    out.into_inner().unwrap_or_default().into_iter().flatten().collect()
}

/// One-line description of a result.
pub fn line(r: &CaseResult) -> String {
    let c = &r.case;
    if !c.extra.is_empty() {
        return combined_line(r);
    }
    format!(
        "seed {:>6} {:<20} {:>5.1}σ ({:.1}/{:.1}/{:.1}) {:<7} {:<9} {:<6} rw {:.1} σ {:>5.0} µg {:>5} rows {:.1} Hz | {:<13} eff [{}] amb [{}] {:.2}s{}",
        c.seed,
        c.mech.id(),
        c.size_sigma,
        r.axis_size_sigma[0],
        r.axis_size_sigma[1],
        r.axis_size_sigma[2],
        c.mech.params(),
        c.profile.name(),
        c.positions.name(),
        c.rw_ratio,
        c.sigma_ug,
        c.rows,
        c.rate_hz,
        r.outcome.name(),
        r.effects.join(" "),
        r.ambiguous.join(" "),
        r.secs,
        r.error.as_deref().map(|e| format!(" ERROR {e}")).unwrap_or_default()
    )
}

/// Per-mechanism tallies.
#[derive(Clone, Debug, Default)]
pub struct Tally {
    /// Cases.
    pub n: usize,
    /// Cases ≥ 5 σ.
    pub n_strong: usize,
    /// Named exactly (or ambiguous with the truth), ≥ 5 σ.
    pub named_strong: usize,
    /// Named exactly, all sizes.
    pub named: usize,
    /// Cases with at least one false name.
    pub false_disc: usize,
    /// Outcome counts.
    pub outcomes: BTreeMap<&'static str, usize>,
    /// False ids named, with counts.
    pub false_ids: BTreeMap<String, usize>,
}

/// The scorecard.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    /// Per truth id (`none` for nulls).
    pub per_mech: BTreeMap<String, Tally>,
    /// Effects ≥ 5 σ: (named, total).
    pub strong: (usize, usize),
    /// Cases with a false discovery: (count, total).
    pub false_disc: (usize, usize),
    /// Nulls without random walk: (false, total).
    pub null_white: (usize, usize),
    /// Nulls with random walk: (false, total).
    pub null_rw: (usize, usize),
    /// Median and maximum diagnosis time \[s\].
    pub secs: (f64, f64),
    /// The text.
    pub text: String,
}

fn pct(a: usize, b: usize) -> f64 {
    if b == 0 { f64::NAN } else { 100.0 * a as f64 / b as f64 }
}

/// Summarises results into the scorecard.
pub fn summarize(res: &[CaseResult]) -> Summary {
    let mut s = Summary::default();
    for r in res {
        let id = r.case.mech.id().to_string();
        let t = s.per_mech.entry(id.clone()).or_default();
        t.n += 1;
        let strong = r.case.size_sigma >= STRONG_SIGMA;
        if id != "none" {
            t.n_strong += usize::from(strong);
            t.named_strong += usize::from(strong && r.outcome.named());
            t.named += usize::from(r.outcome.named());
            if strong {
                s.strong.1 += 1;
                s.strong.0 += usize::from(r.outcome.named());
            }
        } else if r.case.rw_ratio > 0.0 {
            s.null_rw.1 += 1;
            s.null_rw.0 += usize::from(r.outcome.false_discovery());
        } else {
            s.null_white.1 += 1;
            s.null_white.0 += usize::from(r.outcome.false_discovery());
        }
        t.false_disc += usize::from(r.outcome.false_discovery());
        *t.outcomes.entry(r.outcome.name()).or_default() += 1;
        for f in &r.false_ids {
            *t.false_ids.entry(f.clone()).or_default() += 1;
        }
        s.false_disc.1 += 1;
        s.false_disc.0 += usize::from(r.outcome.false_discovery());
    }
    let mut times: Vec<f64> = res.iter().map(|r| r.secs).collect();
    times.sort_by(f64::total_cmp);
    if !times.is_empty() {
        s.secs = (times[times.len() / 2], times[times.len() - 1]);
    }
    let mut w = String::new();
    let anchor = res.first().map_or(f64::NAN, |r| r.case.anchor_c);
    let _ = writeln!(w, "blind scorecard ({} cases; concealed tempcos anchored at {anchor} °C)", res.len());
    let _ = writeln!(
        w,
        "{:<20} {:>5} {:>12} {:>12} {:>10}  outcomes; false names",
        "truth", "cases", "named ≥5σ", "named all", "false-disc"
    );
    let mut order: Vec<&str> = vec!["none"];
    order.extend(MECH_IDS);
    for id in order {
        let Some(t) = s.per_mech.get(id) else { continue };
        let oc: Vec<String> = t.outcomes.iter().map(|(k, v)| format!("{k} {v}")).collect();
        let fi: Vec<String> = t.false_ids.iter().map(|(k, v)| format!("{k}×{v}")).collect();
        let strong = if id == "none" {
            "—".to_string()
        } else {
            format!("{}/{} {:>3.0}%", t.named_strong, t.n_strong, pct(t.named_strong, t.n_strong))
        };
        let all =
            if id == "none" { "—".to_string() } else { format!("{}/{} {:>3.0}%", t.named, t.n, pct(t.named, t.n)) };
        let _ = writeln!(
            w,
            "{:<20} {:>5} {:>12} {:>12} {:>4}/{:<2}{:>3.0}%  {}; {}",
            id,
            t.n,
            strong,
            all,
            t.false_disc,
            t.n,
            pct(t.false_disc, t.n),
            oc.join(", "),
            fi.join(" ")
        );
    }
    let _ = writeln!(
        w,
        "effects ≥ {STRONG_SIGMA}× noise named exactly: {}/{} ({:.1} %)",
        s.strong.0,
        s.strong.1,
        pct(s.strong.0, s.strong.1)
    );
    let _ = writeln!(
        w,
        "cases with a false discovery: {}/{} ({:.1} %); nulls without random walk: {}/{}, with random walk: {}/{}",
        s.false_disc.0,
        s.false_disc.1,
        pct(s.false_disc.0, s.false_disc.1),
        s.null_white.0,
        s.null_white.1,
        s.null_rw.0,
        s.null_rw.1
    );
    let _ = writeln!(w, "diagnosis time per case: median {:.2} s, max {:.2} s", s.secs.0, s.secs.1);
    s.text = w;
    s
}

/// Writes the per-case CSV into `dir/blind_cases.csv`.
pub fn write_csv(res: &[CaseResult], dir: &Path) -> std::io::Result<PathBuf> {
    std::fs::create_dir_all(dir)?;
    let mut w = String::from(
        "seed,truth,params,size_sigma,size_x_sigma,size_y_sigma,size_z_sigma,sigma_ug,rw_ratio,profile,positions,power_s,rows,rate_hz,outcome,effects,ambiguous,false_ids,heldout_before_x_mg,heldout_after_x_mg,heldout_before_y_mg,heldout_after_y_mg,heldout_before_z_mg,heldout_after_z_mg,floor_x_mg,floor_y_mg,floor_z_mg,secs,error\n",
    );
    for r in res {
        let c = &r.case;
        let _ = write!(
            w,
            "{},{},{},{:.4},{:.4},{:.4},{:.4},{:.3},{:.3},{},{},{},{},{},{},{},{},{}",
            c.seed,
            c.mech.id(),
            c.mech.params(),
            c.size_sigma,
            r.axis_size_sigma[0],
            r.axis_size_sigma[1],
            r.axis_size_sigma[2],
            c.sigma_ug,
            c.rw_ratio,
            c.profile.name(),
            c.positions.name(),
            c.power_column,
            c.rows,
            c.rate_hz,
            r.outcome.name(),
            r.effects.join(" "),
            r.ambiguous.join(" "),
            r.false_ids.join(" ")
        );
        for i in 0..3 {
            let _ = write!(w, ",{:.5},{:.5}", r.heldout_mg[i].0, r.heldout_mg[i].1);
        }
        let _ = writeln!(
            w,
            ",{:.5},{:.5},{:.5},{:.3},{}",
            r.floor_mg[0],
            r.floor_mg[1],
            r.floor_mg[2],
            r.secs,
            r.error.as_deref().unwrap_or("").replace([',', '\n'], ";")
        );
    }
    let path = dir.join("blind_cases.csv");
    std::fs::write(&path, w)?;
    Ok(path)
}

/// The font (DejaVu Sans; licence in `assets/DejaVuSans.LICENSE`).
static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// Bin edges of the effect size [σ] (log spaced).
pub const BIN_EDGES: [f64; 8] = [0.5, 1.0, 2.0, 3.5, 5.0, 8.0, 12.0, 20.0];

/// Detectability curve: per bin of effect size, the fraction named exactly; `(centre, p, n)`.
pub fn curve(res: &[CaseResult], id: Option<&str>) -> Vec<(f64, f64, usize)> {
    let mut out = Vec::new();
    for w in BIN_EDGES.windows(2) {
        let sel: Vec<&CaseResult> = res
            .iter()
            .filter(|r| r.case.mech.id() != "none" && id.is_none_or(|i| r.case.mech.id() == i))
            .filter(|r| r.case.size_sigma >= w[0] && (r.case.size_sigma < w[1] || w[1] == 20.0))
            .collect();
        if !sel.is_empty() {
            let named = sel.iter().filter(|r| r.outcome.named()).count();
            out.push(((w[0] * w[1]).sqrt(), named as f64 / sel.len() as f64, sel.len()));
        }
    }
    out
}

/// Draws the detectability curve into `dir/blind_detectability.png`.
pub fn plot(res: &[CaseResult], dir: &Path) -> Result<PathBuf, String> {
    use plotters::style::{FontStyle, register_font};
    let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let path = dir.join("blind_detectability.png");
    let tmp = dir.join(format!(".blind_detectability.tmp-{}.png", std::process::id()));
    let result = (|| -> Result<(), String> {
        let root = BitMapBackend::new(&tmp, (1100, 640)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let (f, s) = summarize_counts(res);
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!(
                    "blind harness: probability named vs effect size ({} cases, {f}/{s} false discoveries)",
                    res.len()
                ),
                ("sans-serif", 20),
            )
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(60)
            .build_cartesian_2d((0.5f64..20.0).log_scale(), -0.04f64..1.04)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("effect size: RMS of the concealed contribution / white noise σ")
            .y_desc("probability named exactly (lines offset ±0.024)")
            .light_line_style(RGBColor(238, 238, 238))
            .x_label_formatter(&|x| if *x < 1.0 { format!("{x:.1}") } else { format!("{x:.0}") })
            .label_style(("sans-serif", 14))
            .draw()
            .map_err(|e| e.to_string())?;
        chart
            .draw_series(LineSeries::new([(STRONG_SIGMA, 0.0), (STRONG_SIGMA, 1.0)], BLACK.mix(0.3).stroke_width(1)))
            .map_err(|e| e.to_string())?;
        chart
            .draw_series(LineSeries::new([(0.5, 0.9), (20.0, 0.9)], BLACK.mix(0.3).stroke_width(1)))
            .map_err(|e| e.to_string())?;
        for (k, id) in MECH_IDS.iter().enumerate() {
            // Offset each mechanism's line a little so coinciding lines stay visible.
            let off = (k as f64 - 6.0) * 0.004;
            let pts: Vec<(f64, f64)> = curve(res, Some(id)).iter().map(|p| (p.0, p.1 + off)).collect();
            if pts.is_empty() {
                continue;
            }
            let col = Palette99::pick(k).to_rgba();
            chart
                .draw_series(LineSeries::new(pts.iter().copied(), col.stroke_width(1)))
                .map_err(|e| e.to_string())?
                .label(*id)
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 14, y)], col.stroke_width(2)));
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, col.filled()))).map_err(|e| e.to_string())?;
        }
        let all: Vec<(f64, f64)> = curve(res, None).iter().map(|p| (p.0, p.1)).collect();
        chart
            .draw_series(LineSeries::new(all.iter().copied(), BLACK.stroke_width(3)))
            .map_err(|e| e.to_string())?
            .label("all mechanisms")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 14, y)], BLACK.stroke_width(3)));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 12))
            .draw()
            .map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())
    })();
    match result.and_then(|_| std::fs::rename(&tmp, &path).map_err(|e| e.to_string())) {
        Ok(()) => Ok(path),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(format!("{}: {e}", path.display()))
        }
    }
}

fn summarize_counts(res: &[CaseResult]) -> (usize, usize) {
    (res.iter().filter(|r| r.outcome.false_discovery()).count(), res.len())
}

/// One-line description of a combined case's result: every member with its size (per sample
/// and `z = size·√rows`) and `+` (named) or `-`.
pub fn combined_line(r: &CaseResult) -> String {
    let c = &r.case;
    let members: Vec<String> = r
        .members
        .iter()
        .map(|m| {
            let axes: String = (0..3).filter(|&i| m.axis_size_sigma[i] > 0.0).map(|i| AX[i]).collect();
            format!("{}{}:{} {:.2}σ z {:.0}", if m.named { "+" } else { "-" }, m.id, axes, m.size_sigma, m.snr)
        })
        .collect();
    format!(
        "seed {:>6} [{}] {:<9} {:<6} rw {:.1} σ {:>5.0} µg {:>5} rows {:.1} Hz | {:<13} eff [{}] amb [{}] false [{}] {:.2}s{}",
        c.seed,
        members.join(", "),
        c.profile.name(),
        c.positions.name(),
        c.rw_ratio,
        c.sigma_ug,
        c.rows,
        c.rate_hz,
        r.outcome.name(),
        r.effects.join(" "),
        r.ambiguous.join(" "),
        r.false_ids.join(" "),
        r.secs,
        r.error.as_deref().map(|e| format!(" ERROR {e}")).unwrap_or_default()
    )
}

/// Kind of a mechanism for the per-combination scorecard: `dynamic` (lag, both plays,
/// self-heating, warm-up: the response to the thermal history or the power-on), `tempco`
/// (bias order, scale and cross-coupling tempcos) or `static` (cross-axis, scale factor,
/// asymmetry, k2, k3).
pub fn kind(id: &str) -> &'static str {
    match id {
        "thermal_lag" | "thermal_hysteresis" | "bias_hysteresis" | "self_heating" | "warmup" => "dynamic",
        "bias_temp_order" | "scale_temp" | "cross_coupling_temp" => "tempco",
        _ => "static",
    }
}

/// Tallies of a group of combined cases (one row of the scorecard).
#[derive(Clone, Debug, Default)]
pub struct CombinedTally {
    /// Cases.
    pub cases: usize,
    /// Members ≥ 5 σ: (named, total).
    pub strong: (usize, usize),
    /// Members of all sizes: (named, total).
    pub all: (usize, usize),
    /// Members named only inside an ambiguous group.
    pub ambiguous: usize,
    /// Cases with a false discovery.
    pub false_disc: usize,
    /// False ids named, with counts.
    pub false_ids: BTreeMap<String, usize>,
}

impl CombinedTally {
    fn add_case(&mut self, r: &CaseResult, members: &[&MemberResult]) {
        self.cases += 1;
        for m in members {
            self.all.1 += 1;
            self.all.0 += usize::from(m.named);
            self.ambiguous += usize::from(m.ambiguous);
            if m.size_sigma >= STRONG_SIGMA {
                self.strong.1 += 1;
                self.strong.0 += usize::from(m.named);
            }
        }
        self.false_disc += usize::from(!r.false_ids.is_empty());
        for f in &r.false_ids {
            *self.false_ids.entry(f.clone()).or_default() += 1;
        }
    }

    fn row(&self, name: &str) -> String {
        let fi: Vec<String> = self.false_ids.iter().map(|(k, v)| format!("{k}×{v}")).collect();
        let frac =
            |(a, b): (usize, usize)| if b == 0 { "—".to_string() } else { format!("{a}/{b} {:.0}%", pct(a, b)) };
        format!(
            "{:<40} {:>5} {:>13} {:>13} {:>5} {:>4}/{:<3}{:>4.0}%  {}",
            name,
            self.cases,
            frac(self.strong),
            frac(self.all),
            self.ambiguous,
            self.false_disc,
            self.cases,
            pct(self.false_disc, self.cases),
            fi.join(" ")
        )
    }
}

/// The combined scorecard.
#[derive(Clone, Debug, Default)]
pub struct CombinedSummary {
    /// All cases.
    pub total: CombinedTally,
    /// Per member mechanism (a case counts once per member of that id; its false discoveries
    /// count in the rows of all its members).
    pub per_member: BTreeMap<String, CombinedTally>,
    /// Per combination of kinds (`dynamic+static`, …).
    pub per_kinds: BTreeMap<String, CombinedTally>,
    /// Per pair of mechanisms drawn together (a 3-member case counts in its three pairs, with
    /// the two members of the pair).
    pub per_pair: BTreeMap<String, CombinedTally>,
    /// Cases with and without a random walk.
    pub by_rw: [CombinedTally; 2],
    /// Median and maximum diagnosis time \[s\].
    pub secs: (f64, f64),
    /// The text (per member, per kinds, totals).
    pub text: String,
    /// The per-pair table.
    pub pairs_text: String,
}

/// Summarises combined cases into the scorecard.
pub fn summarize_combined(res: &[CaseResult]) -> CombinedSummary {
    let mut s = CombinedSummary::default();
    for r in res {
        let all: Vec<&MemberResult> = r.members.iter().collect();
        s.total.add_case(r, &all);
        s.by_rw[usize::from(r.case.rw_ratio > 0.0)].add_case(r, &all);
        for m in &r.members {
            s.per_member.entry(m.id.to_string()).or_default().add_case(r, &[m]);
        }
        let mut kinds: Vec<&str> = r.members.iter().map(|m| kind(m.id)).collect();
        kinds.sort_unstable();
        s.per_kinds.entry(kinds.join("+")).or_default().add_case(r, &all);
        for a in 0..r.members.len() {
            for b in a + 1..r.members.len() {
                let (ma, mb) = (&r.members[a], &r.members[b]);
                let (p, q) = if ma.id <= mb.id { (ma, mb) } else { (mb, ma) };
                s.per_pair.entry(format!("{} + {}", p.id, q.id)).or_default().add_case(r, &[p, q]);
            }
        }
    }
    let mut times: Vec<f64> = res.iter().map(|r| r.secs).collect();
    times.sort_by(f64::total_cmp);
    if !times.is_empty() {
        s.secs = (times[times.len() / 2], times[times.len() - 1]);
    }
    let head = format!(
        "{:<40} {:>5} {:>13} {:>13} {:>5} {:>13}  false names",
        "", "cases", "named ≥5σ", "named all", "amb.", "false-disc"
    );
    let mut w = String::new();
    let anchor = res.first().map_or(f64::NAN, |r| r.case.anchor_c);
    let _ = writeln!(
        w,
        "combined scorecard ({} cases of 2–3 mechanisms; concealed tempcos anchored at {anchor} °C)",
        res.len()
    );
    let _ = writeln!(w, "{}", head.replacen(&format!("{:<40}", ""), &format!("{:<40}", "member"), 1));
    for id in MECH_IDS {
        if let Some(t) = s.per_member.get(id) {
            let _ = writeln!(w, "{}", t.row(id));
        }
    }
    let _ = writeln!(w, "{}", head.replacen(&format!("{:<40}", ""), &format!("{:<40}", "kinds drawn together"), 1));
    for (k, t) in &s.per_kinds {
        let _ = writeln!(w, "{}", t.row(k));
    }
    for (t, name) in s.by_rw.iter().zip(["without random walk", "with random walk"]) {
        if t.cases > 0 {
            let _ = writeln!(w, "{}", t.row(name));
        }
    }
    let _ = writeln!(w, "{}", s.total.row("all"));
    let _ = writeln!(
        w,
        "members ≥ {STRONG_SIGMA}× noise named exactly or ambiguous with the truth in the set: {}/{} ({:.1} %)",
        s.total.strong.0,
        s.total.strong.1,
        pct(s.total.strong.0, s.total.strong.1)
    );
    let _ = writeln!(
        w,
        "cases with a false discovery: {}/{} ({:.1} %)",
        s.total.false_disc,
        s.total.cases,
        pct(s.total.false_disc, s.total.cases)
    );
    let _ = writeln!(w, "diagnosis time per case: median {:.2} s, max {:.2} s", s.secs.0, s.secs.1);
    s.text = w;
    let mut p = String::new();
    let _ = writeln!(p, "{}", head.replacen(&format!("{:<40}", ""), &format!("{:<40}", "pair drawn together"), 1));
    for (k, t) in &s.per_pair {
        let _ = writeln!(p, "{}", t.row(k));
    }
    s.pairs_text = p;
    s
}

/// Writes one line per member of the combined cases into `dir/name` (the case's draws, the
/// member's draws and result, the case's names).
pub fn write_combined_csv(res: &[CaseResult], dir: &Path, name: &str) -> std::io::Result<PathBuf> {
    std::fs::create_dir_all(dir)?;
    let mut w = String::from(
        "seed,members,member,params,size_sigma,snr,size_x_sigma,size_y_sigma,size_z_sigma,named,only_ambiguous,sigma_ug,rw_ratio,profile,positions,power_s,rows,rate_hz,outcome,effects,ambiguous,false_ids,heldout_before_x_mg,heldout_after_x_mg,heldout_before_y_mg,heldout_after_y_mg,heldout_before_z_mg,heldout_after_z_mg,floor_x_mg,floor_y_mg,floor_z_mg,secs,error\n",
    );
    for r in res {
        let c = &r.case;
        let ids: Vec<&str> = r.members.iter().map(|m| m.id).collect();
        let mechs: Vec<Mech> = c.members().into_iter().map(|m| m.mech).collect();
        for (m, mech) in r.members.iter().zip(&mechs) {
            let _ = write!(
                w,
                "{},{},{},{},{:.5},{:.3},{:.5},{:.5},{:.5},{},{},{:.3},{:.3},{},{},{},{},{},{},{},{},{}",
                c.seed,
                ids.join(" "),
                m.id,
                mech.params(),
                m.size_sigma,
                m.snr,
                m.axis_size_sigma[0],
                m.axis_size_sigma[1],
                m.axis_size_sigma[2],
                m.named,
                m.ambiguous,
                c.sigma_ug,
                c.rw_ratio,
                c.profile.name(),
                c.positions.name(),
                c.power_column,
                c.rows,
                c.rate_hz,
                r.outcome.name(),
                r.effects.join(" "),
                r.ambiguous.join(" "),
                r.false_ids.join(" ")
            );
            for i in 0..3 {
                let _ = write!(w, ",{:.5},{:.5}", r.heldout_mg[i].0, r.heldout_mg[i].1);
            }
            let _ = writeln!(
                w,
                ",{:.5},{:.5},{:.5},{:.3},{}",
                r.floor_mg[0],
                r.floor_mg[1],
                r.floor_mg[2],
                r.secs,
                r.error.as_deref().unwrap_or("").replace([',', '\n'], ";")
            );
        }
    }
    let path = dir.join(name);
    std::fs::write(&path, w)?;
    Ok(path)
}

/// Bin edges of the record-length-aware size `z = size·√rows` (log spaced).
pub const Z_EDGES: [f64; 11] = [1.0, 2.0, 3.5, 6.0, 10.0, 18.0, 32.0, 56.0, 100.0, 180.0, 320.0];

/// Detectability in `z`: per bin of [`Z_EDGES`], the fraction of the members (of mechanism `id`,
/// or all) named; `(centre, p, n)`.
pub fn curve_snr(res: &[CaseResult], id: Option<&str>) -> Vec<(f64, f64, usize)> {
    let last = Z_EDGES[Z_EDGES.len() - 1];
    let mut out = Vec::new();
    for w in Z_EDGES.windows(2) {
        let sel: Vec<&MemberResult> = res
            .iter()
            .flat_map(|r| r.members.iter())
            .filter(|m| id.is_none_or(|i| m.id == i))
            .filter(|m| m.snr >= w[0] && (m.snr < w[1] || (w[1] == last && m.snr <= last * 1.0001)))
            .collect();
        if !sel.is_empty() {
            let named = sel.iter().filter(|m| m.named).count();
            out.push(((w[0] * w[1]).sqrt(), named as f64 / sel.len() as f64, sel.len()));
        }
    }
    out
}

/// The detectability table: per mechanism and bin of `z`, `named/members`.
pub fn snr_table(res: &[CaseResult]) -> String {
    let mut w = String::new();
    let _ = write!(w, "{:<20}", "z = size·√rows");
    for e in Z_EDGES.windows(2) {
        let _ = write!(w, " {:>9}", format!("{}–{}", e[0], e[1]));
    }
    let _ = writeln!(w);
    let mut ids: Vec<Option<&str>> = MECH_IDS.iter().map(|i| Some(*i)).collect();
    ids.push(None);
    for id in ids {
        let _ = write!(w, "{:<20}", id.unwrap_or("all"));
        let c = curve_snr(res, id);
        for e in Z_EDGES.windows(2) {
            let centre = (e[0] * e[1]).sqrt();
            match c.iter().find(|p| (p.0 - centre).abs() < 1e-9) {
                Some(p) => {
                    let _ = write!(w, " {:>9}", format!("{}/{}", (p.1 * p.2 as f64).round(), p.2));
                }
                None => {
                    let _ = write!(w, " {:>9}", "—");
                }
            }
        }
        let _ = writeln!(w);
    }
    w
}

/// Draws the members' detectability against `z` into `dir/blind_detectability_z.png`: one
/// line per mechanism, one for all.
pub fn plot_snr(res: &[CaseResult], dir: &Path) -> Result<PathBuf, String> {
    use plotters::style::{FontStyle, register_font};
    let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let path = dir.join("blind_detectability_z.png");
    let tmp = dir.join(format!(".blind_detectability_z.tmp-{}.png", std::process::id()));
    let (lo, hi) = (Z_EDGES[0], Z_EDGES[Z_EDGES.len() - 1]);
    let members: usize = res.iter().map(|r| r.members.len()).sum();
    let result = (|| -> Result<(), String> {
        let root = BitMapBackend::new(&tmp, (1100, 640)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!(
                    "blind harness, combined cases: probability a member is named vs its size ({} cases, {members} members)",
                    res.len()
                ),
                ("sans-serif", 18),
            )
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(60)
            .build_cartesian_2d((lo..hi).log_scale(), -0.04f64..1.04)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("z = RMS of the member's contribution / white noise σ × √rows (white noise only)")
            .y_desc("probability named (lines offset ±0.024)")
            .light_line_style(RGBColor(238, 238, 238))
            .x_label_formatter(&|x| format!("{x:.0}"))
            .label_style(("sans-serif", 14))
            .draw()
            .map_err(|e| e.to_string())?;
        for y in [0.1, 0.9] {
            chart
                .draw_series(LineSeries::new([(lo, y), (hi, y)], BLACK.mix(0.3).stroke_width(1)))
                .map_err(|e| e.to_string())?;
        }
        for (k, id) in MECH_IDS.iter().enumerate() {
            let off = (k as f64 - 6.0) * 0.004;
            let pts: Vec<(f64, f64)> = curve_snr(res, Some(id)).iter().map(|p| (p.0, p.1 + off)).collect();
            if pts.is_empty() {
                continue;
            }
            let col = Palette99::pick(k).to_rgba();
            chart
                .draw_series(LineSeries::new(pts.iter().copied(), col.stroke_width(1)))
                .map_err(|e| e.to_string())?
                .label(*id)
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 14, y)], col.stroke_width(2)));
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, col.filled()))).map_err(|e| e.to_string())?;
        }
        let all: Vec<(f64, f64)> = curve_snr(res, None).iter().map(|p| (p.0, p.1)).collect();
        chart
            .draw_series(LineSeries::new(all.iter().copied(), BLACK.stroke_width(3)))
            .map_err(|e| e.to_string())?
            .label("all members")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 14, y)], BLACK.stroke_width(3)));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 12))
            .draw()
            .map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())
    })();
    match result.and_then(|_| std::fs::rename(&tmp, &path).map_err(|e| e.to_string())) {
        Ok(()) => Ok(path),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(format!("{}: {e}", path.display()))
        }
    }
}

/// Cases `seed0 .. seed0 + n` with profiles drawn the way users record
/// ([`Case::draw_user`]), one member or none (`combined` false) or 2–3, diagnosed on
/// `threads` threads (in seed order in the result).
pub fn run_user(n: usize, seed0: u64, combined: bool, threads: usize, progress: bool) -> Vec<CaseResult> {
    let cases: Vec<Case> = (0..n as u64).map(|k| Case::draw_user(seed0 + k, combined)).collect();
    run_list(&cases, threads, progress)
}

/// How a case with a user profile came out, by the answer a user gets.
pub fn user_category(r: &CaseResult) -> &'static str {
    if !r.false_ids.is_empty() {
        return "definite false name";
    }
    let visible: Vec<&MemberResult> = r.members.iter().filter(|m| m.visible()).collect();
    let nothing = r.effects.is_empty() && r.ambiguous.is_empty();
    if visible.iter().all(|m| m.named) {
        if visible.iter().any(|m| m.ambiguous) {
            "truthful ambiguity"
        } else if visible.is_empty() && nothing {
            "honest nothing"
        } else {
            "exact"
        }
    } else if nothing {
        "honest nothing"
    } else {
        "partial"
    }
}

impl MemberResult {
    /// What the profile lets one see of it reaches [`STRONG_SIGMA`] on some accelerometer
    /// (the generator's own truth: its contribution with each session's offset removed).
    pub fn visible(&self) -> bool {
        self.axis_size_sigma.iter().any(|&s| s >= STRONG_SIGMA)
    }
}

/// The scorecard of the user-profile draw.
#[derive(Clone, Debug, Default)]
pub struct UserSummary {
    /// Members the profile lets one see at ≥ 5 σ: named exactly or inside a truthful group,
    /// of all.
    pub visible: (usize, usize),
    /// Of those, named only inside a group.
    pub visible_ambiguous: usize,
    /// Cases with a definite false name, of all.
    pub false_cases: (usize, usize),
    /// Cases per category ([`user_category`]).
    pub categories: BTreeMap<&'static str, usize>,
    /// The text.
    pub text: String,
}

/// Summarises user-profile cases: per category, per member mechanism, per profile.
pub fn summarize_user(res: &[CaseResult]) -> UserSummary {
    let mut s = UserSummary::default();
    // (visible named, visible, in groups only, cases, false cases)
    let mut per_mech: BTreeMap<&str, (usize, usize, usize, usize, usize)> = BTreeMap::new();
    let mut per_profile: BTreeMap<String, (usize, usize, usize, usize)> = BTreeMap::new();
    for r in res {
        let cat = user_category(r);
        *s.categories.entry(cat).or_default() += 1;
        let false_case = !r.false_ids.is_empty();
        s.false_cases.1 += 1;
        s.false_cases.0 += usize::from(false_case);
        let plan = r.case.user.as_ref();
        let sessions = plan.map_or(1, |u| u.sessions.len());
        let first_kind = plan.and_then(|u| u.sessions.first()).map_or("?", |s| s.kind);
        let powered = plan.and_then(|u| u.sessions.first()).is_some_and(|s| s.power_offset_s > 0.0);
        let profile = if sessions > 1 {
            format!("{sessions} sessions joined")
        } else {
            format!("one session: {first_kind}{}", if powered { " (powered before)" } else { "" })
        };
        let pp = per_profile.entry(profile).or_default();
        pp.2 += 1;
        pp.3 += usize::from(false_case);
        let ids: Vec<&str> = if r.members.is_empty() { vec!["none"] } else { r.members.iter().map(|m| m.id).collect() };
        for id in &ids {
            let e = per_mech.entry(id).or_default();
            e.3 += 1;
            e.4 += usize::from(false_case);
        }
        for m in r.members.iter().filter(|m| m.visible()) {
            s.visible.1 += 1;
            s.visible.0 += usize::from(m.named);
            s.visible_ambiguous += usize::from(m.named && m.ambiguous);
            let e = per_mech.entry(m.id).or_default();
            e.1 += 1;
            e.0 += usize::from(m.named);
            e.2 += usize::from(m.named && m.ambiguous);
            pp.1 += 1;
            pp.0 += usize::from(m.named);
        }
    }
    let mut w = String::new();
    let _ = writeln!(w, "user-profile scorecard ({} cases; profiles drawn independently of the members)", res.len());
    let frac = |(a, b): (usize, usize)| if b == 0 { "—".to_string() } else { format!("{a}/{b} {:.0}%", pct(a, b)) };
    let _ =
        writeln!(w, "{:<34} {:>5} {:>14} {:>8} {:>12}", "member", "cases", "visible named", "in group", "false-name");
    let mut order: Vec<&str> = vec!["none"];
    order.extend(MECH_IDS);
    for id in order {
        if let Some(&(named, vis, amb, cases, fal)) = per_mech.get(id) {
            let _ =
                writeln!(w, "{:<34} {:>5} {:>14} {:>8} {:>12}", id, cases, frac((named, vis)), amb, frac((fal, cases)));
        }
    }
    let _ = writeln!(w, "{:<34} {:>5} {:>14} {:>8} {:>12}", "profile", "cases", "visible named", "", "false-name");
    for (p, &(named, vis, cases, fal)) in &per_profile {
        let _ = writeln!(w, "{:<34} {:>5} {:>14} {:>8} {:>12}", p, cases, frac((named, vis)), "", frac((fal, cases)));
    }
    let cats: Vec<String> = s.categories.iter().map(|(k, v)| format!("{k} {v}")).collect();
    let _ = writeln!(w, "cases: {}", cats.join(", "));
    let _ = writeln!(
        w,
        "members the profile lets one see at ≥ {STRONG_SIGMA} σ named exactly or inside a truthful group: {} ({} of them in a group)",
        frac(s.visible),
        s.visible_ambiguous
    );
    let _ = writeln!(w, "cases with a definite false name: {}", frac(s.false_cases));
    // Held-out figures: no axis made worse; several members: every one the profile shows named
    // and every axis down to 1.25× its floor.
    let ok = || res.iter().filter(|r| r.error.is_none());
    let axes = ok().count() * 3;
    let worse: Vec<(u64, usize, f64)> = ok()
        .flat_map(|r| (0..3).map(move |i| (r.case.seed, i, r.heldout_mg[i].1 / r.heldout_mg[i].0)))
        .filter(|x| x.2 > 1.0)
        .collect();
    let worst = worse.iter().map(|x| x.2).fold(1.0, f64::max);
    let _ = writeln!(
        w,
        "axes whose held-out RMS the answer made worse: {}/{axes} (worst {worst:.3}×{})",
        worse.len(),
        worse.iter().map(|(seed, i, q)| format!(" seed {seed} {}: {q:.3}×", ["x", "y", "z"][*i])).collect::<String>()
    );
    let multi: Vec<&CaseResult> = ok().filter(|r| r.members.len() > 1).collect();
    if !multi.is_empty() {
        let full = multi
            .iter()
            .filter(|r| {
                r.members.iter().filter(|m| m.visible()).all(|m| m.named)
                    && (0..3).all(|i| r.heldout_mg[i].1 <= 1.25 * r.floor_mg[i])
            })
            .count();
        let _ = writeln!(
            w,
            "cases of several members with every visible member named and every axis within 1.25× its floor: {}",
            frac((full, multi.len()))
        );
    }
    s.text = w;
    s
}

/// One line of a user-profile case: its plan, members (drawn and visible size) and answer.
pub fn user_line(r: &CaseResult) -> String {
    let c = &r.case;
    let members: Vec<String> = r
        .members
        .iter()
        .map(|m| {
            format!(
                "{}{} {:.1}σ vis {:.1}/{:.1}/{:.1}",
                m.id,
                if m.named { if m.ambiguous { "(grp)" } else { "(ok)" } } else { "" },
                m.size_sigma,
                m.axis_size_sigma[0],
                m.axis_size_sigma[1],
                m.axis_size_sigma[2]
            )
        })
        .collect();
    format!(
        "seed {:>6} {:<28} {:<6} rw {:.1} σ {:>5.0} µg {:>7} rows {:>5.1} Hz | {} | {:<19} eff [{}] amb [{}] false [{}] after/floor {} {:.1}s{}",
        c.seed,
        c.user.as_ref().map_or_else(|| c.profile.name(), |u| u.name()),
        c.positions.name(),
        c.rw_ratio,
        c.sigma_ug,
        c.rows,
        c.rate_hz,
        members.join("; "),
        user_category(r),
        r.effects.join(" "),
        r.ambiguous.join(" "),
        r.false_ids.join(" "),
        (0..3).map(|i| format!("{:.2}", r.heldout_mg[i].1 / r.floor_mg[i])).collect::<Vec<_>>().join("/"),
        r.secs,
        r.error.as_deref().map(|e| format!(" ERROR {e}")).unwrap_or_default()
    )
}
