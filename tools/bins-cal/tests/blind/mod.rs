//! Blind harness of `bins-cal diagnose` (docs/diagnosis-blind.md): cases drawn at random by an
//! independent generator ([`generator`], `gen.rs`), diagnosed, classified, summarised per mechanism, written as
//! CSV and drawn as a detectability curve.

#[path = "gen.rs"]
pub mod generator;

use bins_cal::diagnose::diagnose;
use bins_cal::diagnose::report::Report;
use generator::{Case, MECH_IDS};
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

/// The diagnosis's report of one case as JSON (or the error), for looking into a failure.
pub fn report_json(case: &Case) -> String {
    let (sim, real, _) = generator::generate(case);
    match diagnose(&sim, &real, Path::new("sim.csv"), Path::new("real.csv")) {
        Ok(d) => serde_json::to_string_pretty(&d.report).unwrap_or_else(|e| e.to_string()),
        Err(e) => e.to_string(),
    }
}

/// Generates, diagnoses and classifies one case.
pub fn run_case(case: &Case) -> CaseResult {
    let (sim, real, truth) = generator::generate(case);
    let t0 = Instant::now();
    let d = diagnose(&sim, &real, Path::new("sim.csv"), Path::new("real.csv"));
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
            let (o, f) = classify(case, &truth.axis_size_sigma, r);
            res.outcome = o;
            res.false_ids = f;
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
