//! The flight image: the firmware that is flashed, with no test harness (no semihosting, no
//! logger, no test vectors). The flash and static-RAM budgets are measured on it.
//!
//! - At boot the calibration blob in the CALIB region is parsed once ([`calib`]); if it is
//!   missing or invalid the image runs uncalibrated (every sample flagged
//!   `INVALID_CALIBRATION`), exactly as the replay firmware does. A blob with thermal dynamics
//!   (section 0x0007) gets them at the interrupt's fixed period 1/[`TICK_HZ`], their gains
//!   computed once here.
//! - The sensors are initialised on the board's peripherals ([`board`]): the ADS131M04 on the
//!   PL022 SPI with its DRDY line on GPIO0, the TMP117 on the SBCon I²C, behind the sample
//!   source and its fault policy ([`bins_comp::drivers::SampleSource`], [`SOURCE_CONFIG`]).
//!   A sensor that does not answer is not fatal: it is not read, every sample says so
//!   (`SENSOR_FAULT`), and its initialisation is tried again every second.
//! - SysTick fires at [`TICK_HZ`]. Its handler runs [`isr::Isr::on_tick`]: one sample from the
//!   sensors, one pipeline step (the thermal dynamics first, when the blob has them), one
//!   result into the queue.
//! - `main` is the consumer: it drains the queue into output frames on UART0
//!   ([`bins_comp::frame`]): a boot frame first (blob accepted or not, sensors initialised),
//!   then one sample frame per sample and a health frame (fault counts, overruns, link
//!   errors) every [`HEALTH_EVERY`] samples, and sleeps (`wfi`) in between. It never returns.
//!
//! The image contains no reachable panic: its panic handler calls `a_panic_is_reachable`, a
//! symbol defined nowhere, so its release link fails if the optimiser cannot remove every
//! path to a panic (as in `linkcheck`; only the release build links). A HardFault resets the
//! processor: the next boot frame on the link shows it.
#![no_std]
#![no_main]
#![allow(
    unsafe_code,
    reason = "the Cortex-M runtime's entry and exception handlers, SysTick, the queue between the interrupt and `main`, the board's registers"
)]
#![cfg_attr(unstable_target, feature(optimize_attribute))]

use core::cell::RefCell;

mod board;
mod calib;
mod interrupts;
// The interrupt body shared with the replay firmware and the link check; this image's source
// never misses a slot or ends, so two of its `Take` variants are not built here.
#[allow(dead_code)]
mod isr;

use bins_comp::drivers::{Ads131m04, FaultCounts, SampleSource, SourceConfig, Tmp117, adc, temp};
use bins_comp::frame::{BootFrame, FORMAT_VERSION, Frame, HealthFrame, SampleFrame};
use bins_comp::{Pipeline, Sample, VibrationSource};
use board::{Board, DrdyPin, Pl022, SbCon, Uart};
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{SCB, SYST};
use cortex_m_rt::{ExceptionFrame, entry, exception};
use critical_section::Mutex;
use heapless::spsc::Queue;
use isr::Isr;

/// Sampling rate \[Hz\].
const TICK_HZ: u32 = 1000;
/// Length of the queue between the interrupt and `main` (it holds one result less: 31 ms at
/// 1 kHz).
const QUEUE: usize = 32;
/// A health frame after every this many samples (1 s at [`TICK_HZ`]).
const HEALTH_EVERY: u32 = TICK_HZ;
/// The fault policy's timing at 1 kHz sampling: the TMP117 polled every 32 samples (32 ms; it
/// converts every 125 ms at its default averaging), one held sample bridging an isolated ADC
/// glitch, a temperature at most 2 s (16 conversions) old, a sensor that failed to initialise
/// tried again every second.
const SOURCE_CONFIG: SourceConfig =
    SourceConfig { temp_poll_interval: 32, max_signal_hold: 1, max_temp_age: 2000, reinit_interval: TICK_HZ };

/// The VE subtracted in flight: the online moment window ([`bins_comp::replay::SOURCE`]).
const VE_SOURCE: VibrationSource = bins_comp::replay::SOURCE;

/// The flight sample source on this board.
type Source = SampleSource<Pl022, DrdyPin, SbCon>;

/// Results waiting for `main`.
static mut QUEUE_ISR: Queue<Sample<f32>, QUEUE> = Queue::new();
/// The interrupt's state, installed by `main` before SysTick starts.
static ISR: Mutex<RefCell<Slot>> = Mutex::new(RefCell::new(Slot::Empty));

/// The interrupt's state or none yet. Like an `Option`, but its empty value is all zero bytes
/// (an explicit `u32` tag 0), so [`ISR`] is zero-initialised (`.bss`) instead of taking flash
/// for its initial value (`.data`), as `None` of the niche-optimised `Option` would.
// One static instance, no heap: the empty variant's unused bytes are the point.
#[allow(clippy::large_enum_variant)]
#[repr(u32)]
enum Slot {
    Empty = 0,
    Running(Isr<Source, QUEUE>),
}

/// The sampling interrupt. Deadline: it must return within one tick period (1 ms), before
/// the next SysTick; if the next one is already pending when it finishes, the deadline was
/// missed and the next result is flagged `OVERRUN`. Its bus accesses are bounded
/// ([`board`]): one ADC frame (23 µs on the SPI) every tick, one or two TMP117 register reads
/// (about 0.14 ms each on the I²C) every 32nd.
#[exception]
fn SysTick() {
    // Acknowledge first: reading SYST_CSR clears COUNTFLAG (the pending bit itself is cleared
    // by the exception entry).
    // SAFETY: a read of a read-only-in-effect SysTick register; the only side effect is
    // clearing COUNTFLAG, which nothing else uses.
    let _ = unsafe { (*SYST::PTR).csr.read() };
    critical_section::with(|cs| {
        let Ok(mut slot) = ISR.borrow(cs).try_borrow_mut() else { return };
        let Slot::Running(isr) = &mut *slot else { return };
        isr.on_tick();
        if SCB::is_pendst_pending() {
            isr.tick.overrun();
        }
    });
}

/// What the boot found, for the boot frame.
struct Boot {
    blob_accepted: bool,
    vibration_profiles: u32,
    blob_crc32: u32,
}

#[entry]
fn main() -> ! {
    run()
}

/// Boot, then the consumer loop (see the module docs). Out of line and optimised for size:
/// none of it is on the per-sample path.
#[inline(never)]
#[cfg_attr(unstable_target, optimize(size))]
fn run() -> ! {
    let (Some(board), Some(mut cp)) = (Board::take(), cortex_m::Peripherals::take()) else { SCB::sys_reset() };
    let uart = board.uart;
    let (pipeline, boot) = flashed_pipeline();
    let adc = Ads131m04::new(board.spi, board.drdy, adc::Config::default());
    let temp = Tmp117::new(board.i2c, temp::Address::Gnd);
    let source = SampleSource::init(adc, temp, temp::Config::default(), SOURCE_CONFIG);
    let (adc_ready, temp_ready) = (source.adc_ready(), source.temp_ready());

    // SAFETY: `main` runs once and this is the only reference ever taken to the queue; its
    // halves are then owned by exactly one context each (producer: the interrupt's state,
    // consumer: this loop).
    let queue: Option<&'static mut Queue<Sample<f32>, QUEUE>> = unsafe { (&raw mut QUEUE_ISR).as_mut() };
    let Some(queue) = queue else { SCB::sys_reset() };
    let (producer, mut consumer) = queue.split();
    let isr = Isr::new(pipeline, source, producer);
    // `try_borrow_mut`: `RefCell::replace` would contain a panic (already borrowed), which the
    // optimiser cannot rule out; nothing else holds the cell before SysTick starts.
    critical_section::with(|cs| {
        if let Ok(mut slot) = ISR.borrow(cs).try_borrow_mut() {
            *slot = Slot::Running(isr);
        }
    });

    let mut link = Link { uart, seq: 0, errors: 0 };
    link.send(Frame::Boot(BootFrame {
        seq: 0,
        blob_accepted: boot.blob_accepted,
        adc_ready,
        temp_ready,
        tick_hz: TICK_HZ,
        vibration_profiles: boot.vibration_profiles,
        blob_crc32: boot.blob_crc32,
        format_version: FORMAT_VERSION,
    }));

    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(board::CLOCK_HZ / TICK_HZ - 1);
    cp.SYST.clear_current();
    cp.SYST.enable_interrupt();
    cp.SYST.enable_counter();

    let mut until_health = HEALTH_EVERY;
    loop {
        while let Some(s) = consumer.dequeue() {
            link.send(Frame::Sample(SampleFrame::from_sample(0, &s)));
            until_health -= 1;
            if until_health == 0 {
                until_health = HEALTH_EVERY;
                let (counts, overruns, adc_ready, temp_ready) =
                    critical_section::with(|cs| match ISR.borrow(cs).try_borrow().as_deref() {
                        Ok(Slot::Running(i)) => {
                            let s = &i.source;
                            (*s.fault_counts(), i.tick.overruns(), s.adc_ready(), s.temp_ready())
                        }
                        _ => (FaultCounts::default(), 0, false, false),
                    });
                link.send(Frame::Health(HealthFrame {
                    seq: 0,
                    signal_faults: counts.signal_total(),
                    temp_faults: counts.temp_total(),
                    overruns,
                    link_errors: link.errors,
                    adc_ready,
                    temp_ready,
                }));
            }
        }
        cortex_m::asm::wfi();
    }
}

/// The output link: UART0 and the frame sequence.
struct Link {
    uart: Uart,
    /// Sequence number of the next frame.
    seq: u16,
    /// Frames not sent completely (transmitter stuck).
    errors: u32,
}

impl Link {
    /// Numbers the frame and sends it; a frame the UART does not take is counted, not retried
    /// (the host's decoder skips its remains).
    #[cfg_attr(unstable_target, optimize(size))]
    fn send(&mut self, mut frame: Frame) {
        match &mut frame {
            Frame::Sample(f) => f.seq = self.seq,
            Frame::Boot(f) => f.seq = self.seq,
            Frame::Health(f) => f.seq = self.seq,
        }
        self.seq = self.seq.wrapping_add(1);
        if self.uart.write_all(&frame.encode()).is_err() {
            self.errors = self.errors.saturating_add(1);
        }
    }
}

/// The calibration and vibration-error model in the CALIB region, read and checked once, at
/// boot; on any error, the uncalibrated stand-in with no VE model (every sample flagged
/// `INVALID_CALIBRATION`).
#[cfg_attr(unstable_target, optimize(size))]
#[inline(never)]
fn flashed_pipeline() -> (Pipeline<f32>, Boot) {
    let region = calib::read_region();
    match calib::calibration(&region, 1.0 / TICK_HZ as f32) {
        Ok((pipeline, parsed)) => {
            let crc = parsed.blob.bytes().last_chunk::<4>().map_or(0, |c| u32::from_le_bytes(*c));
            let profiles = pipeline.vibration().n_profiles() as u32;
            let boot = Boot { blob_accepted: true, vibration_profiles: profiles, blob_crc32: crc };
            (pipeline, boot)
        }
        Err(_) => (Pipeline::uncalibrated(), Boot { blob_accepted: false, vibration_profiles: 0, blob_crc32: 0 }),
    }
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

#[exception]
unsafe fn HardFault(_: &ExceptionFrame) -> ! {
    SCB::sys_reset()
}
