//! Link-time proof that the core's boot and per-sample paths contain no reachable panic.
//!
//! This image owns nothing but the check: its panic handler calls `a_panic_is_reachable`, a
//! symbol defined nowhere, so the release link fails with
//! `undefined symbol: a_panic_is_reachable` as soon as the optimiser cannot remove every path
//! to a panic in the code below. It builds the calibration variants
//! ([`bins_comp::vectors::calibrations`]), parses the blob in the CALIB region into the
//! flashed variant ([`calib`], the same code as the firmware's, so the blob parser is in the
//! proof) and compensates inputs read with `read_volatile` (so nothing is constant-folded),
//! writing each result with `write_volatile`. It links no
//! defmt logger (the logger itself can panic) and does no text formatting. Only the release
//! build is meaningful: a debug build keeps panics the optimiser would remove.
//!
//! Each sample also goes through the per-sample step with vibration-error subtraction
//! ([`bins_comp::Pipeline`]): once as a vibration test-vector variant (a flight profile) and
//! once with the online moment window, whose state persists across the samples.
//!
//! The sampling interrupt's per-sample step ([`bins_comp::replay::Tick::step`], with the replay
//! firmware's pipeline and window) runs once per sample. Not yet covered: the heapless SPSC
//! enqueue/dequeue around it in `isr.rs` (with them in, the link reports a reachable panic).
//!
//! Run in QEMU, it compensates [`ITERATIONS`] samples and exits with success.
#![no_std]
#![no_main]

mod calib;

use bins_comp::vectors::{self, VARIANTS};
use cortex_m_rt::entry;

/// Inputs of one compensation, placed in RAM and read volatile.
#[repr(C)]
#[derive(Clone, Copy)]
struct Input {
    u_v: [f32; 3],
    temp_c: f32,
    variant: u32,
}

/// Output of one compensation, written volatile.
#[repr(C)]
#[derive(Clone, Copy)]
struct Output {
    accel_g: [f32; 3],
    status: u32,
}

/// Samples compensated before exiting.
const ITERATIONS: u32 = 64;

static mut INPUT: Input = Input { u_v: [0.1, -0.2, 0.55], temp_c: 45.0, variant: 3 };
static mut OUTPUT: Output = Output { accel_g: [0.0; 3], status: 0 };

#[entry]
fn main() -> ! {
    let mut cals = vectors::calibrations();
    if let Ok((cal, _)) = calib::calibration(&calib::read_region()) {
        cals[vectors::FLASHED_VARIANT] = cal;
    }
    let vib_pipeline = bins_comp::Pipeline::new(
        cals.get(1).copied().unwrap_or(bins_comp::Calibration::uncalibrated()),
        vectors::vibration_config(bins_comp::Variant::Exact),
    );
    let mut vib_state = bins_comp::PipelineState::<f32, 16>::new();
    let mut tick = bins_comp::replay::Tick::<f32, { bins_comp::replay::WINDOW }>::new(bins_comp::replay::pipeline(
        *vib_pipeline.calibration(),
    ));
    for i in 0..ITERATIONS {
        // SAFETY: `INPUT` is a valid, aligned, initialised static; this single-threaded
        // program has no interrupt handlers, so nothing writes it concurrently. The volatile
        // read keeps the compiler from assuming its value.
        let mut input = unsafe { core::ptr::read_volatile(&raw const INPUT) };
        input.variant = input.variant.wrapping_add(i);
        if let Some(cal) = cals.get(input.variant as usize % VARIANTS) {
            let s = cal.compensate(input.u_v, input.temp_c);
            let out = Output { accel_g: s.accel_g, status: s.status.0 };
            // SAFETY: `OUTPUT` is a valid, aligned static, written by this code only; nothing
            // holds a reference to it.
            unsafe { core::ptr::write_volatile(&raw mut OUTPUT, out) };
        }
        let rec = vectors::Record {
            variant: vectors::VIB_VARIANT_BASE + input.variant % vectors::VIB_VARIANTS,
            u_v: input.u_v,
            temp_c: input.temp_c,
            expected: bins_comp::Sample { accel_g: [0.0; 3], status: bins_comp::Status::OK },
        };
        // The sampling interrupt's body, as the replay firmware runs it.
        let s0 = tick.step(&bins_comp::replay::Input {
            u_v: input.u_v,
            temp_c: input.temp_c,
            status: bins_comp::Status::OK,
        });
        // SAFETY: `OUTPUT` is a valid, aligned static, written by this code only; nothing
        // holds a reference to it.
        unsafe { core::ptr::write_volatile(&raw mut OUTPUT, Output { accel_g: s0.accel_g, status: s0.status.0 }) };
        let online = vib_pipeline.step(&mut vib_state, input.u_v, input.temp_c, bins_comp::VibrationSource::Online);
        for s in [vectors::evaluate(&cals, &rec), online] {
            // SAFETY: `OUTPUT` is a valid, aligned static, written by this code only; nothing
            // holds a reference to it.
            unsafe { core::ptr::write_volatile(&raw mut OUTPUT, Output { accel_g: s.accel_g, status: s.status.0 }) };
        }
    }
    semihosting::process::exit(0)
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    unsafe extern "C" {
        /// Defined nowhere: referencing it makes a reachable panic a link error.
        fn a_panic_is_reachable() -> !;
    }
    // SAFETY: never executed in a linked image: the link fails if this call is reachable.
    unsafe { a_panic_is_reachable() }
}
