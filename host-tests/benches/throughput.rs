//! Host samples per second of the per-sample step (`Pipeline::step` in `f32`, the code the
//! firmware runs), for the same method/model cases as the firmware's instruction benchmark:
//! `cargo xtask bench` (or `cargo bench -p host-tests --bench throughput`). Each iteration
//! steps through a batch of [`BATCH`] precomputed inputs whose temperature reading changes
//! every [`TEMP_EVERY`] samples (or every sample in the "every sample" cases).

use bins_comp::pipeline::VibrationSource;
use bins_comp::replay::WINDOW;
use bins_comp::{Calibration, Form, Method, Pipeline, PipelineState, TempModel, Variant, VibrationConfig, paper};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;

/// Samples per iteration.
const BATCH: usize = 4096;
/// Samples per temperature reading (a TMP117 at 64 Hz against a 1 kHz sample rate).
const TEMP_EVERY: usize = 16;

fn inputs(temp_every: usize) -> Vec<([f32; 3], f32)> {
    (0..BATCH)
        .map(|i| {
            let k = i as f32;
            let u = [0.3 * (k * 0.37).sin(), -0.2 + 0.01 * (k * 1.3).cos(), -0.55 + 0.02 * (k * 0.71).sin()];
            let t = -17.0 + ((i / temp_every) % 97) as f32 * 0.37;
            (u, t)
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let poly3 = paper::order3_model().expect("order-3 model of the paper's unit");
    let pwl = paper::two_range_model().expect("two-range model of the paper's unit");
    let cal = |m: TempModel<f64>, method: Method| -> Calibration<f32> {
        paper::calibration(m, method).expect("paper calibration")
    };
    let vib = bins_comp::vectors::vibration_config::<f32>(Variant::Exact);
    let m1 = Method::CoefficientCorrection;
    let m2s = Method::OutputCorrection(Form::Simplified);
    let (online, none) = (VibrationSource::Online, VibrationSource::None);
    let cases = [
        ("poly3 method 1 + online VE", cal(poly3, m1), online, TEMP_EVERY),
        ("poly3 method 1", cal(poly3, m1), none, TEMP_EVERY),
        ("poly3 method 1, new temperature every sample", cal(poly3, m1), none, 1),
        ("pwl method 2 simplified", cal(pwl, m2s), none, TEMP_EVERY),
        ("pwl method 2 simplified + online VE", cal(pwl, m2s), online, TEMP_EVERY),
    ];
    let mut g = c.benchmark_group("step_f32");
    g.throughput(Throughput::Elements(BATCH as u64));
    for (name, cal, source, temp_every) in cases {
        let p = Pipeline::new(cal, if source == online { vib } else { VibrationConfig::none() });
        let mut st = PipelineState::<f32, WINDOW>::new();
        let inp = inputs(temp_every);
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut acc = 0.0f32;
                for (u, t) in black_box(&inp) {
                    let s = p.step(&mut st, *u, *t, source);
                    acc += s.accel_g[0] + s.accel_g[1] + s.accel_g[2];
                }
                acc
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
