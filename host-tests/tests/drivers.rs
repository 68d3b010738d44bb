//! The sensor drivers (`bins_comp::drivers`) against their data sheets, through mocked buses:
//! ADS131M04 (TI SBAS890D) frames built here byte by byte from the frame layout of §8.5.1.7
//! (Figure 8-18) and the word layout of §8.5.1.8 convert to the volts of Table 8-10, a flipped
//! bit is a CRC error, a bus or pin error and a missing DRDY are typed errors, and `init` sends
//! the command words of Table 8-11; TMP117 (TI SNOSD82D) converts every example of Table 7-1
//! exactly and reports a wrong device ID, a missing conversion and bus errors; the sample
//! source flags and counts every fault and delivers the documented fallbacks.

// Binary literals below are grouped by register field, as the data sheets draw them.
#![allow(clippy::unusual_byte_groupings)]

use bins_comp::drivers::adc::{self, Ads131m04, Gain};
use bins_comp::drivers::temp::{self, Address, Tmp117};
use bins_comp::drivers::{SampleSource, SignalFault, SourceConfig, TempFault};
use bins_comp::{Calibration, Status};
use embedded_hal::spi::{ErrorKind as SpiErrorKind, ErrorType, Operation, SpiDevice};
use embedded_hal_mock::eh1::MockError;
use embedded_hal_mock::eh1::digital::{Mock as PinMock, State, Transaction as PinT};
use embedded_hal_mock::eh1::i2c::{Mock as I2cMock, Transaction as I2cT};
use embedded_hal_mock::eh1::spi::{Mock as SpiMock, Transaction as SpiT};

// ---- independent references -------------------------------------------------------------

/// CRC-16-CCITT as a bit-serial shift register, the way the device's hardware computes it
/// (polynomial x¹⁶ + x¹² + x⁵ + 1, register preset to 0xFFFF, MSB first; SBAS890D Table 8-7).
fn crc16_bit_serial(data: &[u8]) -> u16 {
    let mut reg = 0xFFFFu16;
    for &byte in data {
        for i in (0..8).rev() {
            let bit = (byte >> i) & 1 == 1;
            let feedback = (reg & 0x8000 != 0) ^ bit;
            reg <<= 1;
            if feedback {
                reg ^= 0x1021;
            }
        }
    }
    reg
}

/// A 16-bit content in a 24-bit word: MSB-aligned, low byte zero (SBAS890D §8.5.1.8).
fn word16(v: u16) -> [u8; 3] {
    [(v >> 8) as u8, v as u8, 0]
}

/// A 24-bit two's-complement code in a word, MSB first.
fn word24(code: i32) -> [u8; 3] {
    let c = (code as u32) & 0x00FF_FFFF;
    [(c >> 16) as u8, (c >> 8) as u8, c as u8]
}

/// An output frame: response word, four channel words, then the CRC word over all bytes before
/// it (SBAS890D Figure 8-18).
fn out_frame(response: u16, codes: [i32; 4]) -> Vec<u8> {
    let mut f: Vec<u8> = word16(response).to_vec();
    for c in codes {
        f.extend_from_slice(&word24(c));
    }
    let crc = crc16_bit_serial(&f);
    f.extend_from_slice(&word16(crc));
    f
}

/// An input frame: command word, optional data word, optional input CRC word, zeros; 6 words.
fn in_frame(command: u16, data: Option<u16>, input_crc: bool) -> Vec<u8> {
    let mut f: Vec<u8> = word16(command).to_vec();
    if let Some(d) = data {
        f.extend_from_slice(&word16(d));
    }
    if input_crc {
        let crc = crc16_bit_serial(&f);
        f.extend_from_slice(&word16(crc));
    }
    f.resize(18, 0);
    f
}

/// The three SPI mock transactions of one frame.
fn frame_tx(tx: Vec<u8>, rx: Vec<u8>) -> [SpiT<u8>; 3] {
    [SpiT::transaction_start(), SpiT::transfer(tx, rx), SpiT::transaction_end()]
}

/// STATUS after `init`: WLENGTH = 01b (24-bit), nothing else but DRDY[3:0] (SBAS890D §8.6,
/// STATUS register).
const STATUS_OK_DRDY012: u16 = 0x0107;
/// 2²³: codes per full scale.
const TWO23: f64 = 8_388_608.0;

/// An SPI device that fails the transactions whose numbers (from 0) are in `fail`, and passes
/// the others to the mock. embedded-hal-mock's SPI mock cannot return errors itself.
struct FlakySpi {
    inner: SpiMock<u8>,
    fail: Vec<usize>,
    n: usize,
}

impl ErrorType for FlakySpi {
    type Error = SpiErrorKind;
}

impl SpiDevice<u8> for FlakySpi {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), SpiErrorKind> {
        let n = self.n;
        self.n += 1;
        if self.fail.contains(&n) { Err(SpiErrorKind::Other) } else { self.inner.transaction(ops) }
    }
}

fn flaky(expectations: &[SpiT<u8>], fail: &[usize]) -> FlakySpi {
    FlakySpi { inner: SpiMock::new(expectations), fail: fail.to_vec(), n: 0 }
}

/// `x` equals the f64 reference within one ulp of `f32`: 1.2 V is not exact in `f32`
/// (relative error 4.0e-8 < 2⁻²⁴) and the product rounds once (≤ 2⁻²⁴).
fn assert_f32_near(x: f32, reference: f64) {
    let tol = reference.abs() * f64::from(f32::EPSILON);
    assert!((f64::from(x) - reference).abs() <= tol, "{x} vs reference {reference}");
}

// ---- ADS131M04: CRC, codes, frames ------------------------------------------------------------

#[test]
fn crc_matches_the_ccitt_check_value_and_the_bit_serial_register() {
    // CRC-16 with polynomial 0x1021, preset 0xFFFF, no reflection, no final XOR (the catalogue's
    // CRC-16/CCITT-FALSE) has the check value 0x29B1 for the ASCII string "123456789".
    assert_eq!(adc::crc16_ccitt(b"123456789"), 0x29B1);
    assert_eq!(crc16_bit_serial(b"123456789"), 0x29B1);
    assert_eq!(adc::crc16_ccitt(&[]), 0xFFFF, "the seed (Table 8-7)");
    let data: Vec<u8> = (0u8..=255).map(|i| i.wrapping_mul(37) ^ 0x5A).collect();
    for n in 0..data.len() {
        assert_eq!(adc::crc16_ccitt(&data[..n]), crc16_bit_serial(&data[..n]), "length {n}");
    }
    // A running CRC continues exactly.
    let (a, b) = data.split_at(100);
    assert_eq!(adc::crc16_ccitt_update(adc::crc16_ccitt(a), b), adc::crc16_ccitt(&data));
    // Appending the CRC (MSB first) leaves a zero remainder.
    let mut m = b"123456789".to_vec();
    m.extend_from_slice(&0x29B1u16.to_be_bytes());
    assert_eq!(adc::crc16_ccitt(&m), 0);
}

#[test]
fn codes_sign_extend_and_convert_as_table_8_10() {
    assert_eq!(adc::code_from_bytes([0x7F, 0xFF, 0xFF]), 8_388_607);
    assert_eq!(adc::code_from_bytes([0x00, 0x00, 0x01]), 1);
    assert_eq!(adc::code_from_bytes([0x00, 0x00, 0x00]), 0);
    assert_eq!(adc::code_from_bytes([0xFF, 0xFF, 0xFF]), -1);
    assert_eq!(adc::code_from_bytes([0x80, 0x00, 0x00]), -8_388_608);
    // Table 8-10, FSR = 1.2 V / gain: 7FFFFFh ↔ FSR(2²³ − 1)/2²³, 000001h ↔ FSR/2²³, 0 ↔ 0,
    // FFFFFFh ↔ −FSR/2²³, 800000h ↔ −FSR.
    for (gain, g) in [(Gain::X1, 1.0), (Gain::X2, 2.0), (Gain::X8, 8.0), (Gain::X128, 128.0)] {
        let fsr = 1.2 / g;
        let table = [
            (0x7F_FFFF, fsr * (TWO23 - 1.0) / TWO23),
            (0x00_0001, fsr / TWO23),
            (0x00_0000, 0.0),
            (-1, -fsr / TWO23),
            (-0x80_0000, -fsr),
        ];
        for (code, volts) in table {
            assert_f32_near(adc::code_to_volts(code, gain), volts);
        }
    }
    // The fixed-point fraction is exact: 0x400000 is one half of full scale.
    assert_eq!(adc::code_to_fraction(0x40_0000).to_num::<f64>(), 0.5);
    assert_eq!(adc::code_to_fraction(-0x80_0000).to_num::<f64>(), -1.0);
    // Out-of-range codes saturate at the clipping codes.
    assert_eq!(adc::code_to_fraction(1 << 24), adc::code_to_fraction(0x7F_FFFF));
}

#[test]
fn command_words_follow_table_8_11() {
    // RREG 101a aaaa annn nnnn, WREG 011a aaaa annn nnnn, ack 010a aaaa ammm mmmm.
    assert_eq!(adc::cmd::rreg(0x00, 1), 0b101_000000_0000000);
    assert_eq!(adc::cmd::rreg(0x3F, 128), 0b101_111111_1111111);
    assert_eq!(adc::cmd::wreg(0x02, 1), 0b011_000010_0000000);
    assert_eq!(adc::cmd::wreg(0x04, 3), 0b011_000100_0000010);
    assert_eq!(adc::cmd::wreg_ack(0x03, 1), 0b010_000011_0000000);
    assert_eq!(adc::command_frame(adc::cmd::NULL, None, false).to_vec(), vec![0; 18]);
    assert_eq!(adc::command_frame(0x6100, Some(0x0110), true).to_vec(), in_frame(0x6100, Some(0x0110), true));
    assert_eq!(adc::command_frame(0xA000, None, true).to_vec(), in_frame(0xA000, None, true));
}

#[test]
fn register_words_place_each_field_where_section_8_6_puts_it() {
    let c = adc::Config {
        gains: [Gain::X2, Gain::X4, Gain::X8, Gain::X128],
        osr: adc::Osr::R4096,
        power: adc::PowerMode::LowPower,
        enable_ch3: true,
        input_crc: true,
    };
    // GAIN1: PGAGAIN3 14:12 = 111, PGAGAIN2 10:8 = 011, PGAGAIN1 6:4 = 010, PGAGAIN0 2:0 = 001.
    assert_eq!(c.gain1_word(), 0b0_111_0_011_0_010_0_001);
    // CLOCK: CH3..CH0_EN 11:8 = 1111, OSR 4:2 = 101, PWR 1:0 = 01.
    assert_eq!(c.clock_word(), 0b0000_1111_000_101_01);
    // MODE: RX_CRC_EN 12, WLENGTH 9:8 = 01, TIMEOUT 4; RESET 10 = 0, CRC_TYPE 11 = 0 (CCITT).
    assert_eq!(c.mode_word(), 0b0001_0001_0001_0000);
    // The defaults: CH0–CH2 on, OSR 1024 (011), high resolution (10): the reset value 0x0F0E
    // without CH3; gains 1; no input CRC.
    let d = adc::Config::default();
    assert_eq!((d.clock_word(), d.gain1_word(), d.mode_word()), (0x070E, 0x0000, 0x0110));
}

#[test]
fn a_frame_built_from_the_layout_parses_to_its_codes() {
    let codes = [0x40_0000, -0x20_0000, 1, -0x7F_0000];
    let f = out_frame(STATUS_OK_DRDY012, codes);
    let rx: [u8; 18] = f.clone().try_into().unwrap();
    let frame = adc::parse_frame(&rx).unwrap();
    assert_eq!(frame.response, STATUS_OK_DRDY012);
    assert_eq!(frame.codes, codes);
    assert_eq!(frame.crc, crc16_bit_serial(&f[..15]));
}

#[test]
fn every_single_bit_flip_of_a_frame_is_a_crc_error() {
    let f = out_frame(STATUS_OK_DRDY012, [0x12_3456, -0x65_4321, 0x7F_FFFF, 0]);
    let received_crc = u16::from_be_bytes([f[15], f[16]]);
    // The 16 bits before the CRC word's padding byte: every flip in the covered words or in
    // the CRC itself is detected (a CRC-16 detects every single-bit error).
    for byte in 0..17 {
        for bit in 0..8 {
            let mut rx: [u8; 18] = f.clone().try_into().unwrap();
            rx[byte] ^= 1 << bit;
            let err = adc::parse_frame(&rx).unwrap_err();
            if byte < 15 {
                assert_eq!(err.got, received_crc);
                assert_eq!(err.expected, crc16_bit_serial(&rx[..15]));
            } else {
                assert_eq!(err.expected, crc16_bit_serial(&rx[..15]));
                assert_eq!(err.got, received_crc ^ (1 << (bit + 8 * (16 - byte))));
            }
        }
    }
}

// ---- ADS131M04 driver through the mocks -------------------------------------------------------

fn adc_with(spi: &[SpiT<u8>], pin: &[PinT]) -> Ads131m04<SpiMock<u8>, PinMock> {
    Ads131m04::new(SpiMock::new(spi), PinMock::new(pin), adc::Config::default())
}

fn finish(a: Ads131m04<SpiMock<u8>, PinMock>) {
    let (mut spi, mut pin) = a.destroy();
    spi.done();
    pin.done();
}

#[test]
fn read_signals_converts_channels_0_to_2_to_volts() {
    // +0.6 V, −0.3 V and one LSB at gain 1; channel 3 carries something else.
    let rx = out_frame(STATUS_OK_DRDY012, [0x40_0000, -0x20_0000, 1, 0x12_3456]);
    let mut a = adc_with(&frame_tx(vec![0; 18], rx), &[PinT::get(State::Low)]);
    let v = a.read_signals_v().unwrap();
    assert_f32_near(v[0], 0.6);
    assert_f32_near(v[1], -0.3);
    assert_f32_near(v[2], 1.2 / TWO23);
    finish(a);
}

#[test]
fn each_channel_uses_its_own_gain() {
    let cfg = adc::Config { gains: [Gain::X1, Gain::X4, Gain::X128, Gain::X1], ..Default::default() };
    let rx = out_frame(STATUS_OK_DRDY012, [-0x80_0000, -0x80_0000, -0x80_0000, 0]);
    let mut a = Ads131m04::new(SpiMock::new(&frame_tx(vec![0; 18], rx)), PinMock::new(&[PinT::get(State::Low)]), cfg);
    let v = a.read_signals_v().unwrap();
    assert_f32_near(v[0], -1.2);
    assert_f32_near(v[1], -0.3);
    assert_f32_near(v[2], -1.2 / 128.0);
    finish(a);
}

#[test]
fn a_flipped_bit_on_the_wire_is_a_crc_error() {
    let mut rx = out_frame(STATUS_OK_DRDY012, [0x40_0000, 0, 0, 0]);
    let got = u16::from_be_bytes([rx[15], rx[16]]);
    rx[4] ^= 0x10; // channel 0, middle byte
    let expected = crc16_bit_serial(&rx[..15]);
    let mut a = adc_with(&frame_tx(vec![0; 18], rx), &[PinT::get(State::Low)]);
    assert_eq!(a.read_signals_v(), Err(adc::Error::Crc { expected, got }));
    finish(a);
}

#[test]
fn drdy_not_asserted_is_not_ready_and_sends_nothing() {
    let mut a = adc_with(&[], &[PinT::get(State::High)]);
    assert_eq!(a.read_signals_v(), Err(adc::Error::NotReady));
    finish(a);
}

#[test]
fn status_without_new_data_on_the_used_channels_is_not_ready() {
    // DRDY2 clear: channel 2 has not converted.
    let rx = out_frame(0x010B, [0; 4]);
    let mut a = adc_with(&frame_tx(vec![0; 18], rx), &[PinT::get(State::Low)]);
    assert_eq!(a.read_signals_v(), Err(adc::Error::NotReady));
    finish(a);
}

#[test]
fn faults_and_unexpected_states_in_status_are_bad_status() {
    // RESET (an unexpected reset since init), LOCK, F_RESYNC, CRC_ERR, 16-bit words, ANSI CRC.
    for st in [0x0507u16, 0x8107, 0x4107, 0x1107, 0x0007, 0x0907] {
        let rx = out_frame(st, [0; 4]);
        let mut a = adc_with(&frame_tx(vec![0; 18], rx), &[PinT::get(State::Low)]);
        assert_eq!(a.read_signals_v(), Err(adc::Error::BadStatus(st)), "{st:#06x}");
        finish(a);
    }
    // Channel 3 not ready does not matter.
    let rx = out_frame(0x0107 & !0x08, [0; 4]);
    let mut a = adc_with(&frame_tx(vec![0; 18], rx), &[PinT::get(State::Low)]);
    assert!(a.read_signals_v().is_ok());
    finish(a);
}

#[test]
fn spi_and_pin_errors_are_typed() {
    let mut a = Ads131m04::new(flaky(&[], &[0]), PinMock::new(&[PinT::get(State::Low)]), adc::Config::default());
    assert_eq!(a.read_signals_v(), Err(adc::Error::Spi(SpiErrorKind::Other)));
    let (mut spi, mut pin) = a.destroy();
    spi.inner.done();
    pin.done();

    let err = MockError::Io(std::io::ErrorKind::NotConnected);
    let mut a = adc_with(&[], &[PinT::get(State::Low).with_error(err.clone())]);
    assert_eq!(a.read_signals_v(), Err(adc::Error::Pin(err)));
    finish(a);
}

/// The frames of `init` with the default configuration, as Table 8-11 and §8.6 spell them.
fn init_frames(id: u16) -> Vec<SpiT<u8>> {
    let z = [0; 4];
    let mut t = Vec::new();
    // RREG ID (101 000000 0000000), then NULL returning the ID register.
    t.extend(frame_tx(in_frame(0xA000, None, false), out_frame(0x0500, z)));
    t.extend(frame_tx(in_frame(0x0000, None, false), out_frame(id, z)));
    // WREG MODE (011 000010 0000000) = 0x0110: 24-bit words, TIMEOUT, RESET cleared; ack
    // 010 000010 0000000.
    t.extend(frame_tx(in_frame(0x6100, Some(0x0110), false), out_frame(0x0500, z)));
    t.extend(frame_tx(in_frame(0x0000, None, false), out_frame(0x4100, z)));
    // WREG CLOCK (011 000011 0000000) = 0x070E: CH0–CH2 on, OSR 1024, high resolution.
    t.extend(frame_tx(in_frame(0x6180, Some(0x070E), false), out_frame(0x0100, z)));
    t.extend(frame_tx(in_frame(0x0000, None, false), out_frame(0x4180, z)));
    // WREG GAIN1 (011 000100 0000000) = 0: all gains 1.
    t.extend(frame_tx(in_frame(0x6200, Some(0x0000), false), out_frame(0x0100, z)));
    t.extend(frame_tx(in_frame(0x0000, None, false), out_frame(0x4200, z)));
    t
}

#[test]
fn init_reads_the_id_and_writes_mode_clock_gain_with_acknowledgements() {
    let mut a = adc_with(&init_frames(0x2403), &[]);
    a.init().unwrap();
    finish(a);
}

#[test]
fn init_rejects_another_device_and_a_missing_acknowledgement() {
    // 0x22xx: a 2-channel ADS131M02.
    let mut a = adc_with(&init_frames(0x2201)[..6], &[]);
    assert_eq!(a.init(), Err(adc::Error::WrongDevice(0x2201)));
    finish(a);

    let mut frames = init_frames(0x2400);
    frames.truncate(12);
    // The MODE write is answered with STATUS instead of its acknowledgement.
    frames[10] = SpiT::transfer(in_frame(0, None, false), out_frame(0x0500, [0; 4]));
    let mut a = adc_with(&frames, &[]);
    assert_eq!(a.init(), Err(adc::Error::UnexpectedResponse { expected: 0x4100, got: 0x0500 }));
    finish(a);
}

#[test]
fn with_input_crc_every_frame_after_the_mode_write_carries_its_crc() {
    let cfg = adc::Config { input_crc: true, ..Default::default() };
    let z = [0; 4];
    let mut t = Vec::new();
    t.extend(frame_tx(in_frame(0xA000, None, false), out_frame(0x0500, z)));
    t.extend(frame_tx(in_frame(0x0000, None, false), out_frame(0x2400, z)));
    // MODE = 0x1110 (RX_CRC_EN) is sent without CRC; it applies from the next frame on.
    t.extend(frame_tx(in_frame(0x6100, Some(0x1110), false), out_frame(0x0500, z)));
    t.extend(frame_tx(in_frame(0x0000, None, true), out_frame(0x4100, z)));
    t.extend(frame_tx(in_frame(0x6180, Some(0x070E), true), out_frame(0x1100, z)));
    t.extend(frame_tx(in_frame(0x0000, None, true), out_frame(0x4180, z)));
    t.extend(frame_tx(in_frame(0x6200, Some(0x0000), true), out_frame(0x1100, z)));
    t.extend(frame_tx(in_frame(0x0000, None, true), out_frame(0x4200, z)));
    // A data frame: NULL with its CRC word 0x... over 00 00 00.
    t.extend(frame_tx(in_frame(0x0000, None, true), out_frame(0x0107, [0x40_0000, 0, 0, 0])));
    let mut a = Ads131m04::new(SpiMock::new(&t), PinMock::new(&[PinT::get(State::Low)]), cfg);
    a.init().unwrap();
    assert_f32_near(a.read_signals_v().unwrap()[0], 0.6);
    finish(a);
}

// ---- TMP117 ----------------------------------------------------------------------------------

#[test]
fn tmp117_converts_every_example_of_table_7_1_exactly() {
    let table: [(u16, f64); 11] = [
        (0x8000, -256.0),
        (0xF380, -25.0),
        (0xFFF0, -0.125),
        (0xFFFF, -0.0078125),
        (0x0000, 0.0),
        (0x0001, 0.0078125),
        (0x0010, 0.125),
        (0x0080, 1.0),
        (0x0C80, 25.0),
        (0x3200, 100.0),
        (0x7FFF, 255.9921875), // printed as 255.9921
    ];
    for (raw, t) in table {
        assert_eq!(f64::from(temp::raw_to_celsius(raw)), t, "{raw:#06x}");
    }
}

const TMP: u8 = 0x48;

#[test]
fn tmp117_init_checks_the_id_and_writes_the_configuration() {
    let cfg = temp::Config { cycle: temp::ConvCycle::C125ms, averaging: temp::Averaging::X32 };
    // CONV = 001b at bits 9:7, AVG = 10b at bits 6:5: 0x0080 | 0x0040.
    let i2c = I2cMock::new(&[
        I2cT::write_read(TMP, vec![0x0F], vec![0x01, 0x17]),
        I2cT::write(TMP, vec![0x01, 0x00, 0xC0]),
        // A later silicon revision (DID_REV ≠ 0) is still a TMP117.
        I2cT::write_read(TMP, vec![0x0F], vec![0x21, 0x17]),
        I2cT::write(TMP, vec![0x01, 0x00, 0xC0]),
    ]);
    let mut t = Tmp117::new(i2c, Address::Gnd);
    t.init(cfg).unwrap();
    t.init(cfg).unwrap();
    t.destroy().done();
}

#[test]
fn tmp117_wrong_device_id() {
    // 0x0116: a TMP116.
    let i2c = I2cMock::new(&[I2cT::write_read(0x4A, vec![0x0F], vec![0x01, 0x16])]);
    let mut t = Tmp117::new(i2c, Address::Sda);
    assert_eq!(t.init(temp::Config::default()), Err(temp::Error::WrongDevice(0x0116)));
    t.destroy().done();
}

#[test]
fn tmp117_reads_only_when_data_ready_and_reports_bus_errors() {
    let i2c = I2cMock::new(&[
        // Data_Ready (bit 13) set: the result register is read.
        I2cT::write_read(TMP, vec![0x01], vec![0x22, 0x20]),
        I2cT::write_read(TMP, vec![0x00], vec![0x0C, 0x80]),
        // Data_Ready clear: no conversion since the last read.
        I2cT::write_read(TMP, vec![0x01], vec![0x02, 0x20]),
        // Data_Ready set but the result still holds the reset value −256 °C.
        I2cT::write_read(TMP, vec![0x01], vec![0x22, 0x20]),
        I2cT::write_read(TMP, vec![0x00], vec![0x80, 0x00]),
        // The bus fails.
        I2cT::write_read(TMP, vec![0x01], vec![0, 0]).with_error(embedded_hal::i2c::ErrorKind::Other),
    ]);
    let mut t = Tmp117::new(i2c, Address::Gnd);
    assert_eq!(t.read_temp_c(), Ok(25.0));
    assert_eq!(t.read_temp_c(), Err(temp::Error::NotReady));
    assert_eq!(t.read_temp_c(), Err(temp::Error::NotReady));
    assert_eq!(t.read_temp_c(), Err(temp::Error::I2c(embedded_hal::i2c::ErrorKind::Other)));
    t.destroy().done();
}

// ---- the sample source -----------------------------------------------------------------------

fn temp_ready(raw: u16) -> [I2cT; 2] {
    temp_ready_with(0x0220, raw)
}

/// A poll finding a new conversion `raw`, the configuration register holding `settings`.
fn temp_ready_with(settings: u16, raw: u16) -> [I2cT; 2] {
    let cfg = settings | temp::config::DATA_READY;
    [
        I2cT::write_read(TMP, vec![0x01], cfg.to_be_bytes().to_vec()),
        I2cT::write_read(TMP, vec![0x00], raw.to_be_bytes().to_vec()),
    ]
}

#[test]
fn the_sample_source_flags_counts_and_falls_back() {
    let good = |c0: i32| frame_tx(vec![0; 18], out_frame(STATUS_OK_DRDY012, [c0, -c0, 0x10_0000, 0]));
    let mut corrupt = out_frame(STATUS_OK_DRDY012, [0x20_0000, 0, 0, 0]);
    corrupt[5] ^= 1;

    // ADC: 1 good, 2 DRDY high, 3 CRC error, 4 good, 5 good, 6 SPI error, 7 SPI error.
    let mut spi_t: Vec<SpiT<u8>> = Vec::new();
    spi_t.extend(good(0x40_0000));
    spi_t.extend(frame_tx(vec![0; 18], corrupt));
    spi_t.extend(good(0x20_0000));
    spi_t.extend(good(-0x40_0000));
    let spi = flaky(&spi_t, &[4, 5]);
    let pin = PinMock::new(
        &[State::Low, State::High, State::Low, State::Low, State::Low, State::Low, State::Low].map(PinT::get),
    );
    // TMP117 polled on samples 1, 3, 5, 7: 25 °C, bus error, no new conversion, no new conversion.
    let mut i2c_t: Vec<I2cT> = temp_ready(0x0C80).to_vec();
    i2c_t.push(
        I2cT::write_read(TMP, vec![0x01], vec![0, 0])
            .with_error(embedded_hal::i2c::ErrorKind::NoAcknowledge(embedded_hal::i2c::NoAcknowledgeSource::Address)),
    );
    i2c_t.push(I2cT::write_read(TMP, vec![0x01], vec![0x02, 0x20]));
    i2c_t.push(I2cT::write_read(TMP, vec![0x01], vec![0x02, 0x20]));
    let i2c = I2cMock::new(&i2c_t);

    let cfg = SourceConfig { temp_poll_interval: 2, max_signal_hold: 1, max_temp_age: 3, reinit_interval: 0 };
    let mut src =
        SampleSource::new(Ads131m04::new(spi, pin, adc::Config::default()), Tmp117::new(i2c, Address::Gnd), cfg);

    // 1: everything fresh.
    let r1 = src.read();
    assert_f32_near(r1.signals_v[0], 0.6);
    assert_f32_near(r1.signals_v[1], -0.6);
    assert_f32_near(r1.signals_v[2], 0.15);
    assert_eq!((r1.temp_c, r1.signal_fault, r1.temp_fault, r1.status), (25.0, None, None, Status::OK));

    // 2: DRDY not asserted: the last good signals are held, the sample flagged.
    let r2 = src.read();
    assert_eq!(r2.signals_v, r1.signals_v);
    assert_eq!((r2.temp_c, r2.signal_fault, r2.temp_fault), (25.0, Some(SignalFault::NotReady), None));
    assert_eq!(r2.status, Status::SENSOR_FAULT);

    // 3: CRC error right after a held sample: NaN signals; the temperature poll fails too,
    // the last temperature (2 samples old) is kept.
    let r3 = src.read();
    assert!(r3.signals_v.iter().all(|v| v.is_nan()));
    assert_eq!((r3.temp_c, r3.signal_fault, r3.temp_fault), (25.0, Some(SignalFault::Crc), Some(TempFault::Bus)));
    assert_eq!(r3.status, Status::SENSOR_FAULT);
    // What the ISR then does: the compensation flags the NaN inputs, the source's bit is OR-ed in.
    let mut s3 = Calibration::<f32>::uncalibrated().compensate(r3.signals_v, r3.temp_c);
    s3.status.insert(r3.status);
    assert!(s3.status.contains(Status::NONFINITE_INPUT | Status::SENSOR_FAULT));
    assert!(s3.accel_g.iter().all(|a| a.is_finite()));

    // 4: fresh signals; temperature 3 samples old, still within the limit.
    let r4 = src.read();
    assert_f32_near(r4.signals_v[0], 0.3);
    assert_eq!((r4.temp_c, r4.signal_fault, r4.temp_fault, r4.status), (25.0, None, None, Status::OK));

    // 5: fresh signals; no new conversion (not a fault), but the temperature is now 4 samples
    // old: NaN and stale.
    let r5 = src.read();
    assert_f32_near(r5.signals_v[0], -0.6);
    assert!(r5.temp_c.is_nan());
    assert_eq!((r5.signal_fault, r5.temp_fault, r5.status), (None, Some(TempFault::Stale), Status::SENSOR_FAULT));

    // 6 and 7: SPI errors: one held sample, then NaN.
    let r6 = src.read();
    assert_eq!(r6.signals_v, r5.signals_v);
    assert_eq!(r6.signal_fault, Some(SignalFault::Bus));
    let r7 = src.read();
    assert!(r7.signals_v.iter().all(|v| v.is_nan()));
    assert_eq!((r7.signal_fault, r7.temp_fault), (Some(SignalFault::Bus), Some(TempFault::Stale)));

    let c = *src.fault_counts();
    assert_eq!((c.signal_not_ready, c.signal_crc, c.signal_bus, c.signal_total()), (1, 1, 2, 4));
    assert_eq!((c.temp_bus, c.temp_stale, c.temp_total()), (1, 3, 4));

    let (adc, tmp) = src.destroy();
    let (mut spi, mut pin) = adc.destroy();
    spi.inner.done();
    pin.done();
    tmp.destroy().done();
}

#[test]
fn before_the_first_temperature_the_source_delivers_nan_flagged_stale() {
    let spi = SpiMock::new(&frame_tx(vec![0; 18], out_frame(STATUS_OK_DRDY012, [0; 4])));
    let pin = PinMock::new(&[PinT::get(State::Low)]);
    // The first conversion has not completed yet.
    let i2c = I2cMock::new(&[I2cT::write_read(TMP, vec![0x01], vec![0x02, 0x20])]);
    let mut src = SampleSource::new(
        Ads131m04::new(spi, pin, adc::Config::default()),
        Tmp117::new(i2c, Address::Gnd),
        SourceConfig::default(),
    );
    let r = src.read();
    assert_eq!(r.signals_v, [0.0; 3]);
    assert!(r.temp_c.is_nan());
    assert_eq!((r.signal_fault, r.temp_fault, r.status), (None, Some(TempFault::Stale), Status::SENSOR_FAULT));
    assert_eq!(src.fault_counts().temp_stale, 1);
    let (adc, tmp) = src.destroy();
    let (mut spi, mut pin) = adc.destroy();
    spi.done();
    pin.done();
    tmp.destroy().done();
}

/// The TMP117 configuration of the initialisation tests: CONV = 001b, AVG = 10b (0x00C0).
const TMP_CFG: temp::Config = temp::Config { cycle: temp::ConvCycle::C125ms, averaging: temp::Averaging::X32 };

fn tmp117_nack_on_id() -> I2cT {
    I2cT::write_read(TMP, vec![0x0F], vec![0, 0])
        .with_error(embedded_hal::i2c::ErrorKind::NoAcknowledge(embedded_hal::i2c::NoAcknowledgeSource::Address))
}

#[test]
fn a_sensor_that_failed_to_initialise_is_not_read_and_is_tried_again() {
    let sample = |c0: i32| frame_tx(vec![0; 18], out_frame(STATUS_OK_DRDY012, [c0, 0, 0, 0]));
    // Boot: another ADC (ID 0x2201) and no answer from the TMP117.
    let mut spi_t = init_frames(0x2201)[..6].to_vec();
    let mut i2c_t = vec![tmp117_nack_on_id()];
    // Sample 3: the ADC's retry succeeds and it is read at once; samples 4 to 7 read it.
    spi_t.extend(init_frames(0x2403));
    for c0 in [0x40_0000, 0x20_0000, -0x20_0000, 0x10_0000, -0x40_0000] {
        spi_t.extend(sample(c0));
    }
    // Sample 6: the TMP117 answers its retry and is polled at once (25 °C); sample 7 polls it
    // again (no new conversion).
    i2c_t.push(I2cT::write_read(TMP, vec![0x0F], vec![0x01, 0x17]));
    i2c_t.push(I2cT::write(TMP, vec![0x01, 0x00, 0xC0]));
    i2c_t.extend(temp_ready_with(0x00C0, 0x0C80));
    i2c_t.push(I2cT::write_read(TMP, vec![0x01], vec![0x00, 0xC0]));
    let adc =
        Ads131m04::new(SpiMock::new(&spi_t), PinMock::new(&[State::Low; 5].map(PinT::get)), adc::Config::default());
    let cfg = SourceConfig { temp_poll_interval: 1, max_signal_hold: 1, max_temp_age: 10, reinit_interval: 3 };
    let mut src = SampleSource::init(adc, Tmp117::new(I2cMock::new(&i2c_t), Address::Gnd), TMP_CFG, cfg);
    assert!(!src.adc_ready() && !src.temp_ready());

    // Samples 1 and 2: neither sensor is touched; NaN signals, no temperature, both flagged.
    for _ in 0..2 {
        let r = src.read();
        assert!(r.signals_v.iter().all(|v| v.is_nan()) && r.temp_c.is_nan());
        assert_eq!((r.signal_fault, r.temp_fault), (Some(SignalFault::Uninitialised), Some(TempFault::Uninitialised)));
        assert_eq!(r.status, Status::SENSOR_FAULT);
    }
    // Sample 3: the ADC first.
    let r = src.read();
    assert!(src.adc_ready() && !src.temp_ready());
    assert_f32_near(r.signals_v[0], 0.6);
    assert_eq!((r.signal_fault, r.temp_fault), (None, Some(TempFault::Uninitialised)));
    // Samples 4 and 5: the next attempt is not due yet.
    for reference in [0.3, -0.3] {
        let r = src.read();
        assert_f32_near(r.signals_v[0], reference);
        assert!(r.temp_c.is_nan());
        assert_eq!(r.temp_fault, Some(TempFault::Uninitialised));
    }
    // Sample 6: the TMP117, three samples after the ADC.
    let r = src.read();
    assert!(src.adc_ready() && src.temp_ready());
    assert_f32_near(r.signals_v[0], 0.15);
    assert_eq!((r.temp_c, r.signal_fault, r.temp_fault, r.status), (25.0, None, None, Status::OK));
    // Sample 7: both ready, no further attempt.
    let r = src.read();
    assert_f32_near(r.signals_v[0], -0.6);
    assert_eq!((r.temp_c, r.status), (25.0, Status::OK));

    assert_eq!(src.reinit_attempts(), 2);
    let c = *src.fault_counts();
    assert_eq!((c.signal_uninitialised, c.signal_total()), (2, 2));
    // Samples 1 to 5 skipped their polls; with no temperature yet, each was also stale.
    assert_eq!((c.temp_uninitialised, c.temp_stale, c.temp_total()), (5, 5, 10));
    let (adc, tmp) = src.destroy();
    finish(adc);
    tmp.destroy().done();
}

#[test]
fn with_no_reinit_interval_a_failed_sensor_stays_unread() {
    let adc = adc_with(&init_frames(0x2201)[..6], &[]);
    let tmp = Tmp117::new(I2cMock::new(&[tmp117_nack_on_id()]), Address::Gnd);
    let cfg = SourceConfig { reinit_interval: 0, ..SourceConfig::default() };
    let mut src = SampleSource::init(adc, tmp, TMP_CFG, cfg);
    for _ in 0..100 {
        let r = src.read();
        assert!(r.signals_v.iter().all(|v| v.is_nan()));
        assert_eq!(r.signal_fault, Some(SignalFault::Uninitialised));
    }
    assert_eq!((src.reinit_attempts(), src.adc_ready(), src.temp_ready()), (0, false, false));
    assert_eq!(src.fault_counts().signal_uninitialised, 100);
    let (adc, tmp) = src.destroy();
    finish(adc);
    tmp.destroy().done();
}

#[test]
fn an_adc_that_reports_a_reset_is_initialised_again_on_the_next_sample() {
    let sample = |st: u16, c0: i32| frame_tx(vec![0; 18], out_frame(st, [c0, 0, 0, 0]));
    let mut spi_t = init_frames(0x2403);
    spi_t.extend(sample(STATUS_OK_DRDY012, 0x40_0000));
    // STATUS.RESET (bit 10): the part is back at its register defaults.
    spi_t.extend(sample(STATUS_OK_DRDY012 | 0x0400, 0x20_0000));
    spi_t.extend(init_frames(0x2403));
    spi_t.extend(sample(STATUS_OK_DRDY012, -0x20_0000));
    let adc =
        Ads131m04::new(SpiMock::new(&spi_t), PinMock::new(&[State::Low; 3].map(PinT::get)), adc::Config::default());
    let mut i2c_t = vec![I2cT::write_read(TMP, vec![0x0F], vec![0x01, 0x17]), I2cT::write(TMP, vec![0x01, 0x00, 0xC0])];
    i2c_t.extend(temp_ready_with(0x00C0, 0x0C80));
    let cfg = SourceConfig { temp_poll_interval: 1000, max_signal_hold: 1, max_temp_age: 1000, reinit_interval: 1000 };
    let mut src = SampleSource::init(adc, Tmp117::new(I2cMock::new(&i2c_t), Address::Gnd), TMP_CFG, cfg);
    assert!(src.adc_ready() && src.temp_ready());

    let r1 = src.read();
    assert_f32_near(r1.signals_v[0], 0.6);
    // The reset is a bad status: the last good signals are held, and the ADC is no longer ready.
    let r2 = src.read();
    assert_eq!((r2.signals_v, r2.signal_fault), (r1.signals_v, Some(SignalFault::BadStatus)));
    assert!(!src.adc_ready());
    // The next sample initialises it again and reads it, without waiting for the interval.
    let r3 = src.read();
    assert!(src.adc_ready());
    assert_f32_near(r3.signals_v[0], -0.3);
    assert_eq!((r3.temp_c, r3.signal_fault, r3.status), (25.0, None, Status::OK));
    assert_eq!(src.reinit_attempts(), 1);
    let (adc, tmp) = src.destroy();
    finish(adc);
    tmp.destroy().done();
}

#[test]
fn a_tmp117_that_lost_its_configuration_is_initialised_again_on_the_next_sample() {
    let init = [I2cT::write_read(TMP, vec![0x0F], vec![0x01, 0x17]), I2cT::write(TMP, vec![0x01, 0x00, 0xC0])];
    let mut i2c_t = init.to_vec();
    // Sample 1: 25 °C with the settings written (CONV = 001b, AVG = 10b).
    i2c_t.extend(temp_ready_with(0x00C0, 0x0C80));
    // Sample 2: the register holds the reset value 0x0220 (1 s cycle, 8× averaging).
    i2c_t.push(I2cT::write_read(TMP, vec![0x01], vec![0x22, 0x20]));
    // Sample 3: initialised again, then polled at once: 25.5 °C.
    i2c_t.extend(init);
    i2c_t.extend(temp_ready_with(0x00C0, 0x0CC0));
    let frames = |n: usize| {
        let mut t = init_frames(0x2403);
        for _ in 0..n {
            t.extend(frame_tx(vec![0; 18], out_frame(STATUS_OK_DRDY012, [0x40_0000, 0, 0, 0])));
        }
        t
    };
    let adc =
        Ads131m04::new(SpiMock::new(&frames(3)), PinMock::new(&[State::Low; 3].map(PinT::get)), adc::Config::default());
    let cfg = SourceConfig { temp_poll_interval: 1, max_signal_hold: 1, max_temp_age: 100, reinit_interval: 1000 };
    let mut src = SampleSource::init(adc, Tmp117::new(I2cMock::new(&i2c_t), Address::Gnd), TMP_CFG, cfg);

    assert_eq!(src.read().temp_c, 25.0);
    let r2 = src.read();
    assert_eq!((r2.temp_c, r2.temp_fault, r2.status), (25.0, Some(TempFault::ConfigLost), Status::SENSOR_FAULT));
    assert!(!src.temp_ready());
    let r3 = src.read();
    assert!(src.temp_ready());
    assert_eq!((r3.temp_c, r3.temp_fault, r3.status), (25.5, None, Status::OK));
    assert_eq!((src.reinit_attempts(), src.fault_counts().temp_config_lost), (1, 1));
    let (adc, tmp) = src.destroy();
    finish(adc);
    tmp.destroy().done();
}

#[test]
fn tmp117_reports_lost_settings_only_after_init() {
    // Before init nothing is known to compare with: the reset configuration is read as usual.
    let mut t = Tmp117::new(I2cMock::new(&temp_ready(0x0C80)), Address::Gnd);
    assert_eq!(t.read_temp_c(), Ok(25.0));
    t.destroy().done();
    // After init, the flags (Data_Ready, alerts) may change, the settings may not.
    let mut i2c_t = vec![I2cT::write_read(TMP, vec![0x0F], vec![0x01, 0x17]), I2cT::write(TMP, vec![0x01, 0x00, 0xC0])];
    i2c_t.push(I2cT::write_read(TMP, vec![0x01], vec![0xE0, 0xC0]));
    i2c_t.push(I2cT::write_read(TMP, vec![0x00], vec![0x0C, 0x80]));
    i2c_t.push(I2cT::write_read(TMP, vec![0x01], vec![0x20, 0x40]));
    let mut t = Tmp117::new(I2cMock::new(&i2c_t), Address::Gnd);
    t.init(TMP_CFG).unwrap();
    assert_eq!(t.read_temp_c(), Ok(25.0));
    assert_eq!(t.read_temp_c(), Err(temp::Error::ConfigLost(0x2040)));
    t.destroy().done();
}
