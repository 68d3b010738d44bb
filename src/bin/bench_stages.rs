//! Benchmark firmware: the stages of the per-sample step timed one by one in QEMU (run by
//! `cargo xtask bench` after the `bench` image), so that every change is measured against its
//! own stage.
//!
//! Each stage is its own function of the core, called here [`N`](benchkit::N) times in a loop
//! and compared with the same loop reading the same inputs without it
//! ([`benchkit`]: one SysTick count is 40 instructions): instructions per call. The stages,
//! in the order the sampling interrupt runs them:
//!
//! | stage | what is timed |
//! |---|---|
//! | read and check | the sample taken from the interrupt's input queue (the replay image's source: an SPSC dequeue) and its signals checked finite |
//! | temperature path | the temperature cache's lookup of a reading it holds ([`TempCache::get`]) |
//! | constants at temperature | the lookup of a new reading, less the above: the constants recomputed ([`Calibration::at_temperature`]); per reading and per sample at one reading every 16 |
//! | T(1) | the signals to acceleration with those terms ([`Calibration::apply`]) |
//! | VE | the online VE per sample: the window, the block's shares, the subtraction ([`Pipeline::subtract_ve`]) |
//! | dynamics | the thermal dynamics' own step, every stage on ([`FixedRate::step`]); the step adds the rounding of T_eff and the bias play (the `bench` image's "+dynamics") |
//! | status | what the interrupt's step adds to the pipeline's (the input's flags, the overrun flag: [`Tick::step`]) |
//! | output | the result into the interrupt's output queue (an SPSC enqueue) |
//!
//! Timed for the `bench` image's first case (order-3 polynomial, method 1, online VE) and for
//! the piecewise model with method 2 simplified and without correction. A stage called in
//! a loop of its own is compiled apart from the rest of the step, so the stages need not add
//! up to the step exactly.
#![no_std]
#![no_main]
#![allow(unsafe_code, reason = "the queues' statics, the Cortex-M runtime's entry")]

// The timing shared with the `bench` image; its loop against the plain input read is not used
// here (each stage has its own baseline).
#[allow(dead_code)]
mod benchkit;
mod interrupts;

use benchkit::{N, TEMP_EVERY, UNIT_DYNAMICS, cal, input, per_call_x100, run, start_systick};
use bins_comp::pipeline::VibrationSource;
use bins_comp::replay::{Input, Tick, WINDOW};
use bins_comp::{
    Calibration, DynamicsState, Form, Method, Pipeline, PipelineState, Sample, Status, TempCache, TempModel,
    VibrationConfig, paper,
};
use cortex_m::peripheral::SYST;
use cortex_m_rt::entry;
use defmt_semihosting as _;
use heapless::spsc::Queue;

/// Inputs queued for the read's measurement.
static mut IN_QUEUE: Queue<Input<f32>, 64> = Queue::new();
/// Results queued by the output's measurement.
static mut OUT_QUEUE: Queue<Sample<f32>, 64> = Queue::new();
/// Calls per batch of the queue measurements (the queue holds 63).
const BATCH: u32 = 32;

/// Logs a stage: instructions per call ×100.
fn log_stage(case: &str, stage: &str, x100: u32) {
    defmt::info!("STAGE {=str}: {=str}: {=u32}.{=u32:02} instructions", case, stage, x100 / 100, x100 % 100);
}

/// SysTick counts of `f` minus those of `g`, each called [`N`] times.
fn counts_vs(syst: &mut SYST, mut f: impl FnMut(u32) -> f32, mut g: impl FnMut(u32) -> f32) -> u32 {
    run(syst, &mut |i| f(i)).saturating_sub(run(syst, &mut |i| g(i)))
}

/// SysTick counts of `f` called [`N`] times in batches of [`BATCH`], each batch after `setup`
/// (not timed), minus the same for `g`.
fn batched_vs(
    syst: &mut SYST,
    mut setup: impl FnMut(),
    mut f: impl FnMut(u32) -> f32,
    mut g: impl FnMut(u32) -> f32,
) -> u32 {
    let batches = |syst: &mut SYST, h: &mut dyn FnMut(u32) -> f32, setup: &mut dyn FnMut()| {
        let mut total = 0u32;
        let mut k = 0;
        while k < N {
            setup();
            syst.clear_current();
            let t0 = SYST::get_current();
            let mut acc = 0.0f32;
            for j in 0..BATCH {
                acc += h(k + j);
            }
            let t1 = SYST::get_current();
            core::hint::black_box(acc);
            total += t0.wrapping_sub(t1) & 0x00FF_FFFF;
            k += BATCH;
        }
        total
    };
    let full = batches(syst, &mut |i| f(i), &mut setup);
    let empty = batches(syst, &mut |i| g(i), &mut setup);
    full.saturating_sub(empty)
}

/// The sum of an input's numbers: what a baseline loop computes from the inputs it reads.
fn sum(i: &Input<f32>) -> f32 {
    i.u_v[0] + i.u_v[1] + i.u_v[2] + i.temp_c
}

/// The stages of the step with calibration `cal` and VE source `source` (module docs).
#[inline(never)]
fn stages(syst: &mut SYST, name: &str, cal: Calibration<f32>, source: VibrationSource) {
    let vib = bins_comp::vectors::vibration_config::<f32>(bins_comp::Variant::Exact);
    let pipeline = Pipeline::new(cal, if source == VibrationSource::None { VibrationConfig::none() } else { vib });

    // SAFETY: the only references ever taken to the two queues (this function runs once per
    // case, one case after the other, and the halves are dropped before it returns);
    // single-threaded, no interrupts in this program.
    let (Some(inq), Some(outq)) = (unsafe { (&raw mut IN_QUEUE).as_mut() }, unsafe { (&raw mut OUT_QUEUE).as_mut() })
    else {
        return;
    };
    let (mut in_p, mut in_c) = inq.split();
    let x = batched_vs(
        syst,
        // Each timed batch takes what its setup queued (the baseline's leave it full).
        || {
            for k in 0..BATCH {
                let _ = in_p.enqueue(input(k, TEMP_EVERY));
            }
        },
        |_| match in_c.dequeue() {
            Some(inp) if inp.u_v.iter().all(|u| u.is_finite()) => inp.temp_c,
            _ => 0.0,
        },
        |k| core::hint::black_box(k as f32),
    );
    log_stage(name, "read and check", per_call_x100(x));

    // One reading throughout, passed through `black_box` so that it is not known constant.
    let mut cache = TempCache::new();
    let hit = counts_vs(
        syst,
        |k| cache.get(&cal, core::hint::black_box(input(k, u32::MAX).temp_c)).status().0 as f32,
        |k| core::hint::black_box(input(k, u32::MAX).temp_c),
    );
    log_stage(name, "temperature path", per_call_x100(hit));
    let mut cache = TempCache::new();
    let each = counts_vs(
        syst,
        |k| cache.get(&cal, input(k, 1).temp_c).status().0 as f32,
        |k| core::hint::black_box(input(k, 1).temp_c),
    );
    let new = per_call_x100(each.saturating_sub(hit));
    log_stage(name, "constants at temperature, per new reading", new);
    log_stage(name, "constants at temperature, per sample (a reading every 16)", new / TEMP_EVERY);

    let at = core::hint::black_box(cal.at_temperature(25.0));
    let x = counts_vs(
        syst,
        |k| {
            let s = cal.apply(input(k, TEMP_EVERY).u_v, &at);
            s.accel_g[0] + s.accel_g[1] + s.accel_g[2] + s.status.0 as f32
        },
        |k| sum(&input(k, TEMP_EVERY)),
    );
    log_stage(name, "T(1)", per_call_x100(x));

    if source == VibrationSource::Online {
        let mut state = PipelineState::<f32, WINDOW>::new();
        let mut ve = |k: u32| {
            let s = Sample { accel_g: input(k, TEMP_EVERY).u_v, status: Status::OK };
            let (s, _) = pipeline.subtract_ve(&mut state, s, source);
            s.accel_g[0] + s.accel_g[1] + s.accel_g[2] + s.status.0 as f32
        };
        // A complete block first, so the VE takes its full path.
        for k in 0..WINDOW as u32 {
            ve(k);
        }
        let x = counts_vs(syst, ve, |k| sum(&input(k, TEMP_EVERY)) + core::hint::black_box(0) as f32);
        log_stage(name, "VE", per_call_x100(x));
    }

    if let Ok(rate) = UNIT_DYNAMICS.at_rate(1.0e-3) {
        let mut ds = DynamicsState::new();
        let x = counts_vs(
            syst,
            |k| {
                let e = rate.step(&mut ds, input(k, TEMP_EVERY).temp_c);
                e.temp_eff_c + e.bias_play
            },
            |k| core::hint::black_box(input(k, TEMP_EVERY).temp_c),
        );
        log_stage(name, "dynamics (its own step)", per_call_x100(x));
    }

    // The interrupt's step over the pipeline's, both through the same state kind.
    let mut t = Tick::<f32, WINDOW>::new(pipeline);
    let mut state = PipelineState::<f32, WINDOW>::new();
    let tick = run(syst, &mut |k| {
        let s = t.step(&input(k, TEMP_EVERY), source);
        s.accel_g[0] + s.status.0 as f32
    });
    let plain = run(syst, &mut |k| {
        let inp = input(k, TEMP_EVERY);
        let s = pipeline.step(&mut state, inp.u_v, inp.temp_c, source);
        s.accel_g[0] + s.status.0 as f32
    });
    log_stage(name, "status", per_call_x100(tick.saturating_sub(plain)));

    let (mut out_p, mut out_c) = outq.split();
    let x = batched_vs(
        syst,
        || while out_c.dequeue().is_some() {},
        |k| {
            let inp = input(k, TEMP_EVERY);
            out_p.enqueue(Sample { accel_g: inp.u_v, status: Status::OK }).is_ok() as u32 as f32 + inp.temp_c
        },
        |k| {
            let inp = input(k, TEMP_EVERY);
            core::hint::black_box(inp.u_v);
            inp.temp_c
        },
    );
    log_stage(name, "output", per_call_x100(x));
}

#[entry]
fn main() -> ! {
    let Some(mut cp) = cortex_m::Peripherals::take() else { semihosting::process::exit(1) };
    let syst = &mut cp.SYST;
    start_systick(syst);
    let poly3 =
        paper::order3_model().unwrap_or(TempModel::Poly { order: 1, coef: [bins_comp::CoefDelta::default(); 4] });
    let pwl = paper::two_range_model().unwrap_or(poly3);
    let cases = [
        ("poly3 method 1 + online VE", cal(poly3, Method::CoefficientCorrection), VibrationSource::Online),
        ("pwl method 2 simplified", cal(pwl, Method::OutputCorrection(Form::Simplified)), VibrationSource::None),
        ("pwl uncorrected", cal(pwl, Method::Uncorrected), VibrationSource::None),
    ];
    for (name, c, source) in cases {
        if !c.is_valid() {
            defmt::error!("case {=str}: calibration did not build", name);
            semihosting::process::exit(1)
        }
        stages(syst, name, c, source);
    }
    semihosting::process::exit(0)
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    semihosting::process::exit(1)
}
