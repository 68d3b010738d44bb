//! Replay firmware: a recording streamed through the sampling interrupt in QEMU (ARM MPS2
//! AN386) with semihosting.
//!
//! - At boot the calibration blob in the CALIB region is parsed once ([`calib`]); if it is
//!   missing or invalid the firmware runs uncalibrated (every sample flagged
//!   `INVALID_CALIBRATION`).
//! - SysTick fires at [`TICK_HZ`] (default 1 kHz; `REPLAY_TICK_HZ` at build time). Its handler
//!   runs [`isr::Isr::on_tick`]: one sample from the input queue, one pipeline step
//!   ([`bins_comp::replay`]) with the VE of [`VE_SOURCE`] subtracted (the online window unless
//!   `REPLAY_VE` says otherwise at build time), one result into the output queue.
//! - `main` is the consumer and the prefetcher: it keeps the input queue filled from
//!   `target/fw-replay/in.bin` ([`INPUT_BYTES`] per sample, relative to QEMU's working
//!   directory), drains the output queue into `target/fw-replay/out.bin` ([`OUTPUT_BYTES`] per
//!   result) and sleeps (`wfi`) in between.
//!
//! It exits with success iff every sample was processed with no overrun.
#![no_std]
#![no_main]
#![allow(
    unsafe_code,
    reason = "the Cortex-M runtime's entry and exception handlers, SysTick, the queues between the interrupt and `main`"
)]

use core::cell::RefCell;
use core::sync::atomic::{AtomicBool, Ordering};

mod calib;
mod interrupts;
mod isr;

use bins_comp::replay::{self, INPUT_BYTES, Input, OUTPUT_BYTES};
use bins_comp::{Pipeline, Sample, VibrationSource};
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{SCB, SYST};
use cortex_m_rt::{ExceptionFrame, entry, exception};
use critical_section::Mutex;
use heapless::spsc::{Consumer, Producer, Queue};
use isr::{Isr, SampleIn, Take};
use semihosting::fs::File;
use semihosting::io::{Read, Write};

// The defmt global logger: frames go to QEMU's stdout.
use defmt_semihosting as _;

/// Input stream, relative to QEMU's working directory.
const IN_PATH: &core::ffi::CStr = c"target/fw-replay/in.bin";
/// Output stream: one result per input sample, in input order.
const OUT_PATH: &core::ffi::CStr = c"target/fw-replay/out.bin";
/// SysTick clock: the MPS2 AN386 core clock \[Hz\].
const CORE_CLOCK_HZ: u32 = 25_000_000;
/// Sampling rate \[Hz\]: `REPLAY_TICK_HZ` at build time, else 1000.
const TICK_HZ: u32 = parse_hz(option_env!("REPLAY_TICK_HZ"), 1000);
/// The rate \[Hz\] the pipeline is configured for (the thermal dynamics' time step):
/// `REPLAY_SAMPLE_HZ` at build time, else [`TICK_HZ`]. A recording logged slower than SysTick
/// can tick (1 Hz rows) is replayed one row per tick with the time step of its rows.
const SAMPLE_HZ: u32 = match parse_u32(option_env!("REPLAY_SAMPLE_HZ")) {
    Some(v) if v > 0 => v,
    _ => TICK_HZ,
};
/// The VE subtracted: `REPLAY_VE` at build time (`none`, `online` or `profile:N`, see
/// [`VibrationSource::parse`]), else [`replay::SOURCE`], the flight image's. Any other value
/// stops the build.
const VE_SOURCE: VibrationSource = match option_env!("REPLAY_VE") {
    None => replay::SOURCE,
    Some(name) => match VibrationSource::parse(name) {
        Some(source) => source,
        None => panic!("REPLAY_VE must be none, online or profile:N"),
    },
};
/// Length of the input queue (it holds one sample less).
const IN_QUEUE: usize = 64;
/// Length of the output queue (it holds one result less).
const OUT_QUEUE: usize = 64;
/// Samples per file read and results per file write.
const CHUNK: usize = 32;

/// Semihosting exit status of a passing run.
const EXIT_SUCCESS: i32 = 0;
/// Semihosting exit status of a failing run.
const EXIT_FAILURE: i32 = 1;

/// Samples waiting for the interrupt (filled by `main`).
static mut IN_Q: Queue<Input<f32>, IN_QUEUE> = Queue::new();
/// Results waiting for `main`.
static mut OUT_Q: Queue<Sample<f32>, OUT_QUEUE> = Queue::new();
/// Set by `main` once the whole input file is in the input queue.
static INPUT_DONE: AtomicBool = AtomicBool::new(false);
/// Set by the interrupt when the input has ended: no more results will come.
static ENDED: AtomicBool = AtomicBool::new(false);
/// The interrupt's state, installed by `main` before SysTick starts.
static ISR: Mutex<RefCell<Option<Isr<Replay, OUT_QUEUE>>>> = Mutex::new(RefCell::new(None));

/// The replay source: the input queue; empty with the file done means the end.
struct Replay {
    input: Consumer<'static, Input<f32>, IN_QUEUE>,
}

impl SampleIn for Replay {
    fn take(&mut self) -> Take {
        match self.input.dequeue() {
            Some(i) => Take::Sample(i),
            None if INPUT_DONE.load(Ordering::Acquire) => Take::End,
            None => Take::NotReady,
        }
    }
}

/// The sampling interrupt. Deadline: it must return within one tick period (1/[`TICK_HZ`],
/// 1 ms at the default rate), before the next SysTick; if the next one is already pending
/// when it finishes, the deadline was missed and the next result is flagged `OVERRUN`.
#[exception]
fn SysTick() {
    // Acknowledge first: reading SYST_CSR clears COUNTFLAG (the pending bit itself is cleared
    // by the exception entry).
    // SAFETY: a read of a read-only-in-effect SysTick register; the only side effect is
    // clearing COUNTFLAG, which nothing else uses.
    let _ = unsafe { (*SYST::PTR).csr.read() };
    critical_section::with(|cs| {
        let Ok(mut slot) = ISR.borrow(cs).try_borrow_mut() else { return };
        let Some(isr) = slot.as_mut() else { return };
        if !isr.on_tick() {
            ENDED.store(true, Ordering::Release);
        }
        if SCB::is_pendst_pending() {
            isr.tick.overrun();
        }
    });
}

#[entry]
fn main() -> ! {
    let code = match run() {
        Ok(()) => EXIT_SUCCESS,
        Err(e) => {
            defmt::error!("FAIL: {}", e);
            EXIT_FAILURE
        }
    };
    semihosting::process::exit(code)
}

/// Why a run failed.
#[derive(defmt::Format)]
enum RunError {
    OpenInput,
    CreateOutput,
    Read,
    Write,
    NoPeripherals,
    /// The input's length is not a whole number of samples.
    TrailingBytes(usize),
    /// Samples lost or flagged: (samples read, results written, overruns).
    Lost(u32, u32, u32),
}

fn run() -> Result<(), RunError> {
    let pipeline = flashed_pipeline();
    // SAFETY: `main` runs once and these are the only references ever taken to the two
    // queues; the halves are then owned by exactly one context each (producer and consumer).
    let in_q: Option<&'static mut Queue<Input<f32>, IN_QUEUE>> = unsafe { (&raw mut IN_Q).as_mut() };
    // SAFETY: as above.
    let out_q: Option<&'static mut Queue<Sample<f32>, OUT_QUEUE>> = unsafe { (&raw mut OUT_Q).as_mut() };
    let (Some(in_q), Some(out_q)) = (in_q, out_q) else { return Err(RunError::NoPeripherals) };
    let (mut in_p, in_c) = in_q.split();
    let (out_p, mut out_c) = out_q.split();
    let mut input = File::open(IN_PATH).map_err(|_| RunError::OpenInput)?;
    let mut output = File::create(OUT_PATH).map_err(|_| RunError::CreateOutput)?;

    let mut read = 0u32;
    refill(&mut input, &mut in_p, &mut read)?;
    let isr = Isr::new(pipeline, Replay { input: in_c }, out_p);
    // `try_borrow_mut`, not `replace`: nothing holds the cell before SysTick starts, and no
    // borrow panic is left in the image (as in the flight image).
    critical_section::with(|cs| {
        if let Ok(mut slot) = ISR.borrow(cs).try_borrow_mut() {
            *slot = Some(isr);
        }
    });

    let mut cp = cortex_m::Peripherals::take().ok_or(RunError::NoPeripherals)?;
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(CORE_CLOCK_HZ / TICK_HZ - 1);
    cp.SYST.clear_current();
    cp.SYST.enable_interrupt();
    cp.SYST.enable_counter();
    defmt::info!(
        "replay: SysTick at {} Hz, samples of {} Hz, VE source {}",
        TICK_HZ,
        SAMPLE_HZ,
        defmt::Debug2Format(&VE_SOURCE)
    );

    let mut outbuf = [0u8; CHUNK * OUTPUT_BYTES];
    let mut out_len = 0usize;
    let mut written = 0u32;
    loop {
        if !INPUT_DONE.load(Ordering::Relaxed) && in_p.capacity() - in_p.len() >= CHUNK {
            refill(&mut input, &mut in_p, &mut read)?;
        }
        let ended = ENDED.load(Ordering::Acquire);
        while let Some(s) = out_c.dequeue() {
            if let Some(slot) = outbuf.get_mut(out_len..out_len + OUTPUT_BYTES) {
                slot.copy_from_slice(&replay::encode_output(&s));
                out_len += OUTPUT_BYTES;
                written += 1;
            }
            if out_len == outbuf.len() {
                output.write_all(&outbuf).map_err(|_| RunError::Write)?;
                out_len = 0;
            }
        }
        if ended {
            break;
        }
        cortex_m::asm::wfi();
    }
    cp.SYST.disable_interrupt();
    output.write_all(outbuf.get(..out_len).unwrap_or(&[])).map_err(|_| RunError::Write)?;
    let overruns = critical_section::with(|cs| {
        ISR.borrow(cs).try_borrow().ok().and_then(|slot| slot.as_ref().map(|i| i.tick.overruns())).unwrap_or(0)
    });
    defmt::info!("samples: {}, results: {}, overruns: {}", read, written, overruns);
    if read == written && overruns == 0 && read > 0 {
        defmt::info!("PASS");
        Ok(())
    } else {
        Err(RunError::Lost(read, written, overruns))
    }
}

/// Reads up to [`CHUNK`] samples (no more than the queue has room for) into the input queue;
/// a short read is the end of the file and sets [`INPUT_DONE`].
fn refill(file: &mut File, q: &mut Producer<'static, Input<f32>, IN_QUEUE>, read: &mut u32) -> Result<(), RunError> {
    let want = CHUNK.min(q.capacity() - q.len());
    let mut buf = [0u8; CHUNK * INPUT_BYTES];
    let Some(buf) = buf.get_mut(..want * INPUT_BYTES) else { return Ok(()) };
    let filled = read_full(file, buf)?;
    for rec in buf.get(..filled).unwrap_or(&[]).chunks_exact(INPUT_BYTES) {
        let Ok(rec) = <&[u8; INPUT_BYTES]>::try_from(rec) else { continue };
        if q.enqueue(Input::decode(rec)).is_ok() {
            *read += 1;
        }
    }
    if filled < buf.len() {
        if filled % INPUT_BYTES != 0 {
            return Err(RunError::TrailingBytes(filled % INPUT_BYTES));
        }
        INPUT_DONE.store(true, Ordering::Release);
    }
    Ok(())
}

/// Fills `buf` from `file`; returns fewer bytes than `buf.len()` only at end of file.
fn read_full(file: &mut File, buf: &mut [u8]) -> Result<usize, RunError> {
    let mut filled = 0;
    while let Some(rest) = buf.get_mut(filled..) {
        if rest.is_empty() {
            break;
        }
        match file.read(rest) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(_) => return Err(RunError::Read),
        }
    }
    Ok(filled)
}

/// The calibration and vibration-error model in the CALIB region, read and checked once, at
/// boot; on any error, logged, the uncalibrated stand-in with no VE model (every sample
/// flagged `INVALID_CALIBRATION`).
fn flashed_pipeline() -> Pipeline<f32> {
    let region = calib::read_region();
    match calib::calibration(&region, 1.0 / SAMPLE_HZ as f32) {
        Ok((pipeline, parsed)) => {
            defmt::info!(
                "CALIB: valid calibration blob, unit {=str}, {=usize} vibration profiles, thermal dynamics {=bool}",
                parsed.meta.serial,
                pipeline.vibration().n_profiles(),
                pipeline.dynamics().is_some()
            );
            pipeline
        }
        Err(e) => {
            defmt::error!("CALIB: {}: running uncalibrated", defmt::Display2Format(&e));
            Pipeline::uncalibrated()
        }
    }
}

/// `s` as a decimal rate in Hz, or `default` if it is absent, not a number, zero, or too low
/// for SysTick's 24-bit reload.
const fn parse_hz(s: Option<&str>, default: u32) -> u32 {
    match parse_u32(s) {
        Some(v) if v > 0 && CORE_CLOCK_HZ / v <= (1 << 24) => v,
        _ => default,
    }
}

/// `s` as a decimal number up to 10⁹, or `None` if it is absent or not one.
const fn parse_u32(s: Option<&str>) -> Option<u32> {
    let Some(s) = s else { return None };
    let b = s.as_bytes();
    if b.is_empty() {
        return None;
    }
    let mut v: u32 = 0;
    let mut i = 0;
    while i < b.len() {
        let d = b[i];
        if d < b'0' || d > b'9' || v > 100_000_000 {
            return None;
        }
        v = v * 10 + (d - b'0') as u32;
        i += 1;
    }
    Some(v)
}

/// Set by the first panic, so a panic while logging the panic does not recurse.
static PANICKING: AtomicBool = AtomicBool::new(false);

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    if !PANICKING.swap(true, Ordering::Relaxed) {
        match info.location() {
            Some(l) => defmt::error!("panic at {}:{}", l.file(), l.line()),
            None => defmt::error!("panic"),
        }
    }
    semihosting::process::exit(EXIT_FAILURE)
}

#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    if !PANICKING.swap(true, Ordering::Relaxed) {
        defmt::error!("HardFault at pc {:#x}", ef.pc());
    }
    semihosting::process::exit(EXIT_FAILURE)
}
