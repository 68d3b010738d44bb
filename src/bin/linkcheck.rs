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
//! The sampling interrupt's body ([`isr::Isr::on_tick`], the code the firmware's timer
//! interrupt runs) runs once per sample with the flight sample source: the ADS131M04 and
//! TMP117 drivers behind [`bins_comp::drivers::SampleSource`], initialised at boot, over
//! buses whose every byte, pin level and error is read volatile ([`bus`]), so every driver
//! path (frames, CRC errors, bus errors, missing data-ready) is in the proof. Its results go
//! through the heapless SPSC queue to the consumer, which drains it.
//!
//! Run in QEMU, it compensates [`ITERATIONS`] samples and exits with success.
#![no_std]
#![no_main]
#![allow(
    unsafe_code,
    reason = "volatile inputs and outputs that keep the checked code reachable, the queue, the undefined symbol a reachable panic links against"
)]

mod calib;
mod interrupts;
mod isr;

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

/// The VE source of the interrupt body's steps: the flight image's.
const VE_SOURCE: bins_comp::VibrationSource = bins_comp::replay::SOURCE;

static mut INPUT: Input = Input { u_v: [0.1, -0.2, 0.55], temp_c: 45.0, variant: 3 };
static mut OUTPUT: Output = Output { accel_g: [0.0; 3], status: 0 };

/// Length of the interrupt's output queue.
const QUEUE: usize = 8;
/// The interrupt's output queue.
static mut QUEUE_ISR: heapless::spsc::Queue<bins_comp::Sample<f32>, QUEUE> = heapless::spsc::Queue::new();

/// Nonzero: the sample source reports this slot's sample missing (1) or the end (2).
static mut SLOT: u32 = 0;

/// The flight sample source, whose slot can be missed or end (read volatile), so the
/// interrupt body's overrun and end paths are in the proof too.
struct Slots<S>(S);

impl<S: isr::SampleIn> isr::SampleIn for Slots<S> {
    fn take(&mut self) -> isr::Take {
        // SAFETY: a valid, aligned static read volatile; nothing holds a reference to it.
        match unsafe { core::ptr::read_volatile(&raw const SLOT) } {
            0 => self.0.take(),
            1 => isr::Take::NotReady,
            _ => isr::Take::End,
        }
    }
}

/// Buses whose data, pin levels and errors are read volatile from RAM, so that nothing the
/// drivers do with them can be assumed by the optimiser.
mod bus {
    use embedded_hal::digital::{ErrorKind as PinErrorKind, ErrorType as PinErrorType, InputPin};
    use embedded_hal::i2c::{self, ErrorKind as I2cErrorKind, I2c};
    use embedded_hal::spi::{self, ErrorKind as SpiErrorKind, SpiDevice};

    /// Bytes the buses deliver, cycled.
    static mut RX: [u8; 64] = [0; 64];
    /// Nonzero: the next bus operation fails.
    static mut FAIL: u32 = 0;
    /// The DRDY pin level (nonzero: high).
    static mut LEVEL: u32 = 0;

    fn rx(i: usize) -> u8 {
        // SAFETY: a valid, aligned static read volatile; nothing holds a reference to it.
        let a = unsafe { core::ptr::read_volatile(&raw const RX) };
        a[i % 64]
    }

    fn fail() -> bool {
        // SAFETY: as in `rx`.
        unsafe { core::ptr::read_volatile(&raw const FAIL) != 0 }
    }

    fn fill(buf: &mut [u8], pos: &mut usize) {
        for b in buf.iter_mut() {
            *b = rx(*pos);
            *pos = pos.wrapping_add(1);
        }
    }

    /// SPI device.
    #[derive(Default)]
    pub struct Spi(usize);
    impl spi::ErrorType for Spi {
        type Error = SpiErrorKind;
    }
    impl SpiDevice<u8> for Spi {
        fn transaction(&mut self, ops: &mut [spi::Operation<'_, u8>]) -> Result<(), SpiErrorKind> {
            if fail() {
                return Err(SpiErrorKind::Other);
            }
            for op in ops.iter_mut() {
                match op {
                    spi::Operation::Read(b) | spi::Operation::TransferInPlace(b) => fill(b, &mut self.0),
                    spi::Operation::Transfer(r, _) => fill(r, &mut self.0),
                    spi::Operation::Write(_) | spi::Operation::DelayNs(_) => {}
                }
            }
            Ok(())
        }
    }

    /// I²C bus.
    #[derive(Default)]
    pub struct Bus(usize);
    impl i2c::ErrorType for Bus {
        type Error = I2cErrorKind;
    }
    impl I2c for Bus {
        fn transaction(&mut self, _address: u8, ops: &mut [i2c::Operation<'_>]) -> Result<(), I2cErrorKind> {
            if fail() {
                return Err(I2cErrorKind::Bus);
            }
            for op in ops.iter_mut() {
                if let i2c::Operation::Read(b) = op {
                    fill(b, &mut self.0);
                }
            }
            Ok(())
        }
    }

    /// DRDY pin.
    pub struct Pin;
    impl PinErrorType for Pin {
        type Error = PinErrorKind;
    }
    impl InputPin for Pin {
        fn is_high(&mut self) -> Result<bool, PinErrorKind> {
            if fail() {
                return Err(PinErrorKind::Other);
            }
            // SAFETY: as in `rx`.
            Ok(unsafe { core::ptr::read_volatile(&raw const LEVEL) } != 0)
        }
        fn is_low(&mut self) -> Result<bool, PinErrorKind> {
            self.is_high().map(|h| !h)
        }
    }
}

#[entry]
fn main() -> ! {
    let mut cals = vectors::calibrations();
    let mut flashed = bins_comp::Pipeline::uncalibrated();
    if let Ok((pipeline, _)) = calib::calibration(&calib::read_region(), 1.0e-3) {
        cals[vectors::FLASHED_VARIANT] = *pipeline.calibration();
        flashed = pipeline;
    }
    let vib_pipeline = bins_comp::Pipeline::new(
        cals.get(1).copied().unwrap_or(bins_comp::Calibration::uncalibrated()),
        vectors::vibration_config(bins_comp::Variant::Exact),
    );
    let mut vib_state = bins_comp::PipelineState::<f32, 16>::new();
    // The flight sample source behind the sampling interrupt's body, as the firmware boots it.
    let adc = bins_comp::drivers::Ads131m04::new(bus::Spi::default(), bus::Pin, Default::default());
    let temp = bins_comp::drivers::Tmp117::new(bus::Bus::default(), Default::default());
    let source = bins_comp::drivers::SampleSource::init(adc, temp, Default::default(), Default::default());
    let (adc_ok, temp_ok) = (source.adc_ready(), source.temp_ready());
    // SAFETY: the only reference ever taken to the queue; its halves are then owned by the
    // interrupt's state and the consumer below.
    let Some(queue) = (unsafe { (&raw mut QUEUE_ISR).as_mut() }) else { semihosting::process::exit(1) };
    let (producer, mut consumer) = queue.split();
    let mut isr = isr::Isr::new(flashed, Slots(source), producer);
    // SAFETY: as for `OUTPUT` below.
    unsafe {
        core::ptr::write_volatile(
            &raw mut OUTPUT,
            Output { accel_g: [0.0; 3], status: (adc_ok as u32) | (temp_ok as u32) << 1 },
        )
    };
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
        // The sampling interrupt's body, then the consumer.
        isr.on_tick();
        while let Some(s0) = consumer.dequeue() {
            // SAFETY: `OUTPUT` is a valid, aligned static, written by this code only; nothing
            // holds a reference to it.
            unsafe { core::ptr::write_volatile(&raw mut OUTPUT, Output { accel_g: s0.accel_g, status: s0.status.0 }) };
        }
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
