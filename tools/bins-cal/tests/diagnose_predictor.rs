//! The proposal's expected evidence checked against realised runs (docs/diagnosis.md, "When the
//! data cannot decide"). The evidence a run of a test gives for a term against its rival is a
//! noisy draw: with the term's columns linear and the noise model true, a noncentral χ² whose
//! noncentrality is the expected evidence (`propose::evidence_interval`).
//!
//! - Default run: on the proposed test's design, data drawn from the fitted model under the
//!   recording's own noise model (white and random walk, generated here) give realised evidence
//!   whose mean is the expected evidence plus its degrees of freedom and that lands in the
//!   predicted 90 % interval about nine times in ten.
//! - `#[ignore]`d measurements (figures in docs/diagnosis.md and docs/measurements.md):
//!   simulated cases with their proposed tests run with REAL's physics and fresh noise
//!   (`cargo test --release -p bins-cal --test diagnose_predictor -- --ignored --nocapture
//!   simulated`), and the real sweep's first part predicting its remainder (`... real_sweep`).

use bins_cal::diagnose::mech::Mech;
use bins_cal::diagnose::propose::{self, Pair};
use bins_cal::diagnose::separate::{Fitted, predict};
use bins_cal::diagnose::{Diagnosis, Options, diagnose_with, prep::Prepared};
use bins_cal::recording::Row;
use bins_cal::sim::scenario::ScenarioFile;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use std::path::{Path, PathBuf};

/// A unit warming up after its one power-on at the start of a ramp, its die lagging (REAL,
/// `real`), or without either (SIM): 1.5 h at 0.5 Hz from +20 °C towards `end_c`.
struct Case {
    warm_v: f64,
    warm_tau_s: f64,
    die_tau_s: f64,
    end_c: f64,
    seed: u64,
}

impl Case {
    fn scenario(&self, real: bool) -> String {
        let (warm, die) = if real { (self.warm_v, self.die_tau_s) } else { (0.0, 0.0) };
        format!(
            r#"
[recording]
rate_Hz = 0.5
[unit]
preset = "paper"
fit = "poly"
order = 2
warmup_V = [{warm:?}, {warm:?}, {warm:?}]
warmup_tau_s = {tau:?}
[thermal]
start_C = 20.0
rate_C_per_min = 1.0
case_tau_s = 300.0
die_tau_s = {die:?}
[noise]
white_V = 1.0e-5
[[step]]
kind = "soak"
chamber_C = {end:?}
dwell_s = 5400.0
"#,
            tau = self.warm_tau_s,
            end = self.end_c,
        )
    }
}

fn rows(text: &str, seed: u64) -> Vec<Row> {
    ScenarioFile::parse(text, Path::new("s.toml")).unwrap().build(Path::new("s.toml")).unwrap().all_rows(seed)
}

fn twin(dir: &Path, name: &str, text: &str) -> propose::Twin {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    propose::Twin::read(&path).unwrap()
}

/// The diagnosis of a case (SIM seed `2·seed`, REAL seed `2·seed + 1`) and its twins.
fn diagnose_case(c: &Case, dir: &Path) -> (Diagnosis, propose::Twin, propose::Twin) {
    let (s, r) = (rows(&c.scenario(false), 2 * c.seed), rows(&c.scenario(true), 2 * c.seed + 1));
    let d = diagnose_with(&s, &r, Path::new("sim"), Path::new("real"), &Options::default()).unwrap();
    (d, twin(dir, "sim.toml", &c.scenario(false)), twin(dir, "real.toml", &c.scenario(true)))
}

/// What the fitted model of accelerometer `axis` predicts on the design `cp` (every term, at
/// its coefficients and θ as fitted on the recording, through the recording's sensitivity).
fn model_on(d: &Diagnosis, cp: &Prepared, axis: usize) -> Vec<f64> {
    let ctx = propose::context_on(d, cp, axis);
    let members: Vec<Fitted> =
        d.axes[axis].terms.iter().map(|t| Fitted { mech: t.mech, theta: t.theta, coef: t.coef.clone() }).collect();
    predict(&ctx, &members)
}

/// A run on the design `cp`: the model `eta` (per axis) plus the recording's noise model in its
/// deviance unit, a level walking with intensity q and white noise of the design's variance per
/// row, both times the unit (the whitened innovations then have the unit's variance).
fn drawn(d: &Diagnosis, cp: &Prepared, eta: &[Vec<f64>], rng: &mut rand_chacha::ChaCha8Rng) -> Prepared {
    let mut run = cp.clone();
    for axis in 0..3 {
        let fit = &d.axes[axis];
        let unit = fit.deviance_scale;
        let mut level = 0.0;
        for k in 0..run.t.len() {
            if k > 0 {
                let z: f64 = StandardNormal.sample(rng);
                level += z * (fit.q * unit * (run.t[k] - run.t[k - 1])).sqrt();
            }
            let z: f64 = StandardNormal.sample(rng);
            run.r[axis][k] = eta[axis][k] + level + z * (cp.r_white[axis][k] * unit).sqrt();
        }
    }
    run
}

/// The first case of docs/diagnosis.md's table (a warm-up of 0.3 mV, τ 600 s, and a 120 s die
/// lag after one power-on on a ramp to −20 °C; SIM seed 0): its diagnosis, its proposal and the
/// design of the proposed test.
fn first_case() -> (Diagnosis, propose::Proposal, Prepared) {
    let case = Case { warm_v: 3.0e-4, warm_tau_s: 600.0, die_tau_s: 120.0, end_c: -20.0, seed: 0 };
    let dir = tempfile::tempdir().unwrap();
    let (d, sim, _) = diagnose_case(&case, dir.path());
    let p = propose::propose(&d, &sim, None, &|_, _| {}).unwrap().expect("pairs to separate");
    let cp = propose::design(&sim, &p.ranked[0].candidate, propose::white_density(&d.prepared)).unwrap();
    (d, p, cp)
}

#[test]
fn realised_evidence_is_a_noncentral_chi2_draw_around_the_expected() {
    let (d, p, cp) = first_case();
    let expected = propose::evidence_on(&d, &cp, &p.pairs);
    let eta: Vec<Vec<f64>> = (0..3).map(|a| model_on(&d, &cp, a)).collect();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let draws = 24;
    let mut realised = vec![Vec::new(); p.pairs.len()];
    for _ in 0..draws {
        let run = drawn(&d, &cp, &eta, &mut rng);
        for (v, r) in realised.iter_mut().zip(propose::realised_on(&d, &run, &p.pairs)) {
            v.push(r);
        }
    }
    let (mut inside, mut counted) = (0usize, 0usize);
    for (k, pair) in p.pairs.iter().enumerate() {
        let (lambda, df) = (expected[k], pair.df);
        if !lambda.is_finite() || lambda <= 0.0 {
            continue;
        }
        let (lo, hi) = propose::evidence_interval(lambda, df, 0.9);
        let v = &realised[k];
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let sd = (2.0 * (df as f64 + 2.0 * lambda) / draws as f64).sqrt();
        let n_in = v.iter().filter(|x| (lo..=hi).contains(*x)).count();
        eprintln!(
            "{} {} / {}: expected {lambda:.1} (df {df}), interval {lo:.1}–{hi:.1}; realised mean {mean:.1} ± {sd:.1}, {n_in}/{draws} inside",
            ["x", "y", "z"][pair.axis],
            pair.a.id(),
            pair.b.id()
        );
        // The mean of a noncentral χ² is its noncentrality plus its degrees of freedom.
        assert!(
            (mean - (lambda + df as f64)).abs() <= 4.0 * sd,
            "{pair:?}: mean {mean:.2}, expected {lambda:.2} + {df}"
        );
        inside += n_in;
        counted += draws;
    }
    assert!(counted >= 3 * draws, "pairs with an expected evidence: {}", counted / draws);
    let share = inside as f64 / counted as f64;
    eprintln!("inside the 90 % interval: {inside} of {counted} ({share:.3})");
    assert!((0.8..=0.98).contains(&share), "{share:.3} of the realised evidence inside the 90 % interval");
}

/// Were another member of a group true instead of the modelled term (that member refitted to
/// the recording in the term's place, `propose::plausible_others`), runs of the proposed test
/// drawn from that model give realised evidence about what `propose::evidence_if_others_true`
/// expects: a noncentral χ² whose mean is that expectation plus the degrees of freedom.
#[test]
fn evidence_were_another_member_true_is_what_runs_drawn_from_it_give() {
    let (d, p, cp) = first_case();
    let best = &p.ranked[0];
    let eta: Vec<Vec<f64>> = (0..3).map(|a| model_on(&d, &cp, a)).collect();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let draws = 12;
    let (mut inside, mut counted, mut checked) = (0usize, 0usize, 0usize);
    for axis in 0..3 {
        let ctx = propose::context_on(&d, &cp, axis);
        for term in &d.axes[axis].terms {
            let own = predict(&ctx, &[Fitted { mech: term.mech, theta: term.theta, coef: term.coef.clone() }]);
            for other in propose::plausible_others(&d, axis, term.mech).into_iter().take(1) {
                let h = other.mech;
                let theirs = predict(&ctx, &[other]);
                // The pairs of this term whose evidence under `h` was predicted.
                let want: Vec<(usize, f64)> = p
                    .pairs
                    .iter()
                    .enumerate()
                    .filter(|(_, q)| q.axis == axis && q.a == term.mech)
                    .filter_map(|(j, _)| best.if_others[j].iter().find(|x| x.0 == h).map(|x| (j, x.1)))
                    .collect();
                if want.is_empty() {
                    continue;
                }
                // The fitted model with the term replaced by the other member on this axis.
                let mut model = eta.clone();
                for (m, (o, t)) in model[axis].iter_mut().zip(own.iter().zip(&theirs)) {
                    *m += t - o;
                }
                let mut realised = vec![Vec::new(); want.len()];
                for _ in 0..draws {
                    let run = drawn(&d, &cp, &model, &mut rng);
                    let got = propose::realised_on(&d, &run, &p.pairs);
                    for (v, (j, _)) in realised.iter_mut().zip(&want) {
                        v.push(got[*j]);
                    }
                }
                for (v, (j, lambda)) in realised.iter().zip(&want) {
                    let q = &p.pairs[*j];
                    let df = q.df as f64;
                    let mean = v.iter().sum::<f64>() / v.len() as f64;
                    let sd = (2.0 * (df + 2.0 * lambda) / draws as f64).sqrt();
                    let (lo, hi) = propose::evidence_interval(*lambda, q.df, 0.9);
                    let n_in = v.iter().filter(|x| (lo..=hi).contains(*x)).count();
                    eprintln!(
                        "{} {} / {}, were {} true: expected {lambda:.1} (df {}), interval {lo:.1}–{hi:.1}; realised mean {mean:.1} ± {sd:.1}, {n_in}/{draws} inside",
                        ["x", "y", "z"][axis],
                        q.a.id(),
                        q.b.id(),
                        h.id(),
                        q.df
                    );
                    assert!(
                        (mean - (lambda + df)).abs() <= 4.0 * sd,
                        "{q:?} were {h:?} true: mean {mean:.2}, expected {lambda:.2} + {df}"
                    );
                    inside += n_in;
                    counted += draws;
                    checked += 1;
                }
            }
        }
    }
    assert!(checked >= 3, "pairs checked under another member: {checked}");
    let share = inside as f64 / counted as f64;
    eprintln!("inside the 90 % interval: {inside} of {counted} ({share:.3})");
    assert!((0.75..=0.99).contains(&share), "{share:.3} of the realised evidence inside the 90 % interval");
}

/// One pair's outcome in a measurement.
struct Outcome {
    label: String,
    expected: f64,
    /// The noncentrality REAL's physics gives on the run (NaN where unknown).
    truth: f64,
    df: usize,
    /// The term's likelihood-ratio statistic on the recording (`propose::Pair::lr`).
    lr: f64,
    realised: f64,
    pair: Pair,
    /// Whether the pair's term is one of the mechanisms REAL has (simulated cases).
    true_term: bool,
    /// Whether it is its case's worst pair on the proposed test (over what it needs).
    worst: bool,
    /// The expected evidence were each other member of the pair's group true
    /// (`propose::evidence_if_others_true`).
    if_others: Vec<(Mech, f64)>,
}

fn summarise(what: &str, out: &[Outcome], simulated: bool) {
    let (mut inside, mut predicted, mut did, mut counted) = (0, 0, 0, 0);
    // Inside / counted: the pairs whose term REAL has, those whose term stands in for another,
    // and each case's worst pair.
    let mut split = [(0usize, 0usize); 4];
    // The interval of the run's noise alone, and the one that also carries what the recording
    // knows of the term's size (`propose::predictive_interval`).
    let mut noise_only = (0usize, 0usize, 0usize);
    // Inside one of the group members' intervals (`propose::group_intervals`): all, term REAL
    // has, stand-in, worst pair.
    let mut group = [(0usize, 0usize); 4];
    // How much longer the set is than the term's own interval, and how often it reaches below
    // the naming threshold (a run may then not name the term).
    let (mut widen, mut low_below) = (Vec::new(), 0usize);
    for o in out {
        let iv = propose::group_intervals(o.expected, &o.if_others, o.df, 0.9, o.lr);
        let g_in = iv.iter().any(|(lo, hi)| (*lo..=*hi).contains(&o.realised));
        let (tlo, thi) = propose::predictive_interval(o.expected, o.df, 0.9, o.lr);
        widen.push(iv.iter().map(|(lo, hi)| hi - lo).sum::<f64>() / (thi - tlo).max(1e-9));
        low_below += usize::from(iv.first().is_some_and(|x| x.0 < o.pair.threshold));
        for (j, member) in [true, o.true_term, !o.true_term, o.worst].into_iter().enumerate() {
            if member {
                group[j].0 += usize::from(g_in);
                group[j].1 += 1;
            }
        }
        let (nlo, nhi) = propose::evidence_interval(o.expected, o.df, 0.9);
        let n_in = (nlo..=nhi).contains(&o.realised);
        noise_only.0 += usize::from(n_in);
        noise_only.1 += usize::from(n_in && o.true_term);
        noise_only.2 += usize::from(n_in && !o.true_term);
        let (lo, hi) = propose::predictive_interval(o.expected, o.df, 0.9, o.lr);
        let is_in = (lo..=hi).contains(&o.realised);
        let sep = o.expected >= o.pair.needed;
        let named = o.realised >= o.pair.threshold;
        let (tlo, thi) = propose::evidence_interval(o.truth, o.df, 0.9);
        let truth_in = (tlo..=thi).contains(&o.realised);
        let truth = if o.truth.is_finite() {
            format!(" (REAL's physics {:.1}, {} its interval)", o.truth, if truth_in { "inside" } else { "outside" })
        } else {
            String::new()
        };
        println!(
            "{}: expected {:.1}{truth}, df {}, 90 % interval {:.1}–{:.1}, realised {:.1} {}; needed {:.1}, threshold {:.1}{}",
            o.label,
            o.expected,
            o.df,
            lo,
            hi,
            o.realised,
            if is_in { "inside" } else { "OUTSIDE" },
            o.pair.needed,
            o.pair.threshold,
            if sep { if named { ", separated" } else { ", NOT separated" } } else { "" }
        );
        counted += 1;
        inside += usize::from(is_in);
        predicted += usize::from(sep);
        did += usize::from(sep && named);
        for (j, member) in [o.true_term, !o.true_term, o.worst].into_iter().enumerate() {
            if member {
                split[j].0 += usize::from(is_in);
                split[j].1 += 1;
            }
        }
        if o.truth.is_finite() {
            split[3].0 += usize::from(truth_in);
            split[3].1 += 1;
        }
    }
    let pc = |a: usize, b: usize| 100.0 * a as f64 / b.max(1) as f64;
    println!(
        "{what}: {counted} pairs; realised inside the predicted 90 % interval {inside} ({:.1} %; the run's noise alone {} ({:.1} %)); predicted to separate {predicted}, separated {did} ({:.1} %)",
        pc(inside, counted),
        noise_only.0,
        pc(noise_only.0, counted),
        pc(did, predicted)
    );
    println!(
        "{what}: realised inside one of the group members' 90 % intervals {} of {} ({:.1} %); pairs whose term REAL has {} of {} ({:.1} %), stand-in terms {} of {} ({:.1} %), each case's worst pair {} of {} ({:.1} %)",
        group[0].0,
        group[0].1,
        pc(group[0].0, group[0].1),
        group[1].0,
        group[1].1,
        pc(group[1].0, group[1].1),
        group[2].0,
        group[2].1,
        pc(group[2].0, group[2].1),
        group[3].0,
        group[3].1,
        pc(group[3].0, group[3].1)
    );
    widen.sort_by(f64::total_cmp);
    let q = |f: f64| widen.get(((widen.len().max(1) - 1) as f64 * f) as usize).copied().unwrap_or(f64::NAN);
    println!(
        "{what}: the intervals' total length over the term's own interval's: median {:.2}, 90th percentile {:.2}; the lowest below the naming threshold in {} of {}",
        q(0.5),
        q(0.9),
        low_below,
        out.len()
    );
    if !simulated {
        return;
    }
    println!(
        "{what}: inside the interval, pairs whose term REAL has {} of {} ({:.1} %; noise alone {}), whose term stands in for another {} of {} ({:.1} %; noise alone {}); each case's worst pair {} of {} ({:.1} %)",
        split[0].0,
        split[0].1,
        pc(split[0].0, split[0].1),
        noise_only.1,
        split[1].0,
        split[1].1,
        pc(split[1].0, split[1].1),
        noise_only.2,
        split[2].0,
        split[2].1,
        pc(split[2].0, split[2].1)
    );
    println!(
        "{what}: realised inside the 90 % interval about the noncentrality REAL's physics gives (the noise alone): {} of {} ({:.1} %)",
        split[3].0,
        split[3].1,
        pc(split[3].0, split[3].1)
    );
}

/// Simulated cases (one power-on, one monotone ramp; warm-up size and τ, die lag, ramp
/// direction and seeds varied), each with its proposed test run once with REAL's physics and
/// fresh noise on the design's rows (`propose::run_on_design`).
#[test]
#[ignore = "measurement: 40 cases, about a minute"]
fn simulated_proposed_tests_realise_their_expected_evidence() {
    let mut cases = Vec::new();
    let sizes = [(1.0e-4, 300.0), (2.0e-4, 600.0), (3.0e-4, 900.0), (5.0e-4, 450.0), (1.5e-4, 1200.0)];
    let lags = [60.0, 120.0, 200.0];
    let ends = [-20.0, 60.0];
    for i in 0..40u64 {
        let (warm_v, warm_tau_s) = sizes[i as usize % sizes.len()];
        cases.push(Case {
            warm_v,
            warm_tau_s,
            die_tau_s: lags[i as usize % lags.len()],
            end_c: ends[(i as usize / 5) % 2],
            seed: 10 + i,
        });
    }
    let mut out = Vec::new();
    for (i, case) in cases.iter().enumerate() {
        let dir = tempfile::tempdir().unwrap();
        let t0 = std::time::Instant::now();
        let (d, sim, real) = diagnose_case(case, dir.path());
        let Some(p) = propose::propose(&d, &sim, None, &|_, _| {}).unwrap() else {
            println!("case {i}: nothing to separate");
            continue;
        };
        let best = &p.ranked[0];
        let dens = propose::white_density(&d.prepared);
        let seeds = (1000 + 2 * case.seed, 1001 + 2 * case.seed);
        let run = propose::run_on_design(&sim, &real, &best.candidate, dens, seeds, true).unwrap();
        let realised = propose::realised_on(&d, &run, &p.pairs);
        // The same run without noise: the evidence REAL's physics gives (its noncentrality).
        let clean = propose::run_on_design(&sim, &real, &best.candidate, dens, seeds, false).unwrap();
        let truth = propose::realised_on(&d, &clean, &p.pairs);
        let design = propose::design(&sim, &best.candidate, dens).unwrap();
        let if_others = propose::evidence_if_others_true(&d, &design, &p.pairs);
        println!(
            "case {i}: warm-up {:.1} mV τ {} s, die lag {} s, ramp to {} °C; proposed {} ({:.1} h); {} pairs ({:.1} s)",
            case.warm_v * 1e3,
            case.warm_tau_s,
            case.die_tau_s,
            case.end_c,
            best.candidate.name,
            best.candidate.duration_s() / 3600.0,
            p.pairs.len(),
            t0.elapsed().as_secs_f64()
        );
        println!(
            "case {i}: terms x {:?}, y {:?}, z {:?}",
            d.axes[0].terms.iter().map(|t| t.mech.id()).collect::<Vec<_>>(),
            d.axes[1].terms.iter().map(|t| t.mech.id()).collect::<Vec<_>>(),
            d.axes[2].terms.iter().map(|t| t.mech.id()).collect::<Vec<_>>()
        );
        let worst = (0..p.pairs.len())
            .filter(|&k| best.deviance[k].is_finite() && realised[k].is_finite())
            .min_by(|&a, &b| (best.deviance[a] / p.pairs[a].needed).total_cmp(&(best.deviance[b] / p.pairs[b].needed)));
        for (k, pair) in p.pairs.iter().enumerate() {
            if !best.deviance[k].is_finite() || !realised[k].is_finite() {
                continue;
            }
            out.push(Outcome {
                label: format!("case {i} {} {} / {}", ["x", "y", "z"][pair.axis], pair.a.id(), pair.b.id()),
                expected: best.deviance[k],
                truth: truth[k],
                df: pair.df,
                lr: pair.lr,
                realised: realised[k],
                pair: *pair,
                true_term: matches!(pair.a, Mech::Warmup | Mech::ThermalLag),
                worst: worst == Some(k),
                if_others: if_others[k].clone(),
            });
        }
    }
    summarise("simulated", &out, true);
}

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/real").join(name)
}

/// The real sweep (`data/real/tofupilot-sweep-*.csv`): diagnosed on its first part, the
/// evidence its remainder would give for the first part's pairs predicted on the remainder's
/// own rows (`evidence_on`), beside what the remainder gives (`realised_on` on its residual)
/// and the remainder's own diagnosis of y.
#[test]
#[ignore = "measurement: the real sweep split at 50 … 90 % of its rows"]
fn real_sweep_first_part_predicts_its_remainder() {
    let (_, s) = bins_cal::recording::read_all(&data("tofupilot-sweep-sim.csv")).unwrap();
    let (_, r) = bins_cal::recording::read_all(&data("tofupilot-sweep-real.csv")).unwrap();
    for share in [0.5, 0.6, 0.7, 0.75, 0.8, 0.85, 0.9] {
        let cut = (s.len() as f64 * share) as usize;
        let (n1, n2) = (Path::new("sweep first part"), Path::new("sweep remainder"));
        let d = diagnose_with(&s[..cut], &r[..cut], n1, n1, &Options::default()).unwrap();
        let pairs = propose::pairs(&d);
        let rem = bins_cal::diagnose::prep::prepare_blocks(&s[cut..], &r[cut..], n2, n2, None).unwrap();
        let expected = propose::evidence_on(&d, &rem, &pairs);
        let realised = propose::realised_on(&d, &rem, &pairs);
        let if_others = propose::evidence_if_others_true(&d, &rem, &pairs);
        let dr = diagnose_with(&s[cut..], &r[cut..], n2, n2, &Options::default()).unwrap();
        let rep = &dr.report;
        println!(
            "split at row {cut} of {} (t = {:.0} s): first part's y terms {:?}; remainder's y: effects {:?}, groups {:?}",
            s.len(),
            s[cut].t_s,
            d.axes[1].terms.iter().map(|t| t.mech.id()).collect::<Vec<_>>(),
            rep.effects.iter().filter(|e| e.axes.iter().any(|a| a == "y")).map(|e| e.id.clone()).collect::<Vec<_>>(),
            rep.ambiguous.iter().filter(|g| g.axes.iter().any(|a| a == "y")).map(|g| g.ids.clone()).collect::<Vec<_>>(),
        );
        let out: Vec<Outcome> = pairs
            .iter()
            .enumerate()
            .filter(|(k, _)| expected[*k].is_finite() && realised[*k].is_finite())
            .map(|(k, pair)| Outcome {
                label: format!("{} {} / {}", ["x", "y", "z"][pair.axis], pair.a.id(), pair.b.id()),
                expected: expected[k],
                truth: f64::NAN,
                df: pair.df,
                lr: pair.lr,
                realised: realised[k],
                pair: *pair,
                true_term: false,
                worst: false,
                if_others: if_others[k].clone(),
            })
            .collect();
        summarise(&format!("real sweep split at {:.0} %", share * 100.0), &out, false);
        println!();
    }
}
