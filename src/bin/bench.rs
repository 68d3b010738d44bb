//! Benchmark firmware: instructions per sample of the per-sample step in QEMU, and the stack
//! depth of the sampling interrupt's body.
//!
//! Run by `cargo xtask bench` under `-icount shift=0` (one instruction per ns). SysTick counts
//! the 25 MHz core clock, so one count is 40 instructions; each case runs [`N`] steps over
//! varying inputs read with `read_volatile`, minus the same loop without the step: the mean
//! per sample. The temperature reading changes every [`TEMP_EVERY`] samples, as a TMP117 at
//! its fastest conversion cycle (15.5 ms) does at 1 kHz, or, in the "every sample" cases, on
//! every sample. The worst single step (a new temperature on a step that carries the online
//! VE's work: the one completing a block and the three after it) is timed alone over
//! [`WORST_REPS`] blocks, and the largest kept. The stack is
//! painted below the current stack pointer before the heaviest case and scanned after it.
#![no_std]
#![no_main]
#![allow(unsafe_code, reason = "volatile inputs, the painted stack read by address, the Cortex-M runtime's entry")]

mod interrupts;

use bins_comp::pipeline::VibrationSource;
use bins_comp::replay::{Input, SOURCE, Tick, WINDOW};
use bins_comp::{
    Calibration, FixedRate, Form, Method, Pipeline, Status, TempModel, ThermalDynamics, VibrationConfig, paper,
};
use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m_rt::entry;
use defmt_semihosting as _;

/// Steps per case (a multiple of the online block, so block completions are averaged
/// exactly).
const N: u32 = 2048;
/// Samples per temperature reading in the normal cases.
const TEMP_EVERY: u32 = 16;
/// Worst-case steps timed.
const WORST_REPS: u32 = 16;
/// Instructions per SysTick count (`-icount shift=0`, 25 MHz SysTick).
const INSNS_PER_COUNT: u32 = 40;
/// Bytes painted below the stack pointer.
const PAINT_BYTES: usize = 4096;
/// The paint pattern.
const PAINT: u32 = 0xDEAD_BEEF;

/// Inputs cycled through by the cases (read volatile).
static mut INPUTS: [[f32; 4]; 8] = [
    [0.02, -0.005, -0.55, 19.9],
    [0.51, 0.08, -0.46, 41.7],
    [-0.3, 0.2, -0.5, -12.5],
    [0.1, -0.2, 0.55, 45.0],
    [1.2, 0.01, -0.28, 65.3],
    [-0.9, 0.4, 0.1, 3.2],
    [0.0, 0.0, -0.55, 20.0],
    [0.3, -0.3, 0.3, -35.0],
];

/// Input `i` with a new temperature reading every `temp_every` samples.
fn input(i: u32, temp_every: u32) -> Input<f32> {
    // SAFETY: `INPUTS` is a valid, aligned static; nothing writes it and there are no
    // interrupts in this program. Volatile so the inputs are not constant-folded.
    let a = unsafe { core::ptr::read_volatile(&raw const INPUTS) };
    let r = a.get((i % 8) as usize).copied().unwrap_or_default();
    let reading = i / temp_every.max(1);
    let t = 20.0 + (reading % 97) as f32 * 0.37 - 17.0;
    Input { u_v: [r[0], r[1], r[2]], temp_c: t, status: Status::OK }
}

/// SysTick counts spent by `f` over `N` calls, minus the empty loop's.
fn counts(syst: &mut SYST, mut f: impl FnMut(u32) -> f32) -> u32 {
    let mut run = |g: &mut dyn FnMut(u32) -> f32| {
        syst.clear_current();
        let t0 = SYST::get_current();
        let mut acc = 0.0f32;
        for i in 0..N {
            acc += g(i);
        }
        let t1 = SYST::get_current();
        core::hint::black_box(acc);
        t0.wrapping_sub(t1) & 0x00FF_FFFF
    };
    let full = run(&mut |i| f(i));
    let empty = run(&mut |i| core::hint::black_box(input(i, TEMP_EVERY)).temp_c);
    full.saturating_sub(empty)
}

/// Instructions per sample ×100.
fn per_sample_x100(c: u32) -> u32 {
    (c as u64 * INSNS_PER_COUNT as u64 * 100 / N as u64) as u32
}

fn cal(model: TempModel<f64>, method: Method) -> Calibration<f32> {
    paper::calibration::<f32>(model, method).unwrap_or(Calibration::uncalibrated())
}

#[inline(never)]
fn step<const W: usize>(t: &mut Tick<f32, W>, i: u32, temp_every: u32, source: VibrationSource) -> f32 {
    let inp = input(i, temp_every);
    let s = t.pipeline.step(&mut t.state, inp.u_v, inp.temp_c, source);
    s.accel_g[0] + s.accel_g[1] + s.accel_g[2]
}

/// SysTick counts of the worst single step among those that carry the online VE's work (the
/// step that completes a block and the three after it, each with a new temperature reading),
/// minus the same measurement around nothing; the largest over [`WORST_REPS`] blocks.
fn worst_counts<const W: usize>(syst: &mut SYST, t: &mut Tick<f32, W>) -> u32 {
    let mut worst = 0;
    let mut i = 0u32;
    for _ in 0..WORST_REPS {
        // Up to the sample before a block completes, at one temperature.
        while !(i + 1).is_multiple_of(W as u32) {
            step(t, i, u32::MAX, SOURCE);
            i += 1;
        }
        for _ in 0..4 {
            syst.clear_current();
            let t0 = SYST::get_current();
            let acc = step(t, i ^ 0x5A5A, 1, SOURCE);
            let t1 = SYST::get_current();
            core::hint::black_box(acc);
            syst.clear_current();
            let e0 = SYST::get_current();
            let e1 = SYST::get_current();
            let dt = (t0.wrapping_sub(t1) & 0x00FF_FFFF).saturating_sub(e0.wrapping_sub(e1) & 0x00FF_FFFF);
            worst = worst.max(dt);
            i += 1;
        }
    }
    worst
}

#[entry]
fn main() -> ! {
    let Some(mut cp) = cortex_m::Peripherals::take() else { semihosting::process::exit(1) };
    let syst = &mut cp.SYST;
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(0x00FF_FFFF);
    syst.clear_current();
    syst.enable_counter();

    let poly3 =
        paper::order3_model().unwrap_or(TempModel::Poly { order: 1, coef: [bins_comp::CoefDelta::default(); 4] });
    let pwl = paper::two_range_model().unwrap_or(poly3);
    let vib = bins_comp::vectors::vibration_config::<f32>(bins_comp::Variant::Exact);
    let m1 = Method::CoefficientCorrection;
    let m2s = Method::OutputCorrection(Form::Simplified);
    let online = VibrationSource::Online;
    let none = VibrationSource::None;
    let profile = VibrationSource::Profile(0);
    // Thermal dynamics with every stage on (a die a minute behind the thermistor), and the
    // same without the lag, whose effective temperature follows each new reading at once: the
    // temperature terms are then recomputed as often as without dynamics.
    let unit = ThermalDynamics {
        lag_tau_s: 60.0f32,
        hysteresis_width_c: 0.3,
        self_heating_c: 1.5,
        self_heating_tau_s: 300.0,
        bias_play_width_c: 0.5,
        bias_play_g: [20e-6, -15e-6, 10e-6],
    };
    let full = unit.at_rate(1.0e-3).ok();
    let no_lag = ThermalDynamics { lag_tau_s: 0.0, ..unit }.at_rate(1.0e-3).ok();
    type Case<'a> = (&'a str, Calibration<f32>, VibrationSource, u32, Option<FixedRate<f32>>);
    let cases: [Case; 17] = [
        ("poly3 method 1 + online VE", cal(poly3, m1), online, TEMP_EVERY, None),
        ("poly3 method 1 + flight-profile VE", cal(poly3, m1), profile, TEMP_EVERY, None),
        ("poly3 method 1", cal(poly3, m1), none, TEMP_EVERY, None),
        ("poly3 method 1, new temperature every sample", cal(poly3, m1), none, 1, None),
        ("pwl method 1", cal(pwl, m1), none, TEMP_EVERY, None),
        ("pwl method 2 simplified", cal(pwl, m2s), none, TEMP_EVERY, None),
        ("pwl method 2 simplified, new temperature every sample", cal(pwl, m2s), none, 1, None),
        ("pwl method 2 simplified + online VE", cal(pwl, m2s), online, TEMP_EVERY, None),
        ("pwl uncorrected", cal(pwl, Method::Uncorrected), none, TEMP_EVERY, None),
        ("poly3 method 1 + online VE + dynamics", cal(poly3, m1), online, TEMP_EVERY, full),
        ("poly3 method 1 + online VE + dynamics without lag", cal(poly3, m1), online, TEMP_EVERY, no_lag),
        ("poly3 method 1 + dynamics", cal(poly3, m1), none, TEMP_EVERY, full),
        ("poly3 method 1 + dynamics without lag", cal(poly3, m1), none, TEMP_EVERY, no_lag),
        ("pwl method 2 simplified + dynamics", cal(pwl, m2s), none, TEMP_EVERY, full),
        ("pwl method 2 simplified + dynamics without lag", cal(pwl, m2s), none, TEMP_EVERY, no_lag),
        ("pwl method 2 simplified + online VE + dynamics", cal(pwl, m2s), online, TEMP_EVERY, full),
        (
            "pwl method 2 simplified + dynamics without lag, new temperature every sample",
            cal(pwl, m2s),
            none,
            1,
            no_lag,
        ),
    ];
    for (i, (name, c, source, temp_every, dynamics)) in cases.iter().enumerate() {
        if !c.is_valid() {
            defmt::error!("case {=str}: calibration did not build", name);
        }
        let mut p = if *source != none { Pipeline::new(*c, vib) } else { Pipeline::new(*c, VibrationConfig::none()) };
        if let Some(d) = dynamics {
            p = p.with_dynamics(*d);
        } else if i >= 9 {
            defmt::error!("case {=str}: thermal dynamics did not build", name);
        }
        let mut t = Tick::<f32, WINDOW>::new(p);
        // Complete a block so the VE cases take their full path.
        for k in 0..WINDOW as u32 {
            step(&mut t, k, *temp_every, *source);
        }
        if i == 0 {
            paint();
        }
        let c = counts(syst, |k| step(&mut t, k, *temp_every, *source));
        let x = per_sample_x100(c);
        defmt::info!("BENCH {=str}: {=u32}.{=u32:02} instructions/sample", name, x / 100, x % 100);
        if i == 0 {
            defmt::info!("STACK step high-water: {=u32} bytes below main's frame", high_water());
        }
        if i == 0 || i == 9 || i == 10 {
            let w = worst_counts(syst, &mut t) * INSNS_PER_COUNT;
            defmt::info!("WORST {=str}: {=u32} instructions (one step, ±{=u32})", name, w, INSNS_PER_COUNT);
        }
    }
    semihosting::process::exit(0)
}

static mut PAINT_TOP: usize = 0;

/// Paints [`PAINT_BYTES`] below the current stack pointer.
#[inline(never)]
fn paint() {
    let sp = cortex_m::register::msp::read() as usize & !3;
    let top = sp - 64;
    for a in (top - PAINT_BYTES..top).step_by(4) {
        // SAFETY: unused stack below this frame (nothing runs concurrently: no interrupts);
        // aligned, inside the 4 MiB RAM.
        unsafe { core::ptr::write_volatile(a as *mut u32, PAINT) };
    }
    // SAFETY: single-threaded, no references to PAINT_TOP exist.
    unsafe { core::ptr::write_volatile(&raw mut PAINT_TOP, top) };
}

/// Bytes of the painted area overwritten since [`paint`].
fn high_water() -> u32 {
    // SAFETY: as in `paint`.
    let top = unsafe { core::ptr::read_volatile(&raw const PAINT_TOP) };
    let mut a = top - PAINT_BYTES;
    // SAFETY: painted words below the stack, see `paint`.
    while a < top && unsafe { core::ptr::read_volatile(a as *const u32) } == PAINT {
        a += 4;
    }
    (top - a) as u32
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    semihosting::process::exit(1)
}
