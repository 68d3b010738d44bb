//! What the two benchmark images share (`mod benchkit;` in `bench` and `bench-stages`): the
//! inputs, read volatile so that nothing is constant-folded, and the SysTick timing.
//!
//! Timing: under `-icount shift=0` QEMU runs one instruction per ns and SysTick counts the
//! 25 MHz core clock, so one count is [`INSNS_PER_COUNT`] instructions; a measurement runs
//! [`N`] calls and subtracts the same loop around something cheaper, so its resolution is
//! 40/N instructions per call.

use bins_comp::replay::Input;
use bins_comp::{Calibration, Method, Status, TempModel, ThermalDynamics, paper};
use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;

/// Calls per measurement (a multiple of the online block, so block completions are averaged
/// exactly).
pub const N: u32 = 2048;
/// Samples per temperature reading in the normal cases: a TMP117 at its fastest conversion
/// cycle (15.5 ms) against 1 kHz sampling.
pub const TEMP_EVERY: u32 = 16;
/// Instructions per SysTick count (`-icount shift=0`, 25 MHz SysTick).
pub const INSNS_PER_COUNT: u32 = 40;

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
pub fn input(i: u32, temp_every: u32) -> Input<f32> {
    // SAFETY: `INPUTS` is a valid, aligned static and `i % 8` indexes it; nothing writes it
    // and there are no interrupts in these programs. Volatile so the inputs are not
    // constant-folded; only the row used is read, so that the loop's own cost stays small
    // beside the step's and the empty loop subtracts it.
    let r = unsafe { core::ptr::read_volatile((&raw const INPUTS).cast::<[f32; 4]>().add((i % 8) as usize)) };
    // The period through `black_box`, so that the measured loop and the empty one divide
    // alike (a constant period would be a shift in one and a division in the other).
    let reading = i / core::hint::black_box(temp_every).max(1);
    let t = 20.0 + (reading % 97) as f32 * 0.37 - 17.0;
    Input { u_v: [r[0], r[1], r[2]], temp_c: t, status: Status::OK }
}

/// SysTick free-running at the core clock, its full 24-bit range.
pub fn start_systick(syst: &mut SYST) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(0x00FF_FFFF);
    syst.clear_current();
    syst.enable_counter();
}

/// SysTick counts of `N` calls of `g` (through a `dyn` call, as every measured loop).
pub fn run(syst: &mut SYST, g: &mut dyn FnMut(u32) -> f32) -> u32 {
    syst.clear_current();
    let t0 = SYST::get_current();
    let mut acc = 0.0f32;
    for i in 0..N {
        acc += g(i);
    }
    let t1 = SYST::get_current();
    core::hint::black_box(acc);
    t0.wrapping_sub(t1) & 0x00FF_FFFF
}

/// SysTick counts spent by `f` over `N` calls, minus the loop reading the inputs alone.
pub fn counts(syst: &mut SYST, mut f: impl FnMut(u32) -> f32) -> u32 {
    let full = run(syst, &mut |i| f(i));
    let empty = run(syst, &mut |i| core::hint::black_box(input(i, TEMP_EVERY)).temp_c);
    full.saturating_sub(empty)
}

/// Instructions per call ×100 from the counts of `N` calls.
pub fn per_call_x100(c: u32) -> u32 {
    (c as u64 * INSNS_PER_COUNT as u64 * 100 / N as u64) as u32
}

/// The paper's unit with `model` and `method` in `f32` (the uncalibrated stand-in if it does
/// not build; the caller checks).
pub fn cal(model: TempModel<f64>, method: Method) -> Calibration<f32> {
    paper::calibration::<f32>(model, method).unwrap_or(Calibration::uncalibrated())
}

/// Thermal dynamics with every stage on: a die a minute behind the thermistor, a 0.3 °C play,
/// 1.5 °C of self-heating over 5 minutes, a 0.5 °C bias play.
pub const UNIT_DYNAMICS: ThermalDynamics<f32> = ThermalDynamics {
    lag_tau_s: 60.0,
    hysteresis_width_c: 0.3,
    self_heating_c: 1.5,
    self_heating_tau_s: 300.0,
    bias_play_width_c: 0.5,
    bias_play_g: [20e-6, -15e-6, 10e-6],
};
