//! Driver of the TI TMP117, the ±0.1 °C digital temperature sensor that measures the
//! accelerometer unit's temperature for the temperature models T(3)/T(4). This module owns the
//! sensor's register map, its temperature format and the driver ([`Tmp117`]) over an
//! embedded-hal 1.0 [`I2c`] bus.
//!
//! # Source
//!
//! Texas Instruments, *TMP117 High-Accuracy, Low-Power, Digital Temperature Sensor With
//! SMBus™- and I²C-Compatible Interface*, data sheet SNOSD82D (revised September 2022).
//!
//! - §7.3.3 *Temperature Result and Limits*, Table 7-1: the result is 16-bit two's complement,
//!   1 LSB = 7.8125 m°C, i.e. a signed fixed-point number with 7 fractional bits ([`I9F7`]).
//! - §7.5.2 *Pointer Register*, §7.5.3.1.3 *Writing and Reading Operation*: a register is read
//!   by writing its address, then reading two bytes, MSB first; it is written as the address
//!   followed by MSB and LSB.
//! - §7.5.3.1.2 *Serial Bus Address*: 0x48…0x4B by the ADD0 pin ([`Address`]).
//! - §7.6 *Register Map*: temperature result 0x00 (reset 0x8000 = −256 °C until the first
//!   conversion), configuration 0x01 (reset 0x0220), device ID 0x0F (0x0117).

use embedded_hal::i2c::I2c;
use fixed::types::I9F7;

/// Register addresses (§7.6, register map table).
pub mod reg {
    /// Temperature result, read-only, reset 0x8000.
    pub const TEMP_RESULT: u8 = 0x00;
    /// Configuration, reset 0x0220; bits in [`config`](super::config).
    pub const CONFIGURATION: u8 = 0x01;
    /// Device ID, read-only, 0x0117.
    pub const DEVICE_ID: u8 = 0x0F;
}

/// Configuration register bits (§7.6, configuration register field descriptions).
pub mod config {
    /// HIGH_Alert flag.
    pub const HIGH_ALERT: u16 = 1 << 15;
    /// LOW_Alert flag.
    pub const LOW_ALERT: u16 = 1 << 14;
    /// Data_Ready: a conversion has completed since the configuration or the temperature
    /// register was last read (reading either clears it).
    pub const DATA_READY: u16 = 1 << 13;
    /// EEPROM_Busy.
    pub const EEPROM_BUSY: u16 = 1 << 12;
    /// MOD\[1:0\] in bits 11:10; 00b = continuous conversion.
    pub const MOD_SHIFT: u16 = 10;
    /// CONV\[2:0\] in bits 9:7: conversion cycle time.
    pub const CONV_SHIFT: u16 = 7;
    /// AVG\[1:0\] in bits 6:5: number of averaged conversions.
    pub const AVG_SHIFT: u16 = 5;
    /// Soft_Reset (self-clearing).
    pub const SOFT_RESET: u16 = 1 << 1;
    /// The settings [`Config::word`](super::Config::word) programs and a reset restores to
    /// 0x0220: MOD, CONV, AVG, T/nA, POL, DR/Alert (bits 11:2). The flags above them and the
    /// self-clearing reset bit below are not settings.
    pub const SETTINGS_MASK: u16 = 0x0FFC;
}

/// Device ID register: DID\[11:0\] = 0x117, DID_REV in bits 15:12 (§7.6, device ID register).
pub const DEVICE_ID_MASK: u16 = 0x0FFF;
/// Expected value of `Device_ID & DEVICE_ID_MASK`.
pub const DEVICE_ID: u16 = 0x0117;
/// The temperature register's content until the first conversion has completed: −256 °C
/// (§7.6, temperature register).
pub const TEMP_RESET_VALUE: u16 = 0x8000;

/// 7-bit I²C address, set by the ADD0 pin (§7.5.3.1.2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Address {
    /// ADD0 to GND.
    #[default]
    Gnd = 0x48,
    /// ADD0 to V+.
    Vplus = 0x49,
    /// ADD0 to SDA.
    Sda = 0x4A,
    /// ADD0 to SCL.
    Scl = 0x4B,
}

/// Conversions averaged per result: AVG\[1:0\] (§7.6, configuration register; §7.3.2
/// *Averaging*).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Averaging {
    /// No averaging (15.5 ms active conversion).
    None = 0,
    /// 8 conversions, the reset default.
    #[default]
    X8 = 1,
    /// 32 conversions.
    X32 = 2,
    /// 64 conversions.
    X64 = 3,
}

/// Conversion cycle: CONV\[2:0\] (§7.6, configuration register; the cycle time also depends on
/// the averaging, see the conversion-cycle table of §7.4.1 *Continuous Conversion Mode*).
/// Named by the cycle time without averaging.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ConvCycle {
    /// 000b: 15.5 ms (no averaging); with averaging, the averaging time.
    #[default]
    C15ms5 = 0,
    /// 001b: 125 ms.
    C125ms = 1,
    /// 010b: 250 ms.
    C250ms = 2,
    /// 011b: 500 ms.
    C500ms = 3,
    /// 100b: 1 s, the reset default.
    C1s = 4,
    /// 101b: 4 s.
    C4s = 5,
    /// 110b: 8 s.
    C8s = 6,
    /// 111b: 16 s.
    C16s = 7,
}

/// What [`Tmp117::init`] programs: continuous conversion with this cycle and averaging.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Config {
    /// Conversion cycle.
    pub cycle: ConvCycle,
    /// Averaging.
    pub averaging: Averaging,
}

impl Config {
    /// The configuration register value: MOD = 00b (continuous), CONV, AVG, alert mode, alert
    /// pin active low, no reset.
    pub const fn word(&self) -> u16 {
        ((self.cycle as u16) << config::CONV_SHIFT) | ((self.averaging as u16) << config::AVG_SHIFT)
    }
}

/// What went wrong talking to the sensor. `E` is the I²C bus's error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error<E> {
    /// The I²C transfer failed (NACK, arbitration loss, bus error…).
    I2c(E),
    /// The device ID register does not identify a TMP117; its value is included.
    WrongDevice(u16),
    /// No conversion has completed since the last read (Data_Ready clear), or none at all
    /// since reset (the result still holds [`TEMP_RESET_VALUE`]).
    NotReady,
    /// The configuration register's settings are not the ones [`Tmp117::init`] wrote: the
    /// sensor has reset (a brown-out, say). Its value is included.
    ConfigLost(u16),
}

/// A temperature register value in °C: the 16 bits read as two's complement with 7 fractional
/// bits ([`I9F7`], 1 LSB = 2⁻⁷ °C = 7.8125 m°C; §7.3.3, Table 7-1). Exact in `f32`.
pub fn raw_to_celsius(raw: u16) -> f32 {
    I9F7::from_bits(raw.cast_signed()).to_num::<f32>()
}

/// The TMP117 on an I²C bus.
pub struct Tmp117<I2C> {
    i2c: I2C,
    address: u8,
    /// The settings written by the last successful [`init`](Self::init).
    settings: Option<u16>,
}

impl<I2C: I2c> Tmp117<I2C> {
    /// Takes the bus; no traffic until [`init`](Self::init).
    pub fn new(i2c: I2C, address: Address) -> Self {
        Tmp117 { i2c, address: address as u8, settings: None }
    }

    /// Gives the bus back.
    pub fn destroy(self) -> I2C {
        self.i2c
    }

    /// Reads a 16-bit register: pointer byte written, two bytes read MSB first (§7.5.3.1.3).
    pub fn read_register(&mut self, reg: u8) -> Result<u16, Error<I2C::Error>> {
        let mut buf = [0u8; 2];
        self.i2c.write_read(self.address, &[reg], &mut buf).map_err(Error::I2c)?;
        Ok(u16::from_be_bytes(buf))
    }

    /// Writes a 16-bit register: pointer byte, MSB, LSB (§7.5.3.1.3).
    pub fn write_register(&mut self, reg: u8, value: u16) -> Result<(), Error<I2C::Error>> {
        let [msb, lsb] = value.to_be_bytes();
        self.i2c.write(self.address, &[reg, msb, lsb]).map_err(Error::I2c)
    }

    /// Checks the device ID, then programs continuous conversion with `config`.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn init(&mut self, config: Config) -> Result<(), Error<I2C::Error>> {
        let id = self.read_register(reg::DEVICE_ID)?;
        if id & DEVICE_ID_MASK != DEVICE_ID {
            return Err(Error::WrongDevice(id));
        }
        self.write_register(reg::CONFIGURATION, config.word())?;
        self.settings = Some(config.word() & config::SETTINGS_MASK);
        Ok(())
    }

    /// The latest temperature in °C if a new conversion has completed: reads the configuration
    /// register (which clears Data_Ready), and the result register if Data_Ready was set. After
    /// [`init`](Self::init), a configuration whose settings differ from the ones written is
    /// [`Error::ConfigLost`] (a reset; undetectable only for a configuration equal to the reset
    /// default, 1 s cycle and 8× averaging).
    pub fn read_temp_c(&mut self) -> Result<f32, Error<I2C::Error>> {
        let cfg = self.read_register(reg::CONFIGURATION)?;
        if self.settings.is_some_and(|w| cfg & config::SETTINGS_MASK != w) {
            return Err(Error::ConfigLost(cfg));
        }
        if cfg & config::DATA_READY == 0 {
            return Err(Error::NotReady);
        }
        let raw = self.read_register(reg::TEMP_RESULT)?;
        if raw == TEMP_RESET_VALUE {
            return Err(Error::NotReady);
        }
        Ok(raw_to_celsius(raw))
    }
}
