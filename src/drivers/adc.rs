//! Driver of the TI ADS131M04, the 4-channel, simultaneous-sampling, 24-bit delta-sigma ADC
//! that digitises the three accelerometer signals. This module owns the device's SPI frame
//! format, its CRC, its command and register encodings, the conversion of its codes to volts,
//! and the driver ([`Ads131m04`]) over an embedded-hal 1.0 [`SpiDevice`] and the DRDY
//! [`InputPin`].
//!
//! # Source
//!
//! Texas Instruments, *ADS131M04 4-Channel, Simultaneously-Sampling, 24-Bit, Delta-Sigma ADC*,
//! data sheet SBAS890D (revised May 2021); the ADS131M04-Q1 data sheet has the same section,
//! table and figure numbers. Subsections are cited by number where that is settled and
//! otherwise by title (titles are stable across revisions).
//!
//! # What the driver relies on
//!
//! - 24-bit words, the reset default (WLENGTH = 01b, §8.5.1.8 *SPI Communication Words*): one
//!   frame is [`FRAME_WORDS`] words of [`WORD_BYTES`] bytes, 16-bit contents (commands,
//!   responses, registers, CRC) MSB-aligned and zero-padded in the low byte.
//! - The typical frame of §8.5.1.7 *SPI Communication Frames* (Figure 8-18): on DIN the command
//!   word, the input CRC word (or a zero word when input CRC is off) and zeros; on DOUT the
//!   response to the *previous* frame's command, the four channel words and the output CRC
//!   word, which the device always sends (*Cyclic Redundancy Check (CRC)*).
//! - CRC-CCITT (MODE.CRC_TYPE = 0): polynomial x¹⁶ + x¹² + x⁵ + 1 (0x1021), seed 0xFFFF, over
//!   every byte of the words before the CRC word, padding included (*Cyclic Redundancy
//!   Check (CRC)*, Table 8-7).
//! - DRDY in level format (MODE.DRDY_FMT = 0), asserted low while new data wait to be read,
//!   released by reading them (*Data Ready (DRDY)*); DRDY_SEL = 00b, so it asserts
//!   when the most lagging enabled channel has converted.
//!
//! [`Ads131m04::init`] writes MODE, CLOCK and GAIN1 so that every one of these holds whatever
//! state the device was in, and leaves a NULL command as the last one sent, so that every
//! later frame's response word is the STATUS register (§8.5.1.10.1 *NULL*).

use embedded_hal::digital::InputPin;
use embedded_hal::spi::SpiDevice;
use fixed::types::I9F23;

/// Bytes per SPI word at the 24-bit word size (§8.5.1.8).
pub const WORD_BYTES: usize = 3;
/// Number of ADC channels of the ADS131M04.
pub const CHANNELS: usize = 4;
/// Words per frame: response, one word per channel, CRC (§8.5.1.7, Figure 8-18).
pub const FRAME_WORDS: usize = 1 + CHANNELS + 1;
/// Bytes per frame at the 24-bit word size.
pub const FRAME_BYTES: usize = FRAME_WORDS * WORD_BYTES;
/// Internal reference: the full-scale range is ±`VREF_V`/gain (*ADC Conversion Data*,
/// Table 8-10: FSR = 1.2 V / Gain).
pub const VREF_V: f32 = 1.2;

/// Command words (§8.5.1.10 *Commands*, Table 8-11).
pub mod cmd {
    /// NULL: no operation; the next frame's response is the STATUS register (§8.5.1.10.1).
    pub const NULL: u16 = 0x0000;
    /// RESET: back to the register defaults (Table 8-11).
    pub const RESET: u16 = 0x0011;
    /// Response to RESET in the next frame, for the 4-channel part (Table 8-11).
    pub const RESET_RESPONSE: u16 = 0xFF24;
    /// STANDBY; acknowledged with the same word (Table 8-11).
    pub const STANDBY: u16 = 0x0022;
    /// WAKEUP; acknowledged with the same word (Table 8-11).
    pub const WAKEUP: u16 = 0x0033;

    /// RREG `101a aaaa annn nnnn`: read `count` registers from `addr` (6-bit address, count
    /// 1..=128 encoded as count − 1; Table 8-11). For one register the next frame's response
    /// word is the register's content.
    pub const fn rreg(addr: u8, count: u8) -> u16 {
        0xA000 | ((addr as u16 & 0x3F) << 7) | (count.wrapping_sub(1) as u16 & 0x7F)
    }

    /// WREG `011a aaaa annn nnnn`: write `count` registers from `addr` (Table 8-11).
    pub const fn wreg(addr: u8, count: u8) -> u16 {
        0x6000 | ((addr as u16 & 0x3F) << 7) | (count.wrapping_sub(1) as u16 & 0x7F)
    }

    /// Acknowledgement of a WREG in the next frame, `010a aaaa ammm mmmm` with `mmm mmmm` the
    /// number of registers actually written minus one (Table 8-11, note 2).
    pub const fn wreg_ack(addr: u8, written: u8) -> u16 {
        0x4000 | ((addr as u16 & 0x3F) << 7) | (written.wrapping_sub(1) as u16 & 0x7F)
    }
}

/// Register addresses (§8.6 *Register Map*, Table 8-12).
pub mod reg {
    /// ID, read-only, `0x24xx` on the ADS131M04 (§8.6, ID register).
    pub const ID: u8 = 0x00;
    /// STATUS, read-only, reset 0x0500; bits in [`status`](super::status).
    pub const STATUS: u8 = 0x01;
    /// MODE, reset 0x0510; bits in [`mode`](super::mode).
    pub const MODE: u8 = 0x02;
    /// CLOCK, reset 0x0F0E: channel enables, OSR, power mode.
    pub const CLOCK: u8 = 0x03;
    /// GAIN1, reset 0x0000: PGA gains of channels 0–3.
    pub const GAIN1: u8 = 0x04;
}

/// The ID register of an ADS131M04 with its revision byte masked: bits 15:12 = 0010b,
/// CHANCNT\[11:8\] = 4 (§8.6, ID register).
pub const ID_MASK: u16 = 0xFF00;
/// Expected value of `ID & ID_MASK`.
pub const ID_EXPECTED: u16 = 0x2400;

/// STATUS register bits (§8.6, STATUS register field descriptions).
pub mod status {
    /// SPI interface locked.
    pub const LOCK: u16 = 1 << 15;
    /// Resynchronisation fault.
    pub const F_RESYNC: u16 = 1 << 14;
    /// Register-map CRC fault (only with MODE.REG_CRC_EN).
    pub const REG_MAP: u16 = 1 << 13;
    /// The previous input frame's CRC was wrong (only with MODE.RX_CRC_EN).
    pub const CRC_ERR: u16 = 1 << 12;
    /// CRC type: 0 = CCITT, 1 = ANSI.
    pub const CRC_TYPE: u16 = 1 << 11;
    /// A reset has occurred since MODE.RESET was last cleared.
    pub const RESET: u16 = 1 << 10;
    /// Word length field WLENGTH\[1:0\].
    pub const WLENGTH_MASK: u16 = 0b11 << 8;
    /// WLENGTH = 01b: 24-bit words.
    pub const WLENGTH_24: u16 = 0b01 << 8;
    /// Reserved bits 7:4, zero on the 4-channel part.
    pub const RESERVED_MASK: u16 = 0xF0;
    /// DRDY\[3:0\]: channel n has new data.
    pub const DRDY_MASK: u16 = 0x0F;

    /// The bits [`Ads131m04`](super::Ads131m04) checks in every data frame: all but DRDY\[3:0\].
    pub const CHECK_MASK: u16 = !DRDY_MASK;
    /// Their value in a healthy frame after [`init`](super::Ads131m04::init): unlocked, no
    /// fault, CCITT CRC, no reset since init, 24-bit words.
    pub const CHECK_EXPECTED: u16 = WLENGTH_24;
}

/// MODE register bits (§8.6, MODE register field descriptions).
pub mod mode {
    /// Register-map CRC enable.
    pub const REG_CRC_EN: u16 = 1 << 13;
    /// Input (DIN) CRC enable.
    pub const RX_CRC_EN: u16 = 1 << 12;
    /// CRC type: 0 = CCITT (used here), 1 = ANSI.
    pub const CRC_TYPE: u16 = 1 << 11;
    /// Reset flag; writing 0 clears STATUS.RESET.
    pub const RESET: u16 = 1 << 10;
    /// WLENGTH = 01b: 24-bit words.
    pub const WLENGTH_24: u16 = 0b01 << 8;
    /// SPI timeout enable.
    pub const TIMEOUT: u16 = 1 << 4;
    /// DRDY_SEL\[1:0\] = 00b: DRDY follows the most lagging enabled channel.
    pub const DRDY_SEL_LAGGING: u16 = 0b00 << 2;
    /// DRDY_HiZ: 0 = DRDY driven high when inactive.
    pub const DRDY_HIZ: u16 = 1 << 1;
    /// DRDY_FMT: 0 = level (asserted low until the data are read), 1 = pulse.
    pub const DRDY_FMT_PULSE: u16 = 1 << 0;
}

/// PGA gain of one channel: GAIN1.PGAGAINn\[2:0\], gain = 2^code (§8.6, GAIN1 register).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Gain {
    /// ×1, full scale ±1.2 V.
    #[default]
    X1 = 0,
    /// ×2.
    X2 = 1,
    /// ×4.
    X4 = 2,
    /// ×8.
    X8 = 3,
    /// ×16.
    X16 = 4,
    /// ×32.
    X32 = 5,
    /// ×64.
    X64 = 6,
    /// ×128.
    X128 = 7,
}

impl Gain {
    /// The 3-bit field value.
    pub const fn code(self) -> u16 {
        self as u16
    }
    /// The gain as a number (a power of two, so dividing by it is exact).
    pub const fn factor(self) -> f32 {
        (1u32 << self as u32) as f32
    }
    /// Full-scale range FSR = 1.2 V / gain (Table 8-10).
    pub fn full_scale_v(self) -> f32 {
        VREF_V / self.factor()
    }
}

/// Oversampling ratio: CLOCK.OSR\[2:0\] (§8.6, CLOCK register). The output data rate is
/// f_MOD / OSR with f_MOD = CLKIN / 2 (4.096 MHz at the nominal 8.192 MHz CLKIN).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Osr {
    /// 128 (32 kSPS at 8.192 MHz).
    R128 = 0,
    /// 256 (16 kSPS).
    R256 = 1,
    /// 512 (8 kSPS).
    R512 = 2,
    /// 1024 (4 kSPS), the reset default.
    #[default]
    R1024 = 3,
    /// 2048 (2 kSPS).
    R2048 = 4,
    /// 4096 (1 kSPS).
    R4096 = 5,
    /// 8192 (500 SPS).
    R8192 = 6,
    /// 16256 (≈252 SPS).
    R16256 = 7,
}

/// Power mode: CLOCK.PWR\[1:0\] (§8.6, CLOCK register).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PowerMode {
    /// Very-low-power.
    VeryLowPower = 0,
    /// Low-power.
    LowPower = 1,
    /// High-resolution, the reset default.
    #[default]
    HighResolution = 2,
}

/// What [`Ads131m04::init`] programs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Config {
    /// PGA gain per channel (channels 0, 1, 2 carry the x, y, z signals).
    pub gains: [Gain; CHANNELS],
    /// Oversampling ratio (sets the data rate).
    pub osr: Osr,
    /// Power mode.
    pub power: PowerMode,
    /// Also convert channel 3 (unused by [`Ads131m04::read_signals_v`]; off saves power).
    pub enable_ch3: bool,
    /// Send an input CRC word in every frame (MODE.RX_CRC_EN), so that a corrupted command is
    /// not executed by the device.
    pub input_crc: bool,
}

impl Config {
    /// The MODE value: 24-bit words, CCITT CRC, RESET flag cleared, SPI timeout on, DRDY level
    /// format following the most lagging channel, RX_CRC_EN as configured.
    pub const fn mode_word(&self) -> u16 {
        let crc = if self.input_crc { mode::RX_CRC_EN } else { 0 };
        crc | mode::WLENGTH_24 | mode::TIMEOUT | mode::DRDY_SEL_LAGGING
    }
    /// The CLOCK value: CH0–CH2 (and CH3 if enabled) on in bits 8–11, OSR in bits 4:2, PWR in
    /// bits 1:0 (§8.6, CLOCK register).
    pub const fn clock_word(&self) -> u16 {
        let ch = if self.enable_ch3 { 0b1111 } else { 0b0111 };
        (ch << 8) | ((self.osr as u16) << 2) | self.power as u16
    }
    /// The GAIN1 value: PGAGAIN3 in bits 14:12, PGAGAIN2 10:8, PGAGAIN1 6:4, PGAGAIN0 2:0
    /// (§8.6, GAIN1 register).
    pub const fn gain1_word(&self) -> u16 {
        let [g0, g1, g2, g3] = self.gains;
        (g3.code() << 12) | (g2.code() << 8) | (g1.code() << 4) | g0.code()
    }
}

/// What went wrong talking to the ADC. `SE` is the SPI device's error, `PE` the DRDY pin's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error<SE, PE> {
    /// The SPI transfer failed.
    Spi(SE),
    /// Reading the DRDY pin failed.
    Pin(PE),
    /// The output frame's CRC word does not match the CRC of its other words.
    Crc {
        /// CRC computed over the received response and channel words.
        expected: u16,
        /// CRC word received.
        got: u16,
    },
    /// No new conversion: DRDY not asserted when a sample was due, or the STATUS word's DRDY
    /// bits of channels 0–2 not all set.
    NotReady,
    /// The STATUS word reports a fault or a state the driver did not set up (lock, resync or
    /// CRC fault, an unexpected reset, another word length or CRC type); the word is included.
    BadStatus(u16),
    /// A command was not acknowledged as Table 8-11 says.
    UnexpectedResponse {
        /// Acknowledgement expected.
        expected: u16,
        /// Response word received.
        got: u16,
    },
    /// The ID register does not identify an ADS131M04; its value is included.
    WrongDevice(u16),
}

/// One output frame, split into its words (§8.5.1.7, Figure 8-18).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Frame {
    /// Response to the previous frame's command (the STATUS register after a NULL).
    pub response: u16,
    /// The four channels' 24-bit two's-complement codes, sign-extended.
    pub codes: [i32; CHANNELS],
    /// The CRC word as received (already checked by [`parse_frame`]).
    pub crc: u16,
}

/// CRC-16-CCITT as the device computes it: polynomial 0x1021, seed 0xFFFF, MSB first, no
/// reflection, no final XOR (*Cyclic Redundancy Check (CRC)*, Table 8-7). Continue a running CRC with
/// [`crc16_ccitt_update`].
pub fn crc16_ccitt(bytes: &[u8]) -> u16 {
    crc16_ccitt_update(0xFFFF, bytes)
}

/// The CRC-16-CCITT register after shifting in four zero bits from `n << 12`: the step
/// [`crc16_ccitt_update`] takes per nibble. 32 bytes, where a byte-wise table takes 512.
const CRC16_NIBBLE: [u16; 16] = {
    let mut table = [0u16; 16];
    let mut n = 0;
    while n < 16 {
        let mut crc = (n as u16) << 12;
        let mut bit = 0;
        while bit < 4 {
            crc = if crc & 0x8000 != 0 { (crc << 1) ^ 0x1021 } else { crc << 1 };
            bit += 1;
        }
        table[n] = crc;
        n += 1;
    }
    table
};

/// Feeds `bytes` into the running CRC `crc` (see [`crc16_ccitt`]), four bits per step. One
/// small out-of-line copy, optimised for size, serves the ADC frames (15 bytes) and the
/// output link (22 bytes).
#[inline(never)]
#[cfg_attr(unstable_target, optimize(size))]
pub fn crc16_ccitt_update(mut crc: u16, bytes: &[u8]) -> u16 {
    let step = |crc: u16, nibble: u8| (crc << 4) ^ CRC16_NIBBLE[usize::from(((crc >> 12) as u8 ^ nibble) & 0x0f)];
    for &b in bytes {
        crc = step(step(crc, b >> 4), b & 0x0f);
    }
    crc
}

/// A 24-bit two's-complement code (MSB first) sign-extended to `i32` (*ADC Conversion Data*).
pub fn code_from_bytes(w: [u8; WORD_BYTES]) -> i32 {
    // Place the code in the top 24 bits, then shift back arithmetically.
    let [a, b, c] = w;
    i32::from_be_bytes([a, b, c, 0]) >> 8
}

/// The 16-bit content of a command, response, register or CRC word: its two most significant
/// bytes (§8.5.1.8).
pub fn word16(w: [u8; WORD_BYTES]) -> u16 {
    let [a, b, _] = w;
    u16::from_be_bytes([a, b])
}

/// A code as the fraction of full scale it stands for: the 24-bit code read as a signed fixed
/// number with 23 fractional bits, in [−1, 1 − 2⁻²³] (Table 8-10: code 1 ↔ FSR/2²³,
/// 0x800000 ↔ −FSR). Codes outside 24 bits are saturated to that range.
pub fn code_to_fraction(code: i32) -> I9F23 {
    I9F23::from_bits(code.clamp(-(1 << 23), (1 << 23) - 1))
}

/// A code in volts at the input pins: `fraction × 1.2 V / gain` (Table 8-10). The fraction is
/// exact in `f32` (24 significant bits) and the gain a power of two, so the result is within
/// one ulp of the exact value: 1.2 V's own rounding to `f32` plus the product's.
pub fn code_to_volts(code: i32, gain: Gain) -> f32 {
    code_to_fraction(code).to_num::<f32>() * gain.full_scale_v()
}

/// The output CRC word disagrees with the CRC of the words before it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CrcMismatch {
    /// CRC computed over the received response and channel words.
    pub expected: u16,
    /// CRC word received.
    pub got: u16,
}

/// Splits a received frame into its words and checks its CRC.
pub fn parse_frame(rx: &[u8; FRAME_BYTES]) -> Result<Frame, CrcMismatch> {
    let mut words = [[0u8; WORD_BYTES]; FRAME_WORDS];
    for (w, c) in words.iter_mut().zip(rx.chunks_exact(WORD_BYTES)) {
        for (d, s) in w.iter_mut().zip(c) {
            *d = *s;
        }
    }
    let [response, c0, c1, c2, c3, crc_word] = words;
    let expected = [response, c0, c1, c2, c3].iter().fold(0xFFFF, |crc, w| crc16_ccitt_update(crc, w));
    let got = word16(crc_word);
    if expected != got {
        return Err(CrcMismatch { expected, got });
    }
    let codes = [c0, c1, c2, c3].map(code_from_bytes);
    Ok(Frame { response: word16(response), codes, crc: got })
}

/// An input frame: `command`, then the optional register data word, then the input CRC word
/// over everything before it when `input_crc` (§8.5.1.7, Figure 8-18), then zeros.
pub fn command_frame(command: u16, data: Option<u16>, input_crc: bool) -> [u8; FRAME_BYTES] {
    let mut tx = [0u8; FRAME_BYTES];
    [tx[0], tx[1]] = command.to_be_bytes();
    match data {
        None if input_crc => [tx[3], tx[4]] = crc16_ccitt(&tx[..3]).to_be_bytes(),
        None => {}
        Some(d) => {
            [tx[3], tx[4]] = d.to_be_bytes();
            if input_crc {
                [tx[6], tx[7]] = crc16_ccitt(&tx[..6]).to_be_bytes();
            }
        }
    }
    tx
}

/// The ADS131M04 on an SPI device (mode 1, CS framing one frame per transaction) with its DRDY
/// output on an input pin.
pub struct Ads131m04<SPI, DRDY> {
    spi: SPI,
    drdy: DRDY,
    config: Config,
    /// Whether the device currently expects an input CRC word (MODE.RX_CRC_EN as last
    /// written).
    rx_crc: bool,
}

impl<SPI, DRDY> Ads131m04<SPI, DRDY>
where
    SPI: SpiDevice<u8>,
    DRDY: InputPin,
{
    /// Takes the bus and the pin; no traffic until [`init`](Self::init).
    pub fn new(spi: SPI, drdy: DRDY, config: Config) -> Self {
        Ads131m04 { spi, drdy, config, rx_crc: false }
    }

    /// Gives the bus and the pin back.
    pub fn destroy(self) -> (SPI, DRDY) {
        (self.spi, self.drdy)
    }

    /// The configuration [`init`](Self::init) programs.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Checks the ID register, then writes MODE, CLOCK and GAIN1 from the configuration, each
    /// acknowledged by the device. Expects the power-on or reset state of the input CRC
    /// (off); 8 frames.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn init(&mut self) -> Result<(), Error<SPI::Error, DRDY::Error>> {
        let id = self.read_register(reg::ID)?;
        if id & ID_MASK != ID_EXPECTED {
            return Err(Error::WrongDevice(id));
        }
        let c = self.config;
        self.write_register(reg::MODE, c.mode_word())?;
        self.write_register(reg::CLOCK, c.clock_word())?;
        self.write_register(reg::GAIN1, c.gain1_word())
    }

    /// One frame: sends `command` (with `data` and the input CRC as configured), returns the
    /// received frame with its CRC checked.
    pub fn exchange(&mut self, command: u16, data: Option<u16>) -> Result<Frame, Error<SPI::Error, DRDY::Error>> {
        let tx = command_frame(command, data, self.rx_crc);
        let mut rx = [0u8; FRAME_BYTES];
        self.spi.transfer(&mut rx, &tx).map_err(Error::Spi)?;
        parse_frame(&rx).map_err(|CrcMismatch { expected, got }| Error::Crc { expected, got })
    }

    /// Reads one register: an RREG frame, then a NULL frame whose response word is the
    /// register's content (Table 8-11).
    pub fn read_register(&mut self, addr: u8) -> Result<u16, Error<SPI::Error, DRDY::Error>> {
        self.exchange(cmd::rreg(addr, 1), None)?;
        Ok(self.exchange(cmd::NULL, None)?.response)
    }

    /// Writes one register: a WREG frame with the data word, then a NULL frame whose response
    /// must be the acknowledgement `wreg_ack(addr, 1)` (Table 8-11).
    pub fn write_register(&mut self, addr: u8, value: u16) -> Result<(), Error<SPI::Error, DRDY::Error>> {
        self.exchange(cmd::wreg(addr, 1), Some(value))?;
        if addr == reg::MODE {
            // The new MODE applies from the next frame on, input CRC included.
            self.rx_crc = value & mode::RX_CRC_EN != 0;
        }
        let got = self.exchange(cmd::NULL, None)?.response;
        let expected = cmd::wreg_ack(addr, 1);
        if got != expected {
            return Err(Error::UnexpectedResponse { expected, got });
        }
        Ok(())
    }

    /// Reads one data frame (NULL command) when a sample is due: DRDY must be asserted (low),
    /// the CRC must match, the STATUS word must be healthy ([`status::CHECK_EXPECTED`]) and
    /// report new data on channels 0–2. Returns the frame.
    pub fn read_frame(&mut self) -> Result<Frame, Error<SPI::Error, DRDY::Error>> {
        if !self.drdy.is_low().map_err(Error::Pin)? {
            return Err(Error::NotReady);
        }
        let frame = self.exchange(cmd::NULL, None)?;
        let st = frame.response;
        if st & status::CHECK_MASK != status::CHECK_EXPECTED {
            return Err(Error::BadStatus(st));
        }
        if st & 0b0111 != 0b0111 {
            return Err(Error::NotReady);
        }
        Ok(frame)
    }

    /// The x, y, z signals (channels 0, 1, 2) in volts, each with its channel's gain; see
    /// [`read_frame`](Self::read_frame) for the checks.
    pub fn read_signals_v(&mut self) -> Result<[f32; 3], Error<SPI::Error, DRDY::Error>> {
        let f = self.read_frame()?;
        let [c0, c1, c2, _] = f.codes;
        let [g0, g1, g2, _] = self.config.gains;
        Ok([code_to_volts(c0, g0), code_to_volts(c1, g1), code_to_volts(c2, g2)])
    }
}
