//! `bins-cal allan` against independent references: the overlapping Allan and Hadamard
//! variances against their definition written here (cluster means summed with compensation,
//! sharing no code with the estimator), allantools' `oadev` and `edf_greenhall` and scipy's χ²
//! quantiles on the project's real recordings (values computed once, written below with the
//! versions), the noise terms of 21 simulated units with the intervals' coverage of the true
//! curve, the twin fitted to a simulated and to a real unit at rest, and the command's outputs
//! and errors.
#![allow(clippy::excessive_precision, reason = "the reference values as Python printed them, 17 digits")]

use bins_cal::allan::estimate::{EXACT_MAX_M, PARTIAL_POSITIONS};
use bins_cal::allan::twin::{self, TwinNoise};
use bins_cal::allan::{Config, Estimator, Grid, Kind, edf, pass, points, terms};
use bins_cal::sim::unit::{NoiseParams, NoiseState};
use rand::SeedableRng;
use std::path::Path;

#[allow(dead_code)] // the CLI helpers other test files use
mod common;

/// Neumaier-compensated sum.
fn csum(v: &[f64]) -> f64 {
    let (mut s, mut c) = (0.0f64, 0.0f64);
    for &x in v {
        let t = s + x;
        c += if s.abs() >= x.abs() { (s - t) + x } else { (x - t) + s };
        s = t;
    }
    s + c
}

/// The overlapping variance by its definition: every start `k`, the cluster means of `m`
/// samples, their first (Allan, `/2`) or second (Hadamard, `/6`) difference squared, averaged.
fn definition(y: &[f64], m: usize, hadamard: bool) -> Option<(f64, usize)> {
    let span = if hadamard { 3 * m } else { 2 * m };
    if y.len() < span + 1 {
        return None;
    }
    let mean = |k: usize| csum(&y[k..k + m]) / m as f64;
    let mut d2 = Vec::new();
    for k in 0..=y.len() - span {
        let d = if hadamard { mean(k + 2 * m) - 2.0 * mean(k + m) + mean(k) } else { mean(k + m) - mean(k) };
        d2.push(d * d);
    }
    Some((csum(&d2) / if hadamard { 6.0 } else { 2.0 } / d2.len() as f64, d2.len()))
}

/// A static accelerometer's signal: 0.98 V offset, white noise, a random walk, a slow ramp.
fn signal(n: usize, seed: u64) -> Vec<f64> {
    use rand_distr::{Distribution, Normal};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let nrm = Normal::new(0.0, 1.0).unwrap();
    let mut rw = 0.0;
    (0..n)
        .map(|k| {
            rw += 3e-6 * nrm.sample(&mut rng);
            0.98 + 2e-9 * k as f64 + rw + 1e-4 * nrm.sample(&mut rng)
        })
        .collect()
}

#[test]
fn equals_the_definition_at_every_exact_tau() {
    let y = signal(30_000, 1);
    for (kind, hadamard) in [(Kind::Allan, false), (Kind::Hadamard, true)] {
        let mut e = Estimator::new(&Config { kind, grid: Grid::Octave, exact_max_m: EXACT_MAX_M });
        e.extend(&y);
        let (raw, _) = e.finish();
        let (mut seen, mut worst) = (0, 0.0f64);
        for m in (0..20).map(|k| 1usize << k) {
            let want = definition(&y, m, hadamard).filter(|w| w.1 >= 2);
            let got = raw.iter().find(|r| r.m == m);
            if m > EXACT_MAX_M {
                // Beyond the exact range: partially overlapping, said so.
                assert!(
                    got.is_none_or(|r| r.stride == m / PARTIAL_POSITIONS && r.stride > 1),
                    "{kind:?} m {m}: {got:?}"
                );
                continue;
            }
            match (want, got) {
                (Some((v, n)), Some(r)) => {
                    assert_eq!(r.stride, 1);
                    assert_eq!(r.n as usize, n, "{kind:?} m {m}");
                    worst = worst.max((r.var / v - 1.0).abs());
                    assert!((r.var - v).abs() <= 1e-9 * v, "{kind:?} m {m}: {} vs {v} ({:e})", r.var, r.var / v - 1.0);
                    seen += 1;
                }
                (None, None) => {}
                (w, g) => panic!("{kind:?} m {m}: definition {w:?}, estimator {g:?}"),
            }
        }
        println!("{kind:?}: {seen} exact octaves, largest relative difference from the definition {worst:.1e}");
        assert!(seen >= 12, "{seen}");
    }
    // Pooled over segments: each segment's terms, segments with fewer than two left out.
    let (a, b, c) = (&y[..9000], &y[9000..9040], &y[9040..]);
    let got = bins_cal::allan::pooled(Kind::Allan, &[a, b, c], &[1, 8, 16, 100, 4000]);
    for (m, v, n) in got {
        let parts: Vec<(f64, usize)> =
            [a, b, c].iter().filter_map(|s| definition(s, m, false)).filter(|p| p.1 >= 2).collect();
        let terms: usize = parts.iter().map(|p| p.1).sum();
        let want = parts.iter().map(|p| p.0 * p.1 as f64).sum::<f64>() / terms as f64;
        assert_eq!(n, terms, "m {m}");
        assert!((v - want).abs() <= 1e-9 * want, "pooled m {m}: {v} vs {want}");
    }
}

/// allantools 2024.06 (numpy 2.4.6, scipy 1.17.1): `oadev(y, rate, data_type="freq",
/// taus="octave")`, `(m, adev, n)`, of `ux_V` of `data/real/imucal-session.csv` (rate 102.4)
/// and `uz_V` of `data/real/tofupilot-sweep-real.csv` (rate 1; the deviation does not depend on
/// it).
const ALLANTOOLS_IMUCAL_UX: [(usize, f64, u64); 13] = [
    (1, 2.82768757125103909e-02, 10375),
    (2, 3.77627069685837549e-02, 10373),
    (4, 4.02483734381963651e-02, 10369),
    (8, 3.45108164113484342e-02, 10361),
    (16, 4.76807379808244017e-02, 10345),
    (32, 7.74407726474924396e-02, 10313),
    (64, 1.18756198365220222e-01, 10249),
    (128, 1.70839604369876830e-01, 10121),
    (256, 2.44754417000365848e-01, 9865),
    (512, 3.55398018644172198e-01, 9353),
    (1024, 4.83326875794632238e-01, 8329),
    (2048, 3.49145452447773064e-01, 6281),
    (4096, 3.59207354834769010e-01, 2185),
];
const ALLANTOOLS_TOFUPILOT_UZ: [(usize, f64, u64); 13] = [
    (1, 5.39744772541598606e-04, 8399),
    (2, 3.84738074975563113e-04, 8397),
    (4, 2.95142653343785297e-04, 8393),
    (8, 2.58918294462229086e-04, 8385),
    (16, 3.35888115826443062e-04, 8369),
    (32, 5.94049369772994265e-04, 8337),
    (64, 1.14822425907487092e-03, 8273),
    (128, 2.25355187739322308e-03, 8145),
    (256, 4.45361308301618977e-03, 7889),
    (512, 8.71591507521319447e-03, 7377),
    (1024, 1.52318834877336693e-02, 6353),
    (2048, 1.44157867239799106e-02, 4305),
    (4096, 1.32897537742988348e-02, 209),
];

#[test]
fn equals_allantools_oadev_on_the_real_recordings() {
    for (file, channel, want) in [
        ("data/real/imucal-session.csv", "ux_V", &ALLANTOOLS_IMUCAL_UX),
        ("data/real/tofupilot-sweep-real.csv", "uz_V", &ALLANTOOLS_TOFUPILOT_UZ),
    ] {
        let opt = pass::Options {
            channels: vec![channel.into()],
            from_s: None,
            to_s: None,
            held_only: false,
            config: Config::allan_octaves(),
            level: 0.95,
        };
        let a = pass::analyse(&common::repo(file), &opt).unwrap();
        assert_eq!(a.segments, 1, "{file}");
        let p = &a.channels[0].points;
        assert_eq!(p.len(), want.len(), "{file}");
        for (p, &(m, dev, n)) in p.iter().zip(want.iter()) {
            assert_eq!((p.m, p.n), (m, n), "{file}");
            assert!((p.dev - dev).abs() <= 1e-10 * dev, "{file} m {m}: {} vs {dev}", p.dev);
            // The interval holds the estimate.
            assert!(p.interval.0 < p.dev && p.dev < p.interval.1, "{file} m {m}: {:?}", p.interval);
        }
    }
}

#[test]
fn degrees_of_freedom_equal_allantools_and_quantiles_scipy() {
    // allantools 2024.06 `ci.edf_greenhall(alpha, d=2, m, N, overlapping=True)`:
    // (α, m, N, edf). Its α = +2 with few terms is not implemented there (ours: the exact sum).
    let want: [(i32, usize, usize, f64); 44] = [
        (2, 1, 1000, 5.13521769019248495e+02),
        (2, 4, 1000, 5.11231586238744001e+02),
        (2, 16, 1000, 5.02096689688020888e+02),
        (2, 64, 1000, 4.66048488150367803e+02),
        (2, 1, 100000, 5.14278073482990367e+04),
        (2, 1000, 100000, 5.06658851113716300e+04),
        (2, 8, 40, 1.48965517241379324e+01),
        (1, 1, 1000, 6.34830036470580808e+02),
        (1, 4, 1000, 3.88501167664116622e+02),
        (1, 16, 1000, 1.90424066336633672e+02),
        (1, 64, 1000, 7.60721128356181282e+01),
        (1, 256, 1000, 2.24997308057155969e+01),
        (1, 1, 100000, 6.35859169097241247e+04),
        (1, 1000, 100000, 1.20073515031135116e+03),
        (1, 30000, 100000, 5.31838230343558749e+01),
        (1, 8, 40, 8.14696489724069117e+00),
        (1, 3, 11, 3.17706806821462884e+00),
        (0, 1, 1000, 7.81247690430538569e+02),
        (0, 4, 1000, 3.05783930801036092e+02),
        (0, 16, 1000, 8.62817100528823033e+01),
        (0, 64, 1000, 2.12160714285714320e+01),
        (0, 256, 1000, 3.87456947150915720e+00),
        (0, 1, 100000, 7.82595085071488575e+04),
        (0, 1000, 100000, 1.47753846153846155e+02),
        (0, 30000, 100000, 3.15236427320490353e+00),
        (0, 8, 40, 4.82981366459627282e+00),
        (0, 3, 11, 2.75600195982361162e+00),
        (-1, 1, 1000, 8.94351406796213951e+02),
        (-1, 4, 1000, 2.82073851075257721e+02),
        (-1, 16, 1000, 7.12325503141255751e+01),
        (-1, 64, 1000, 1.65256264743846515e+01),
        (-1, 256, 1000, 2.89461289834510627e+00),
        (-1, 1, 100000, 8.95938481812430255e+04),
        (-1, 1000, 100000, 1.15542402040398940e+02),
        (-1, 30000, 100000, 2.24194887031572820e+00),
        (-1, 8, 40, 4.07320756223481339e+00),
        (-1, 3, 11, 2.47235619287236741e+00),
        (-2, 1, 1000, 7.61527618362907901e+02),
        (-2, 4, 1000, 2.26864025859356815e+02),
        (-2, 16, 1000, 5.63533221240476863e+01),
        (-2, 64, 1000, 1.29516338615294710e+01),
        (-2, 256, 1000, 2.15242507804055672e+00),
        (-2, 1000, 100000, 9.11420274451003252e+01),
        (-2, 3, 11, 1.88081631107744096e+00),
    ];
    for (alpha, m, n, nu) in want {
        let got = edf::greenhall(alpha, 2, m as f64, n as f64, true).unwrap();
        assert!((got - nu).abs() <= 1e-9 * nu, "α {alpha} m {m} N {n}: {got} vs {nu}");
    }
    assert_eq!(edf::greenhall(-3, 2, 4.0, 1000.0, true), None, "the Allan variance diverges for α = −3");
    // scipy 1.17.1 `chi2.ppf(0.025, ν)`, `chi2.ppf(0.975, ν)`.
    for (nu, lo, hi) in [
        (1.1, 1.97445568531410274e-03, 5.29176080894503453e+00),
        (3.2, 2.62116157394172322e-01, 9.71832217931260978e+00),
        (17.3, 7.76314034833618560e+00, 3.05926582829182401e+01),
        (148.7, 1.16832097446713433e+02, 1.84352832902205023e+02),
        (7915.0, 7.67030230690197095e+03, 8.16348623602185307e+03),
    ] {
        let (l, h) = (edf::chi2_quantile(0.025, nu), edf::chi2_quantile(0.975, nu));
        assert!((l - lo).abs() <= 1e-8 * lo && (h - hi).abs() <= 1e-8 * hi, "ν {nu}: {l} {h} vs {lo} {hi}");
        // The deviation's interval: the lower bound from the upper quantile (allantools #118).
        let (a, b) = edf::interval(1.0, nu, 0.95);
        assert!((a - (nu / hi).sqrt()).abs() < 1e-8 && (b - (nu / lo).sqrt()).abs() < 1e-7 * b);
    }
}

/// Three simulated units (the x, y, z axes of one, independent) through the simulator's noise
/// state, `n` samples at τ₀ = `tau0`.
fn simulate_axes(p: NoiseParams, n: usize, tau0: f64, seed: u64) -> [Vec<f64>; 3] {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut s = NoiseState::new(p, tau0);
    s.start(&mut rng);
    let mut out = [Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n)];
    for _ in 0..n {
        let mut u = [0.0; 3];
        s.apply_signals(&mut rng, &mut u);
        for i in 0..3 {
            out[i].push(u[i]);
        }
    }
    out
}

#[test]
fn noise_terms_of_simulated_units_are_recovered_and_intervals_cover_the_truth() {
    // Per sample τ₀ = 1 s: white 1 (N = 1 u·√s), Gauss–Markov 1 u with T = 10 s (its bump
    // stands 2.7× above the white noise's deviation at 19 s), random walk 0.1 u/√s (above
    // the rest from 80 s on). 10⁶ samples, 21 units (seven seeds, three axes).
    let truth = TwinNoise { white: 1.0, random_walk: 0.1, gm: [(1.0, 10.0), (0.0, 0.0)], adc_step: 0.0 };
    let p = NoiseParams {
        white_v: [truth.white; 3],
        random_walk_v_per_sqrt_s: [truth.random_walk; 3],
        bias_instability_v: [truth.gm[0].0; 3],
        bias_tau_s: [truth.gm[0].1; 3],
        ..NoiseParams::default()
    };
    let (mut covered, mut total) = (0, 0);
    let mut worst = [0.0f64; 3];
    for seed in 0..7u64 {
        for (axis, y) in simulate_axes(p, 1_000_000, 1.0, 100 + seed).iter().enumerate() {
            let unit = 3 * seed as usize + axis;
            let mut e = Estimator::new(&Config::allan_octaves());
            e.extend(y);
            let (raw, segs) = e.finish();
            let pts = points(&raw, &segs, Kind::Allan, 1.0, 0.95);
            for q in &pts {
                let true_dev = truth.avar(q.m as f64, 1.0).sqrt();
                total += 1;
                let inside = q.interval.0 <= true_dev && true_dev <= q.interval.1;
                covered += usize::from(inside);
                if !inside {
                    println!(
                        "  unit {unit} m {}: {:.4} [{:.4}, {:.4}] truth {true_dev:.4}, α {} ({:?}), edf {:?}",
                        q.m, q.dev, q.interval.0, q.interval.1, q.alpha, q.alpha_from, q.edf
                    );
                }
            }
            let fit: Vec<twin::FitPoint> =
                pts.iter().map(|q| (q.m as f64, q.dev * q.dev, q.edf.unwrap_or(f64::NAN))).collect();
            let t = twin::fit(&fit, 1.0, 0.0, 1);
            let rel =
                [t.white / truth.white - 1.0, t.random_walk / truth.random_walk - 1.0, t.gm[0].0 / truth.gm[0].0 - 1.0];
            for (w, r) in worst.iter_mut().zip(rel) {
                *w = w.max(r.abs());
            }
            println!("unit {unit}: white, random walk, Gauss–Markov relative errors {rel:.3?}");
            assert!(rel[0].abs() < 0.10 && rel[1].abs() < 0.10, "unit {unit}: white, random walk {rel:?} ({t:?})");
            assert!(rel[2].abs() < 0.30, "unit {unit}: Gauss–Markov {rel:?} ({t:?})");
        }
    }
    let coverage = covered as f64 / total as f64;
    println!(
        "worst relative error over 21 units: white {:.3}, random walk {:.3}, Gauss–Markov {:.3}; 95 % intervals cover the true curve at {covered}/{total} = {:.3} of the τ",
        worst[0], worst[1], worst[2], coverage
    );
    assert!(coverage >= 0.90, "{coverage}");
}

#[test]
fn ieee_white_noise_and_random_walk_are_recovered() {
    // White noise 2 u per sample at τ₀ = 0.5 s (N = 2·√0.5 u·√s) and a random walk of
    // 0.05 u/√s (above the white noise from 40 s on), 600 000 samples, 21 units: the IEEE fit's
    // N and K, and the intervals' coverage of the true curve.
    let (white, q, tau0) = (2.0, 0.05, 0.5);
    let p = NoiseParams { white_v: [white; 3], random_walk_v_per_sqrt_s: [q; 3], ..NoiseParams::default() };
    let truth = TwinNoise { white, random_walk: q, ..TwinNoise::default() };
    let (mut covered, mut total, mut worst) = (0, 0, [0.0f64; 2]);
    for seed in 0..7u64 {
        for (axis, y) in simulate_axes(p, 600_000, tau0, 500 + seed).iter().enumerate() {
            let unit = 3 * seed as usize + axis;
            let mut e = Estimator::new(&Config::allan_octaves());
            e.extend(y);
            let (raw, segs) = e.finish();
            let pts = points(&raw, &segs, Kind::Allan, tau0, 0.95);
            for q in &pts {
                let d = truth.avar(q.m as f64, tau0).sqrt();
                total += 1;
                covered += usize::from(q.interval.0 <= d && d <= q.interval.1);
            }
            let fit: Vec<(f64, f64, f64)> =
                pts.iter().map(|q| (q.tau_s, q.dev * q.dev, q.edf.unwrap_or(f64::NAN))).collect();
            let t = terms::fit(&fit);
            let rel = [t.n / (white * tau0.sqrt()) - 1.0, t.k / q - 1.0];
            worst = [worst[0].max(rel[0].abs()), worst[1].max(rel[1].abs())];
            assert!(rel[0].abs() < 0.10 && rel[1].abs() < 0.10, "unit {unit}: N, K {rel:?} ({t:?})");
        }
    }
    let coverage = covered as f64 / total as f64;
    println!(
        "IEEE fit, worst over 21 units: N {:.3}, K {:.3}; coverage {covered}/{total} = {coverage:.3}",
        worst[0], worst[1]
    );
    assert!(coverage >= 0.90, "{coverage}");
}

#[test]
fn the_noise_model_is_the_estimators_expectation() {
    // The closed forms of the twin's terms against the definition on long simulated series:
    // the Gauss–Markov form at m = 4 and 64 (T = 20 samples) and the random walk's at m = 16.
    for (p, ms) in [
        (NoiseParams { bias_instability_v: [1.0; 3], bias_tau_s: [20.0; 3], ..NoiseParams::default() }, [4, 64]),
        (NoiseParams { random_walk_v_per_sqrt_s: [1.0; 3], ..NoiseParams::default() }, [16, 16]),
    ] {
        let [y, _, _] = simulate_axes(p, 2_000_000, 1.0, 5);
        for m in ms {
            let (v, n) = definition(&y, m, false).unwrap();
            let model = if p.random_walk_v_per_sqrt_s[0] > 0.0 {
                twin::rw_avar(m as f64, 1.0)
            } else {
                twin::gm_avar(m as f64, 1.0, 20.0)
            };
            // Sampling error of a variance with ~n/m independent terms.
            let tol = 5.0 * (2.0 * m as f64 / n as f64).sqrt() * if m > 10 { 3.0 } else { 1.0 };
            assert!((v / model - 1.0).abs() < tol, "m {m}: {v} vs {model} (tol {tol})");
        }
    }
}

fn write_static_scenario(dir: &Path, name: &str, noise: &str, seconds: f64, rate: f64) -> std::path::PathBuf {
    let text = format!(
        "[recording]\nrate_Hz = {rate}\nlog_chamber = false\n[unit]\npreset = \"paper\"\nfit = \"poly\"\norder = 2\n[thermal]\nstart_C = 20.0\n[noise]\n{noise}\n[[step]]\nkind = \"soak\"\nchamber_C = 20.0\ndwell_s = {seconds}\n"
    );
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

type Curve = Vec<(f64, f64, f64, f64)>;

/// The octave points of a recording (its holds only with `held`): per channel
/// `(τ, dev, lower, upper)`.
fn curves(path: &Path, held: bool) -> Vec<Curve> {
    let opt = pass::Options {
        channels: vec!["ux_V".into(), "uy_V".into(), "uz_V".into()],
        from_s: None,
        to_s: None,
        held_only: held,
        config: Config::allan_octaves(),
        level: 0.95,
    };
    let a = pass::analyse(path, &opt).unwrap();
    a.channels.iter().map(|c| c.points.iter().map(|p| (p.tau_s, p.dev, p.interval.0, p.interval.1)).collect()).collect()
}

/// The fraction of τ at which the twin's deviation is within 20 % of the recording's or
/// inside the recording's interval, per axis.
fn agreement(a: &[Curve], b: &[Curve]) -> Vec<(usize, usize)> {
    a.iter()
        .zip(b)
        .map(|(ca, cb)| {
            let n = ca.len().min(cb.len());
            let ok = (0..n)
                .filter(|&i| {
                    let (r, t) = (ca[i], cb[i]);
                    (t.1 / r.1 - 1.0).abs() <= 0.2 || (r.2 <= t.1 && t.1 <= r.3)
                })
                .count();
            (ok, n)
        })
        .collect()
}

#[test]
fn the_twin_from_noise_toml_follows_the_recording() {
    // A unit whose axes differ and whose bias wanders on two time scales, as a real one's does.
    let dir = tempfile::tempdir().unwrap();
    let unit = write_static_scenario(
        dir.path(),
        "unit.toml",
        "white_V = [4.0e-4, 3.0e-4, 5.0e-4]\nrandom_walk_V_per_sqrt_s = [2.0e-6, 1.0e-6, 3.0e-6]\nbias_instability_V = [6.0e-5, 4.0e-5, 8.0e-5]\nbias_tau_s = [2.0, 3.0, 1.5]\nbias_instability2_V = [5.0e-5, 8.0e-5, 3.0e-5]\nbias_tau2_s = [60.0, 40.0, 90.0]\nadc_lsb_V = 1.0e-6",
        2000.0,
        100.0,
    );
    let rec = dir.path().join("rec.csv");
    let twin_toml = dir.path().join("twin.toml");
    let twin_csv = dir.path().join("twin.csv");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    common::ok(&["simulate", &s(&unit), "-o", &s(&rec), "--seed", "3", "--quiet"]);
    let out = common::ok(&["allan", &s(&rec), "--noise-toml", &s(&twin_toml)]);
    assert!(out.contains("fitted noise"), "{out}");
    let long = longer(&twin_toml, 4.0);
    common::ok(&["simulate", &s(&long), "-o", &s(&twin_csv), "--seed", "11", "--quiet"]);
    for (axis, (ok, n)) in agreement(&curves(&rec, false), &curves(&twin_csv, false)).into_iter().enumerate() {
        println!("simulated unit, axis {axis}: the twin within 20 % or inside the interval at {ok}/{n} octave τ");
        assert!(n >= 15 && ok as f64 >= 0.9 * n as f64, "axis {axis}: {ok}/{n}");
    }
}

/// The twin scenario `path` with its hold `factor` times as long (its curve then scatters
/// less about the model than the recording's about the unit's), as `path`.long.toml.
fn longer(path: &Path, factor: f64) -> std::path::PathBuf {
    let text = std::fs::read_to_string(path).unwrap();
    let out: Vec<String> = text
        .lines()
        .map(|l| match l.strip_prefix("dwell_s = ") {
            Some(v) => format!("dwell_s = {}", v.trim().parse::<f64>().unwrap() * factor),
            None => l.to_string(),
        })
        .collect();
    let p = path.with_extension("long.toml");
    std::fs::write(&p, out.join("\n") + "\n").unwrap();
    p
}

#[test]
fn the_twin_of_a_real_unit_at_rest_follows_it() {
    // The six holds of the real session (`data/real/imucal-session.csv`, a MEMS IMU put down by
    // hand, 4–7 s each at 102.4 Hz; `--held` keeps the rows with a known reference, each hold a
    // segment): its curve against the twin fitted to it, simulated four times as long.
    let dir = tempfile::tempdir().unwrap();
    let rec = common::repo("data/real/imucal-session.csv");
    let twin_toml = dir.path().join("twin.toml");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    common::ok(&["allan", &s(&rec), "--held", "--channels", "ux_V,uy_V,uz_V", "--noise-toml", &s(&twin_toml)]);
    let twin_csv = dir.path().join("twin.csv");
    common::ok(&["simulate", &s(&longer(&twin_toml, 4.0)), "-o", &s(&twin_csv), "--seed", "1", "--quiet"]);
    for (axis, (ok, n)) in agreement(&curves(&rec, true), &curves(&twin_csv, false)).into_iter().enumerate() {
        println!("real holds, axis {axis}: the twin within 20 % or inside the interval at {ok}/{n} octave τ");
        assert!(n >= 8 && ok as f64 >= 0.9 * n as f64, "axis {axis}: {ok}/{n}");
    }
}

#[test]
fn the_command_writes_its_outputs_or_none() {
    let dir = tempfile::tempdir().unwrap();
    let scen =
        write_static_scenario(dir.path(), "s.toml", "white_V = 1.0e-4\nrandom_walk_V_per_sqrt_s = 1.0e-6", 60.0, 50.0);
    let rec = dir.path().join("rec.csv");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    common::ok(&["simulate", &s(&scen), "-o", &s(&rec), "--seed", "1", "--quiet"]);
    let (json, csv, png, toml, yaml) = (
        dir.path().join("a.json"),
        dir.path().join("a.csv"),
        dir.path().join("a.png"),
        dir.path().join("t.toml"),
        dir.path().join("imu.yaml"),
    );
    // The imu.yaml needs g: refused without a scale factor, and nothing else is written.
    let e = common::err(&["allan", &s(&rec), "--json", &s(&json), "--imu-yaml", &s(&yaml)]);
    assert!(e.contains("--scale-v-per-g"), "{e}");
    assert!(!json.exists() && !yaml.exists());
    let out = common::ok(&[
        "allan",
        &s(&rec),
        "--scale-v-per-g",
        "0.5",
        "--per-decade",
        "5",
        "--json",
        &s(&json),
        "--csv",
        &s(&csv),
        "--plot",
        &s(&png),
        "--noise-toml",
        &s(&toml),
        "--imu-yaml",
        &s(&yaml),
    ]);
    assert!(out.contains("velocity random walk [µg/√Hz]"), "{out}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let ch = &v["channels"][0];
    assert_eq!(ch["name"], "ux_V");
    assert_eq!(ch["unit"], "g");
    // 1e-4 V at 50 Hz through 0.5 V/g: N = 2e-4 g · √0.02 s = 28.3 µg/√Hz.
    let n = ch["terms"]["velocity_random_walk_ug_per_sqrt_Hz"].as_f64().unwrap();
    assert!((n / 28.28 - 1.0).abs() < 0.1, "{n}");
    assert!(ch["points"].as_array().unwrap().len() > 10);
    assert!(std::fs::read_to_string(&csv).unwrap().starts_with("channel,unit,tau_s,m,adev,lower,upper"));
    assert_eq!(&std::fs::read(&png).unwrap()[1..4], b"PNG");
    let y = std::fs::read_to_string(&yaml).unwrap();
    assert!(y.contains("accelerometer_noise_density:") && y.contains("update_rate: 50"), "{y}");
    // The twin scenario builds.
    bins_cal::sim::scenario::load(&toml).unwrap();
    // Bad input: an unknown channel, a range with no rows.
    assert!(common::err(&["allan", &s(&rec), "--channels", "ux_V,fx_g"]).contains("not one of"));
    assert!(common::err(&["allan", &s(&rec), "--from", "100"]).contains("time range"));
}
