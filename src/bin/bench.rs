//! Benchmark firmware: instructions per sample of the per-sample step in QEMU, and the stack
//! depth of the sampling interrupt's body.
//!
//! Run by `cargo xtask bench` under `-icount shift=0` (one instruction per ns). SysTick counts
//! the 25 MHz core clock, so one count is 40 instructions; each case runs [`N`](benchkit::N) steps over
//! varying inputs read with `read_volatile`, minus the same loop without the step: the mean
//! per sample. The temperature reading changes every [`TEMP_EVERY`](benchkit::TEMP_EVERY) samples, as a TMP117 at
//! its fastest conversion cycle (15.5 ms) does at 1 kHz, or, in the "every sample" cases, on
//! every sample. The worst single step (a new temperature on a step that carries the online
//! VE's work: the one completing a block and the four after it) is timed alone over
//! [`WORST_REPS`] blocks, and the largest kept. The stack is
//! painted below the current stack pointer before the heaviest case and scanned after it.
//!
//! The budgets ([`BUDGET_ONLINE`] and the others) are failing limits: a missed one is logged
//! and the program exits with failure, after every case has run. The stages of the step are
//! timed one by one by the `bench-stages` image: here each case's step has one caller, so it
//! is inlined as in the sampling interrupt.
#![no_std]
#![no_main]
#![allow(unsafe_code, reason = "the painted stack read by address, the Cortex-M runtime's entry")]

mod benchkit;
mod interrupts;

use benchkit::{INSNS_PER_COUNT, TEMP_EVERY, UNIT_DYNAMICS, cal, counts, input, per_call_x100, start_systick};
use bins_comp::pipeline::VibrationSource;
use bins_comp::replay::{SOURCE, Tick, WINDOW};
use bins_comp::{Calibration, FixedRate, Form, Method, Pipeline, TempModel, ThermalDynamics, VibrationConfig, paper};
use cortex_m::peripheral::SYST;
use cortex_m_rt::entry;
use defmt_semihosting as _;

/// Worst-case steps timed.
const WORST_REPS: u32 = 16;
/// Bytes painted below the stack pointer.
const PAINT_BYTES: usize = 4096;
/// The paint pattern.
const PAINT: u32 = 0xDEAD_BEEF;

/// Budget of the order-3, method 1, online-VE case \[instructions per sample\].
const BUDGET_ONLINE: u32 = 150;
/// Budget of the piecewise, uncorrected case \[instructions per sample\].
const BUDGET_UNCORRECTED: u32 = 80;
/// Budget of the order-3, method 1 case with a new temperature reading on every sample
/// \[instructions per sample\].
const BUDGET_NEW_TEMPERATURE: u32 = 450;
/// Budget of the worst single step \[instructions\].
const BUDGET_WORST: u32 = 1200;
/// Budget of the thermal dynamics: a case with dynamics over the same case without
/// \[instructions per sample\].
const BUDGET_DYNAMICS: u32 = 30;
/// Budget of the step's stack \[bytes\].
const BUDGET_STACK: u32 = 416;

#[inline(never)]
fn step<const W: usize>(t: &mut Tick<f32, W>, i: u32, temp_every: u32, source: VibrationSource) -> f32 {
    let inp = input(i, temp_every);
    let s = t.pipeline.step(&mut t.state, inp.u_v, inp.temp_c, source);
    s.accel_g[0] + s.accel_g[1] + s.accel_g[2]
}

/// SysTick counts of the worst single step among those that carry the online VE's work (the
/// step that completes a block and the four after it, each with a new temperature reading),
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
        for _ in 0..5 {
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

/// One benchmark case: what runs, how often the temperature reading changes, and what it is
/// checked against.
struct Case<'a> {
    name: &'a str,
    cal: Calibration<f32>,
    source: VibrationSource,
    temp_every: u32,
    dynamics: Option<FixedRate<f32>>,
    /// Budget \[instructions per sample\], if the case has one.
    budget: Option<u32>,
    /// The same case without thermal dynamics (index), for the dynamics' budget.
    without_dynamics: Option<usize>,
    /// Time the worst single step too.
    worst: bool,
}

/// `met` or `MISSED`, and counts a miss.
fn verdict(value: u32, budget: u32, missed: &mut u32) -> &'static str {
    if value <= budget {
        "met"
    } else {
        *missed += 1;
        "MISSED"
    }
}

#[entry]
fn main() -> ! {
    let Some(mut cp) = cortex_m::Peripherals::take() else { semihosting::process::exit(1) };
    let syst = &mut cp.SYST;
    start_systick(syst);

    let poly3 =
        paper::order3_model().unwrap_or(TempModel::Poly { order: 1, coef: [bins_comp::CoefDelta::default(); 4] });
    let pwl = paper::two_range_model().unwrap_or(poly3);
    let vib = bins_comp::vectors::vibration_config::<f32>(bins_comp::Variant::Exact);
    let m1 = Method::CoefficientCorrection;
    let m2s = Method::OutputCorrection(Form::Simplified);
    let online = VibrationSource::Online;
    let none = VibrationSource::None;
    let profile = VibrationSource::Profile(0);
    // Thermal dynamics with every stage on, and the same without the lag, whose effective
    // temperature follows each new reading at once: the temperature terms are then recomputed
    // as often as without dynamics.
    let unit = UNIT_DYNAMICS;
    let full = unit.at_rate(1.0e-3).ok();
    let no_lag = ThermalDynamics { lag_tau_s: 0.0, ..unit }.at_rate(1.0e-3).ok();
    let case = |name, cal, source, temp_every, dynamics, without_dynamics| Case {
        name,
        cal,
        source,
        temp_every,
        dynamics,
        budget: None,
        without_dynamics,
        worst: false,
    };
    let cases: [Case; 17] = [
        Case {
            budget: Some(BUDGET_ONLINE),
            worst: true,
            ..case("poly3 method 1 + online VE", cal(poly3, m1), online, TEMP_EVERY, None, None)
        },
        case("poly3 method 1 + flight-profile VE", cal(poly3, m1), profile, TEMP_EVERY, None, None),
        case("poly3 method 1", cal(poly3, m1), none, TEMP_EVERY, None, None),
        Case {
            budget: Some(BUDGET_NEW_TEMPERATURE),
            ..case("poly3 method 1, new temperature every sample", cal(poly3, m1), none, 1, None, None)
        },
        case("pwl method 1", cal(pwl, m1), none, TEMP_EVERY, None, None),
        case("pwl method 2 simplified", cal(pwl, m2s), none, TEMP_EVERY, None, None),
        case("pwl method 2 simplified, new temperature every sample", cal(pwl, m2s), none, 1, None, None),
        case("pwl method 2 simplified + online VE", cal(pwl, m2s), online, TEMP_EVERY, None, None),
        Case {
            budget: Some(BUDGET_UNCORRECTED),
            ..case("pwl uncorrected", cal(pwl, Method::Uncorrected), none, TEMP_EVERY, None, None)
        },
        Case {
            worst: true,
            ..case("poly3 method 1 + online VE + dynamics", cal(poly3, m1), online, TEMP_EVERY, full, Some(0))
        },
        Case {
            worst: true,
            ..case(
                "poly3 method 1 + online VE + dynamics without lag",
                cal(poly3, m1),
                online,
                TEMP_EVERY,
                no_lag,
                Some(0),
            )
        },
        case("poly3 method 1 + dynamics", cal(poly3, m1), none, TEMP_EVERY, full, Some(2)),
        case("poly3 method 1 + dynamics without lag", cal(poly3, m1), none, TEMP_EVERY, no_lag, Some(2)),
        case("pwl method 2 simplified + dynamics", cal(pwl, m2s), none, TEMP_EVERY, full, Some(5)),
        case("pwl method 2 simplified + dynamics without lag", cal(pwl, m2s), none, TEMP_EVERY, no_lag, Some(5)),
        case("pwl method 2 simplified + online VE + dynamics", cal(pwl, m2s), online, TEMP_EVERY, full, Some(7)),
        case(
            "pwl method 2 simplified + dynamics without lag, new temperature every sample",
            cal(pwl, m2s),
            none,
            1,
            no_lag,
            Some(6),
        ),
    ];
    let mut missed = 0;
    let mut per_sample = [0u32; 17];
    for (i, c) in cases.iter().enumerate() {
        if !c.cal.is_valid() {
            defmt::error!("case {=str}: calibration did not build", c.name);
            missed += 1;
        }
        let mut p =
            if c.source != none { Pipeline::new(c.cal, vib) } else { Pipeline::new(c.cal, VibrationConfig::none()) };
        match (c.dynamics, c.without_dynamics) {
            (Some(d), _) => p = p.with_dynamics(d),
            (None, Some(_)) => {
                defmt::error!("case {=str}: thermal dynamics did not build", c.name);
                missed += 1;
            }
            (None, None) => {}
        }
        let mut t = Tick::<f32, WINDOW>::new(p);
        // Complete a block so the VE cases take their full path.
        for k in 0..WINDOW as u32 {
            step(&mut t, k, c.temp_every, c.source);
        }
        if i == 0 {
            paint();
        }
        let x = per_call_x100(counts(syst, |k| step(&mut t, k, c.temp_every, c.source)));
        if let Some(slot) = per_sample.get_mut(i) {
            *slot = x;
        }
        match c.budget {
            Some(b) => defmt::info!(
                "BENCH {=str}: {=u32}.{=u32:02} instructions/sample (budget {=u32}: {=str})",
                c.name,
                x / 100,
                x % 100,
                b,
                verdict(x, b * 100, &mut missed)
            ),
            None => defmt::info!("BENCH {=str}: {=u32}.{=u32:02} instructions/sample", c.name, x / 100, x % 100),
        }
        if let Some(base) = c.without_dynamics.and_then(|k| per_sample.get(k)) {
            let plus = x.saturating_sub(*base);
            defmt::info!(
                "DYNAMICS {=str}: +{=u32}.{=u32:02} instructions/sample (budget +{=u32}: {=str})",
                c.name,
                plus / 100,
                plus % 100,
                BUDGET_DYNAMICS,
                verdict(plus, BUDGET_DYNAMICS * 100, &mut missed)
            );
        }
        if i == 0 {
            let h = high_water();
            defmt::info!(
                "STACK step high-water: {=u32} bytes below main's frame (budget {=u32}: {=str})",
                h,
                BUDGET_STACK,
                verdict(h, BUDGET_STACK, &mut missed)
            );
        }
        if c.worst {
            let w = worst_counts(syst, &mut t) * INSNS_PER_COUNT;
            defmt::info!(
                "WORST {=str}: {=u32} instructions (one step, ±{=u32}; budget {=u32}: {=str})",
                c.name,
                w,
                INSNS_PER_COUNT,
                BUDGET_WORST,
                verdict(w, BUDGET_WORST, &mut missed)
            );
        }
    }
    if missed > 0 {
        defmt::error!("{=u32} budget(s) missed", missed);
        semihosting::process::exit(1)
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
