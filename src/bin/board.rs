//! The flight image's board layer: the ARM MPS2 AN386 peripherals the sensors and the output
//! link are wired to, register-level, each behind the embedded-hal 1.0 trait its driver takes.
//! This module owns every register access of the flight image (all its `unsafe`) and the
//! choice of which instance of each peripheral is used.
//!
//! | what | peripheral | base | trait |
//! |---|---|---|---|
//! | ADS131M04 (SPI mode 1) | PL022 SSP "Shield0 SPI" ([`Pl022`]) | 0x4002_6000 | [`SpiDevice<u8>`] |
//! | ADS131M04 DRDY | CMSDK AHB GPIO0, bit [`DRDY_BIT`] ([`DrdyPin`]) | 0x4001_0000 | [`InputPin`] |
//! | TMP117 | SBCon two-wire controller "Shield0 I2C" ([`SbCon`]) | 0x4002_9000 | [`I2c`] |
//! | output frames | CMSDK APB UART0 ([`Uart`]) | 0x4000_4000 | — |
//!
//! Addresses: ARM AN386 (the MPS2 FPGA image for Cortex-M4) memory map, as QEMU's
//! `mps2-an386` machine models it (`hw/arm/mps2.c`): the PL022s at 0x4002_0000 (APB),
//! 0x4002_1000 (LCD), 0x4002_5000 (ADC), 0x4002_6000 / 0x4002_7000 (Shield0 / Shield1); the
//! SBCon I²C controllers at 0x4002_2000 (touch), 0x4002_3000 (audio), 0x4002_9000 /
//! 0x4002_A000 (Shield0 / Shield1). The sensor board is taken to sit on shield header 0.
//!
//! Every wait on the hardware is bounded (a poll count, never a free-running loop) and ends in
//! an error: the sampling interrupt calls the SPI, pin and I²C code, and must return within
//! its slot whatever the bus does.
//!
//! # In QEMU
//!
//! No sensor is attached: the PL022 shifts in zeros (so every ADC frame fails its CRC), the
//! SBCon bus has no device (every address is not acknowledged), and the GPIO block is an
//! unimplemented device that reads 0 (so DRDY reads low, "data ready"). The UART's output is
//! what `-serial file:PATH` captures.

use core::convert::Infallible;
use core::sync::atomic::{AtomicBool, Ordering};
use embedded_hal::digital::{ErrorType as PinErrorType, InputPin};
use embedded_hal::i2c::{self, ErrorKind as I2cErrorKind, I2c, NoAcknowledgeSource, Operation as I2cOperation};
use embedded_hal::spi::{self, ErrorKind as SpiErrorKind, Operation as SpiOperation, SpiDevice};

/// Core and peripheral clock of the AN386 \[Hz\].
pub const CLOCK_HZ: u32 = 25_000_000;

/// One 32-bit device register.
#[derive(Clone, Copy)]
struct Reg(usize);

impl Reg {
    fn read(self) -> u32 {
        // SAFETY: every `Reg` is a constant address of a 32-bit register of the AN386
        // peripheral map above (4-byte aligned, always mapped, holding no Rust object), so a
        // volatile read aliases nothing; its only side effects are the device's own (popping
        // a receive FIFO), which the caller intends.
        unsafe { core::ptr::read_volatile(core::ptr::with_exposed_provenance::<u32>(self.0)) }
    }

    fn write(self, v: u32) {
        // SAFETY: as in `read`; the register is owned by the one driver struct of its
        // peripheral (`Board::take` hands each out once).
        unsafe { core::ptr::write_volatile(core::ptr::with_exposed_provenance_mut::<u32>(self.0), v) }
    }
}

/// The board's peripherals, each handed out once.
pub struct Board {
    /// The ADC's SPI.
    pub spi: Pl022,
    /// The ADC's data-ready line.
    pub drdy: DrdyPin,
    /// The temperature sensor's bus.
    pub i2c: SbCon,
    /// The output link.
    pub uart: Uart,
}

/// Set once [`Board::take`] has handed out the peripherals.
static TAKEN: AtomicBool = AtomicBool::new(false);

impl Board {
    /// The peripherals, configured (SPI mode 1 at [`SPI_CLOCK_HZ`], DRDY as a GPIO input, the
    /// I²C bus idle, the UART transmitting at [`UART_BAUD`]); `None` after the first call.
    pub fn take() -> Option<Board> {
        if TAKEN.swap(true, Ordering::AcqRel) {
            return None;
        }
        Some(Board { spi: Pl022::init(), drdy: DrdyPin::init(), i2c: SbCon::init(), uart: Uart::init() })
    }
}

// ---- SPI: ARM PrimeCell PL022 SSP ---------------------------------------------------------

/// Base of the PL022 the ADC is on: Shield0 SPI.
const SSP_BASE: usize = 0x4002_6000;
/// SSPCR0: data size, frame format, clock polarity/phase, serial clock rate.
const SSP_CR0: Reg = Reg(SSP_BASE);
/// SSPCR1: loop back, enable, master/slave.
const SSP_CR1: Reg = Reg(SSP_BASE + 0x04);
/// SSPDR: writes push the transmit FIFO, reads pop the receive FIFO.
const SSP_DR: Reg = Reg(SSP_BASE + 0x08);
/// SSPSR: FIFO and busy flags.
const SSP_SR: Reg = Reg(SSP_BASE + 0x0C);
/// SSPCPSR: clock prescale divisor (even, 2..=254).
const SSP_CPSR: Reg = Reg(SSP_BASE + 0x10);
/// SSPIMSC: interrupt masks (all masked: the driver polls).
const SSP_IMSC: Reg = Reg(SSP_BASE + 0x14);
/// CR0.DSS = 0111b: 8-bit frames.
const CR0_DSS_8: u32 = 0b0111;
/// CR0.SPH: data captured on the second clock edge (SPI mode 1 with SPO = 0).
const CR0_SPH: u32 = 1 << 7;
/// CR1.SSE: port enabled (CR1.MS = 0: master).
const CR1_SSE: u32 = 1 << 1;
/// SR.TNF: transmit FIFO not full.
const SR_TNF: u32 = 1 << 1;
/// SR.RNE: receive FIFO not empty.
const SR_RNE: u32 = 1 << 2;
/// Depth of the PL022's transmit and receive FIFOs.
const SSP_FIFO: usize = 8;
/// The SPI clock \[Hz\]: 6.25 MHz (the ADS131M04 takes up to 25 MHz; one 18-byte frame takes
/// 23 µs).
const SPI_CLOCK_HZ: u32 = 6_250_000;
/// Clock prescale divisor: SSPCLKOUT = [`CLOCK_HZ`] / (CPSDVSR × (1 + SCR)), SCR = 0.
const SSP_CPSDVSR: u32 = CLOCK_HZ / SPI_CLOCK_HZ;
/// Status polls without progress before a transfer is abandoned: at the SPI clock, a byte
/// takes 32 core cycles, far fewer than these polls.
const SSP_POLLS: u32 = 1_000;

/// The ADC's SPI device on the PL022.
///
/// Chip select is the PL022's own frame signal SSPFSSOUT, wired to the ADC's /CS. In the
/// Motorola format with SPH = 1 the PL022 holds it low across back-to-back bytes and releases
/// it when the transmit FIFO runs empty. A transaction is therefore streamed with up to
/// [`SSP_FIFO`] bytes in flight (write DR while the transmit FIFO has room, read DR whenever
/// the receive FIFO has a byte), so the FIFO does not run dry between its bytes and /CS frames
/// exactly one transaction, as long as the loop is not held up for longer than the bytes in
/// flight take to shift out (10 µs at [`SPI_CLOCK_HZ`]): it runs in the sampling interrupt,
/// which nothing preempts, or at boot before interrupts start. A delay operation inside a
/// transaction cannot keep /CS low on this controller and is refused
/// ([`SpiErrorKind::Other`]), before any byte is sent.
pub struct Pl022(());

impl Pl022 {
    fn init() -> Self {
        SSP_CR1.write(0);
        SSP_CR0.write(CR0_DSS_8 | CR0_SPH);
        SSP_CPSR.write(SSP_CPSDVSR);
        SSP_IMSC.write(0);
        let p = Pl022(());
        p.drain();
        SSP_CR1.write(CR1_SSE);
        p
    }

    /// Empties the receive FIFO (bounded).
    fn drain(&self) {
        for _ in 0..SSP_FIFO * 2 {
            if SSP_SR.read() & SR_RNE == 0 {
                break;
            }
            let _ = SSP_DR.read();
        }
    }
}

/// Bytes an SPI operation clocks.
fn spi_op_len(op: &SpiOperation<'_, u8>) -> usize {
    match op {
        SpiOperation::Read(b) | SpiOperation::TransferInPlace(b) => b.len(),
        SpiOperation::Write(b) => b.len(),
        SpiOperation::Transfer(r, w) => r.len().max(w.len()),
        SpiOperation::DelayNs(_) => 0,
    }
}

/// A position in the byte stream of a transaction: operation and byte within it.
#[derive(Default)]
struct Cursor {
    op: usize,
    at: usize,
}

impl Cursor {
    /// Moves to the next byte that exists; the operation index and offset of that byte.
    fn next(&mut self, ops: &[SpiOperation<'_, u8>]) -> Option<(usize, usize)> {
        while let Some(op) = ops.get(self.op) {
            if self.at < spi_op_len(op) {
                let here = (self.op, self.at);
                self.at += 1;
                return Some(here);
            }
            self.op += 1;
            self.at = 0;
        }
        None
    }
}

impl spi::ErrorType for Pl022 {
    type Error = SpiErrorKind;
}

impl SpiDevice<u8> for Pl022 {
    fn transaction(&mut self, ops: &mut [SpiOperation<'_, u8>]) -> Result<(), SpiErrorKind> {
        if ops.iter().any(|op| matches!(op, SpiOperation::DelayNs(ns) if *ns > 0)) {
            return Err(SpiErrorKind::Other);
        }
        let total = ops.iter().fold(0usize, |n, op| n.saturating_add(spi_op_len(op)));
        let (mut tx, mut rx) = (Cursor::default(), Cursor::default());
        let (mut sent, mut received, mut idle) = (0usize, 0usize, 0u32);
        while received < total {
            let sr = SSP_SR.read();
            let mut progress = false;
            if sent < total && sent - received < SSP_FIFO && sr & SR_TNF != 0 {
                // Read and Transfer beyond its write buffer clock out zeros.
                let byte = tx.next(ops).and_then(|(o, i)| match ops.get(o)? {
                    SpiOperation::Write(w) | SpiOperation::Transfer(_, w) => w.get(i).copied(),
                    SpiOperation::TransferInPlace(b) => b.get(i).copied(),
                    SpiOperation::Read(_) | SpiOperation::DelayNs(_) => None,
                });
                SSP_DR.write(u32::from(byte.unwrap_or(0)));
                sent += 1;
                progress = true;
            }
            if sr & SR_RNE != 0 {
                let byte = SSP_DR.read() as u8;
                if let Some((o, i)) = rx.next(ops) {
                    let slot = match ops.get_mut(o) {
                        Some(
                            SpiOperation::Read(r) | SpiOperation::Transfer(r, _) | SpiOperation::TransferInPlace(r),
                        ) => r.get_mut(i),
                        _ => None,
                    };
                    if let Some(slot) = slot {
                        *slot = byte;
                    }
                }
                received += 1;
                progress = true;
            }
            if progress {
                idle = 0;
            } else {
                idle += 1;
                if idle > SSP_POLLS {
                    self.drain();
                    return Err(SpiErrorKind::Other);
                }
            }
        }
        Ok(())
    }
}

// ---- DRDY: CMSDK AHB GPIO -----------------------------------------------------------------

/// Base of GPIO0.
const GPIO0_BASE: usize = 0x4001_0000;
/// DATA: the pins' levels.
const GPIO_DATA: Reg = Reg(GPIO0_BASE);
/// OUTENABLECLR: writing 1 makes a pin an input.
const GPIO_OUTENCLR: Reg = Reg(GPIO0_BASE + 0x14);
/// ALTFUNCCLR: writing 1 gives a pin to the GPIO block (not its alternate function).
const GPIO_ALTFUNCCLR: Reg = Reg(GPIO0_BASE + 0x1C);
/// The GPIO0 bit the ADC's /DRDY output is wired to.
pub const DRDY_BIT: u32 = 0;

/// The ADC's /DRDY line (low: a conversion waits to be read). In QEMU the GPIO block is not
/// modelled and reads 0: DRDY always low, data always "ready".
pub struct DrdyPin(());

impl DrdyPin {
    fn init() -> Self {
        GPIO_ALTFUNCCLR.write(1 << DRDY_BIT);
        GPIO_OUTENCLR.write(1 << DRDY_BIT);
        DrdyPin(())
    }
}

impl PinErrorType for DrdyPin {
    type Error = Infallible;
}

impl InputPin for DrdyPin {
    fn is_high(&mut self) -> Result<bool, Infallible> {
        Ok(GPIO_DATA.read() & (1 << DRDY_BIT) != 0)
    }

    fn is_low(&mut self) -> Result<bool, Infallible> {
        self.is_high().map(|h| !h)
    }
}

// ---- I²C: SBCon two-wire controller (bit-banged) ------------------------------------------

/// Base of the SBCon the temperature sensor is on: Shield0 I2C.
const SBCON_BASE: usize = 0x4002_9000;
/// CONTROL (read): the lines' levels; CONTROLS (write): 1 bits release (set) the lines.
const SB_CONTROL: Reg = Reg(SBCON_BASE);
/// CONTROLC (write): 1 bits pull (clear) the lines low.
const SB_CONTROLC: Reg = Reg(SBCON_BASE + 0x04);
/// SCL bit of the SBCon registers.
const SB_SCL: u32 = 1 << 0;
/// SDA bit of the SBCon registers.
const SB_SDA: u32 = 1 << 1;
/// Core cycles of the pause after each line change: 20 cycles = 0.8 µs at 25 MHz. A bit
/// holds SCL low for two pauses (1.6 µs ≥ fast mode's t_LOW of 1.3 µs) and high for one
/// (0.8 µs ≥ t_HIGH 0.6 µs): with the register accesses, SCL runs at about 330 kHz, and one
/// TMP117 register read (45 bits) takes about 0.14 ms.
const I2C_PAUSE_CYCLES: u32 = 20;
/// Polls of a released SCL before a device stretching the clock is given up on.
const I2C_STRETCH_POLLS: u32 = 1_000;

/// The temperature sensor's I²C bus on the SBCon: a register whose two bits drive SCL and SDA
/// open-drain (write 1 to CONTROLS to release a line, to CONTROLC to pull it low) and read
/// their levels back; start, stop, bytes and acknowledges are bit-banged here. SCL is read
/// back after every release, so a device stretching the clock is waited for (bounded); a
/// released SDA read low while sending is a lost arbitration.
///
/// A transaction follows embedded-hal's contract: a start and the address before the first
/// operation and before each operation whose direction differs from the previous one
/// (repeated start), the last byte read before a direction change or the end not
/// acknowledged, a stop at the end, and a stop after any error.
pub struct SbCon(());

impl SbCon {
    fn init() -> Self {
        SB_CONTROL.write(SB_SCL | SB_SDA);
        SbCon(())
    }

    fn pause() {
        cortex_m::asm::delay(I2C_PAUSE_CYCLES);
    }

    fn sda(high: bool) {
        if high {
            SB_CONTROL.write(SB_SDA)
        } else {
            SB_CONTROLC.write(SB_SDA)
        }
        Self::pause();
    }

    fn sda_is_high() -> bool {
        SB_CONTROL.read() & SB_SDA != 0
    }

    fn scl_low() {
        SB_CONTROLC.write(SB_SCL);
        Self::pause();
    }

    /// Releases SCL and waits until it reads high.
    fn scl_high() -> Result<(), I2cErrorKind> {
        SB_CONTROL.write(SB_SCL);
        let mut polls = 0;
        while SB_CONTROL.read() & SB_SCL == 0 {
            polls += 1;
            if polls > I2C_STRETCH_POLLS {
                return Err(I2cErrorKind::Other);
            }
        }
        Self::pause();
        Ok(())
    }

    /// A start (from idle) or repeated start (SCL low): SDA falls while SCL is high.
    fn start() -> Result<(), I2cErrorKind> {
        Self::sda(true);
        Self::scl_high()?;
        if !Self::sda_is_high() {
            return Err(I2cErrorKind::ArbitrationLoss);
        }
        Self::sda(false);
        Self::scl_low();
        Ok(())
    }

    /// A stop: SDA rises while SCL is high; the bus is then idle.
    fn stop() -> Result<(), I2cErrorKind> {
        Self::sda(false);
        Self::scl_high()?;
        Self::sda(true);
        if Self::sda_is_high() { Ok(()) } else { Err(I2cErrorKind::Bus) }
    }

    /// One bit: SDA pulled low (`false`) or released (`true`) while SCL is low, SCL released
    /// (a stretched clock waited for), SDA sampled, SCL pulled low again. Returns the level
    /// sampled. Every bit of a byte and of its acknowledge is one of these.
    #[inline(never)]
    fn clock_bit(sda_high: bool) -> Result<bool, I2cErrorKind> {
        Self::sda(sda_high);
        Self::scl_high()?;
        let level = Self::sda_is_high();
        Self::scl_low();
        Ok(level)
    }

    /// Sends one byte MSB first and reads the acknowledge bit; `Err(NoAcknowledge(source))`
    /// if the device left SDA high.
    #[cfg_attr(unstable_target, optimize(size))]
    fn write_byte(byte: u8, source: NoAcknowledgeSource) -> Result<(), I2cErrorKind> {
        for i in (0..8).rev() {
            let bit = byte & (1 << i) != 0;
            if Self::clock_bit(bit)? != bit {
                return Err(I2cErrorKind::ArbitrationLoss);
            }
        }
        if Self::clock_bit(true)? { Err(I2cErrorKind::NoAcknowledge(source)) } else { Ok(()) }
    }

    /// Reads one byte MSB first, then acknowledges it (`ack`: SDA low) or not.
    #[cfg_attr(unstable_target, optimize(size))]
    fn read_byte(ack: bool) -> Result<u8, I2cErrorKind> {
        let mut v = 0u8;
        for _ in 0..8 {
            v = (v << 1) | u8::from(Self::clock_bit(true)?);
        }
        Self::clock_bit(!ack)?;
        Ok(v)
    }

    /// The operations between the first start and the stop.
    #[cfg_attr(unstable_target, optimize(size))]
    fn run(address: u8, ops: &mut [I2cOperation<'_>]) -> Result<(), I2cErrorKind> {
        let mut reading = None;
        for k in 0..ops.len() {
            let is_read = matches!(ops.get(k), Some(I2cOperation::Read(_)));
            if reading != Some(is_read) {
                Self::start()?;
                Self::write_byte((address << 1) | u8::from(is_read), NoAcknowledgeSource::Address)?;
                reading = Some(is_read);
            }
            // A read's last byte is acknowledged only if the next read operation with bytes
            // follows without a direction change.
            let more_reads = ops
                .get(k + 1..)
                .unwrap_or(&[])
                .iter()
                .take_while(|op| matches!(op, I2cOperation::Read(_)))
                .any(|op| matches!(op, I2cOperation::Read(b) if !b.is_empty()));
            match ops.get_mut(k) {
                Some(I2cOperation::Read(buf)) => {
                    let n = buf.len();
                    for (i, b) in buf.iter_mut().enumerate() {
                        *b = Self::read_byte(i + 1 < n || more_reads)?;
                    }
                }
                Some(I2cOperation::Write(buf)) => {
                    for &b in buf.iter() {
                        Self::write_byte(b, NoAcknowledgeSource::Data)?;
                    }
                }
                None => {}
            }
        }
        Ok(())
    }
}

impl i2c::ErrorType for SbCon {
    type Error = I2cErrorKind;
}

impl I2c for SbCon {
    #[cfg_attr(unstable_target, optimize(size))]
    fn transaction(&mut self, address: u8, ops: &mut [I2cOperation<'_>]) -> Result<(), I2cErrorKind> {
        if address > 0x7F {
            return Err(I2cErrorKind::Other);
        }
        if ops.is_empty() {
            return Ok(());
        }
        let r = Self::run(address, ops);
        let stopped = Self::stop();
        r.and(stopped)
    }
}

// ---- output link: CMSDK APB UART ----------------------------------------------------------

/// Base of UART0.
const UART_BASE: usize = 0x4000_4000;
/// DATA: writing sends a byte.
const UART_DATA: Reg = Reg(UART_BASE);
/// STATE: bit 0 transmit buffer full.
const UART_STATE: Reg = Reg(UART_BASE + 0x04);
/// CTRL: bit 0 transmit enable.
const UART_CTRL: Reg = Reg(UART_BASE + 0x08);
/// BAUDDIV: baud rate = [`CLOCK_HZ`] / BAUDDIV, at least 16.
const UART_BAUDDIV: Reg = Reg(UART_BASE + 0x10);
/// STATE.TXFULL.
const UART_TX_FULL: u32 = 1 << 0;
/// CTRL.TXEN.
const UART_TX_EN: u32 = 1 << 0;
/// The link's rate \[Bd\]: 1 MBd, 8N1 (the UART's only format): 100 kB/s, four times the
/// 24 kB/s of the sample frames at 1 kHz.
const UART_BAUD: u32 = 1_000_000;
/// Baud rate divisor: 25.
const UART_DIV: u32 = CLOCK_HZ / UART_BAUD;
/// Polls of a full transmit buffer before a byte is given up on: one byte takes 250 core
/// cycles at 1 MBd.
const UART_POLLS: u32 = 10_000;

/// The transmitter stayed full for [`UART_POLLS`] polls.
#[derive(Debug)]
pub struct TxStuck;

/// UART0, transmit only; its one-byte buffer is polled.
pub struct Uart(());

impl Uart {
    fn init() -> Self {
        UART_BAUDDIV.write(UART_DIV);
        UART_CTRL.write(UART_TX_EN);
        Uart(())
    }

    /// Sends `bytes` in order; stops at the first byte the transmitter does not take in time.
    /// Out of line and not unrolled: the link is not on the per-sample path.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn write_all(&mut self, bytes: &[u8]) -> Result<(), TxStuck> {
        for &b in bytes {
            let mut polls = 0;
            while UART_STATE.read() & UART_TX_FULL != 0 {
                polls += 1;
                if polls > UART_POLLS {
                    return Err(TxStuck);
                }
            }
            UART_DATA.write(u32::from(b));
        }
        Ok(())
    }
}
