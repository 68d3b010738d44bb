//! Benchmark firmware: instructions per sample of the per-sample step in QEMU, and the stack
//! depth of the sampling interrupt's body.
//!
//! Run by `cargo xtask bench` under `-icount shift=0` (one instruction per ns). SysTick counts
//! the 25 MHz core clock, so one count is 40 instructions; each case runs [`N`] steps over
//! varying inputs read with `read_volatile`, minus the same loop without the step. The stack
//! is painted below the current stack pointer before the heaviest case and scanned after it.
#![no_std]
#![no_main]

use bins_comp::pipeline::VibrationSource;
use bins_comp::replay::{Input, Tick, WINDOW};
use bins_comp::{Calibration, Form, Method, Pipeline, Status, TempModel, paper};
use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m_rt::entry;
use defmt_semihosting as _;

/// Steps per case.
const N: u32 = 2000;
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

fn input(i: u32) -> Input<f32> {
    // SAFETY: `INPUTS` is a valid, aligned static; nothing writes it and there are no
    // interrupts in this program. Volatile so the inputs are not constant-folded.
    let a = unsafe { core::ptr::read_volatile(&raw const INPUTS) };
    let r = a.get((i % 8) as usize).copied().unwrap_or_default();
    // The temperature moves every sample (as in a ramp), so no case can reuse K(T).
    let t = r[3] + (i % 97) as f32 * 0.013;
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
    let empty = run(&mut |i| core::hint::black_box(input(i)).temp_c);
    full.saturating_sub(empty)
}

/// Instructions per sample ×100.
fn per_sample_x100(c: u32) -> u32 {
    (c as u64 * INSNS_PER_COUNT as u64 * 100 / N as u64) as u32
}

fn cal(model: TempModel<f64>, method: Method) -> Calibration<f32> {
    paper::calibration::<f32>(model, method).unwrap_or(Calibration::uncalibrated())
}

/// The quadratic through Tables T1/T2 made order 3 (a small cubic term), so the Horner
/// evaluation has its full length.
fn order3() -> Option<TempModel<f64>> {
    match paper::quadratic_truth().ok()? {
        TempModel::Poly { mut coef, .. } => {
            let c2 = coef.get(1).copied()?.to_array();
            let c3 = c2.map(|c| c * 1e-3);
            *coef.get_mut(2)? = bins_comp::CoefDelta::from_array(&c3);
            Some(TempModel::Poly { order: 3, coef })
        }
        other => Some(other),
    }
}

#[inline(never)]
fn step<const W: usize>(t: &mut Tick<f32, W>, i: u32) -> f32 {
    let s = t.step(&input(i));
    s.accel_g[0] + s.accel_g[1] + s.accel_g[2]
}

#[entry]
fn main() -> ! {
    let Some(mut cp) = cortex_m::Peripherals::take() else { semihosting::process::exit(1) };
    let syst = &mut cp.SYST;
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(0x00FF_FFFF);
    syst.clear_current();
    syst.enable_counter();

    let poly3 = order3().unwrap_or(TempModel::Poly { order: 1, coef: [bins_comp::CoefDelta::default(); 4] });
    let pwl = paper::two_range_model().unwrap_or(poly3);
    let vib = bins_comp::vectors::vibration_config::<f32>(bins_comp::Variant::Exact);
    let cases: [(&str, Calibration<f32>, bool); 6] = [
        ("poly3 method 1 + online VE", cal(poly3, Method::CoefficientCorrection), true),
        ("poly3 method 1", cal(poly3, Method::CoefficientCorrection), false),
        ("pwl method 1", cal(pwl, Method::CoefficientCorrection), false),
        ("pwl method 2 simplified", cal(pwl, Method::OutputCorrection(Form::Simplified)), false),
        ("pwl method 2 simplified + online VE", cal(pwl, Method::OutputCorrection(Form::Simplified)), true),
        ("pwl uncorrected", cal(pwl, Method::Uncorrected), false),
    ];
    for (i, (name, c, with_ve)) in cases.iter().enumerate() {
        if !c.is_valid() {
            defmt::error!("case {=str}: calibration did not build", name);
        }
        let p = if *with_ve { Pipeline::new(*c, vib) } else { Pipeline::new(*c, bins_comp::VibrationConfig::none()) };
        let mut t = Tick::<f32, WINDOW>::new(p);
        // Fill the window so the VE cases take their full path.
        for k in 0..WINDOW as u32 {
            step(&mut t, k);
        }
        let src_ok = !*with_ve || bins_comp::replay::SOURCE == VibrationSource::Online;
        if i == 0 {
            paint();
        }
        let c = counts(syst, |k| if *with_ve { step(&mut t, k) } else { step_nove(&mut t, k) });
        let x = per_sample_x100(c);
        defmt::info!(
            "BENCH {=str}: {=u32}.{=u32:02} instructions/sample (source ok: {})",
            name,
            x / 100,
            x % 100,
            src_ok
        );
        if i == 0 {
            defmt::info!("STACK step high-water: {=u32} bytes below main's frame", high_water());
        }
    }
    semihosting::process::exit(0)
}

/// Without the VE (source `None`): the temperature step alone.
#[inline(never)]
fn step_nove<const W: usize>(t: &mut Tick<f32, W>, i: u32) -> f32 {
    let inp = input(i);
    let s = t.pipeline.step(&mut t.state, inp.u_v, inp.temp_c, VibrationSource::None);
    s.accel_g[0] + s.accel_g[1] + s.accel_g[2]
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
