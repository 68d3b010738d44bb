//! Sensor drivers of the firmware and the glue that turns them into one sample per interrupt.
//! This module owns the drivers of the two front-end parts, generic over embedded-hal 1.0
//! traits so that they build for the target and test on the host against mocks, and the
//! fault policy of the sample source ([`SampleSource`]): what the compensation gets when a
//! driver fails, how the sample is flagged and how faults are counted.
//!
//! | module | part | bus |
//! |---|---|---|
//! | [`adc`] | TI ADS131M04, 4-channel simultaneous-sampling 24-bit ΔΣ ADC: the x, y, z signals on channels 0–2 | SPI + DRDY pin |
//! | [`temp`] | TI TMP117, ±0.1 °C digital temperature sensor: the unit's temperature | I²C |
//!
//! Every driver takes its bus by value and gives it back with `destroy(self)`; its errors are
//! typed enums carrying the bus error, with no allocation.
//!
//! # Fault policy of [`SampleSource::read`]
//!
//! - **Signals.** A failed ADC read (bus, pin, CRC, not ready, bad status) is counted and the
//!   sample gets the last good signals if at most [`SourceConfig::max_signal_hold`]
//!   consecutive samples have been held so far (a zero-order hold bridging an isolated
//!   glitch); otherwise NaN, which the compensation replaces by the zero offsets and flags
//!   [`Status::NONFINITE_INPUT`].
//! - **Temperature.** The TMP117 is polled every [`SourceConfig::temp_poll_interval`]
//!   samples; it converts far slower than the ADC, so "no new conversion" is normal and not a
//!   fault. A failed poll (bus error, wrong device) is counted and flags that sample; the last
//!   good temperature is kept. A temperature older than [`SourceConfig::max_temp_age`]
//!   samples (or none yet) is delivered as NaN, counted as stale; the compensation then
//!   works at T0 and flags [`Status::NONFINITE_INPUT`] | [`Status::TEMP_CLAMPED`].
//! - **Initialisation.** A sensor whose initialisation failed (at boot, [`SampleSource::init`])
//!   is not read: its samples get the fallbacks above with the fault `Uninitialised`
//!   (signals NaN; temperature polls skipped, so it goes stale). Its initialisation is tried
//!   again every [`SourceConfig::reinit_interval`] samples, one sensor per attempt (the ADC
//!   first), so that an attempt adds at most one sensor's initialisation to its sample's bus
//!   time. A sensor that answers is read from the next sample on. A sensor that reports a
//!   reset (e.g. after a brown-out: its registers are back at their defaults) is treated the
//!   same way, with its first attempt on the next sample: the ADC by STATUS.RESET, the TMP117
//!   by its configuration settings ([`temp::Error::ConfigLost`]).
//! - Every sample with a fault carries [`Status::SENSOR_FAULT`] in [`Reading::status`], to be
//!   OR-ed into the compensated sample's status by the caller:
//!
//! ```ignore
//! let r = source.read();
//! let mut sample = calibration.compensate(r.signals_v, r.temp_c);
//! sample.status.insert(r.status);
//! ```

pub mod adc;
pub mod temp;

pub use adc::Ads131m04;
pub use temp::Tmp117;

use crate::compensate::Status;
use embedded_hal::digital::InputPin;
use embedded_hal::i2c::I2c;
use embedded_hal::spi::SpiDevice;

/// Why a sample's signals were not freshly measured (from [`adc::Error`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SignalFault {
    /// SPI transfer failed.
    Bus,
    /// Reading the DRDY pin failed.
    Pin,
    /// Output frame CRC mismatch.
    Crc,
    /// No new conversion when the sample was due.
    NotReady,
    /// The STATUS word reported a fault or an unexpected state.
    BadStatus,
    /// A command was not acknowledged, or the device is not an ADS131M04.
    Protocol,
    /// The ADC's initialisation has not succeeded yet, so it is not read.
    Uninitialised,
}

impl<SE, PE> From<&adc::Error<SE, PE>> for SignalFault {
    fn from(e: &adc::Error<SE, PE>) -> Self {
        match e {
            adc::Error::Spi(_) => SignalFault::Bus,
            adc::Error::Pin(_) => SignalFault::Pin,
            adc::Error::Crc { .. } => SignalFault::Crc,
            adc::Error::NotReady => SignalFault::NotReady,
            adc::Error::BadStatus(_) => SignalFault::BadStatus,
            adc::Error::UnexpectedResponse { .. } | adc::Error::WrongDevice(_) => SignalFault::Protocol,
        }
    }
}

/// Why a sample's temperature is not a good recent value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TempFault {
    /// The I²C transfer of this sample's poll failed; the last good temperature was kept.
    Bus,
    /// This sample's poll found another device ID; the last good temperature was kept.
    WrongDevice,
    /// No good temperature within [`SourceConfig::max_temp_age`] samples: NaN delivered.
    Stale,
    /// The sensor's initialisation has not succeeded yet, so this sample's poll was skipped.
    Uninitialised,
    /// This sample's poll found the sensor's configuration lost (it has reset); the last good
    /// temperature was kept and the sensor is initialised again.
    ConfigLost,
}

impl TempFault {
    /// The fault a driver error stands for; `None` for "no new conversion", which is normal.
    pub fn from_error<E>(e: &temp::Error<E>) -> Option<Self> {
        match e {
            temp::Error::I2c(_) => Some(TempFault::Bus),
            temp::Error::WrongDevice(_) => Some(TempFault::WrongDevice),
            temp::Error::ConfigLost(_) => Some(TempFault::ConfigLost),
            temp::Error::NotReady => None,
        }
    }
}

/// Fault counters since [`SampleSource::new`] or [`SampleSource::init`], saturating at
/// `u32::MAX`. Driver faults count failed driver calls; `temp_stale` counts samples delivered
/// with a NaN temperature; the `uninitialised` counts, samples of a sensor not read.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FaultCounts {
    /// [`SignalFault::Bus`].
    pub signal_bus: u32,
    /// [`SignalFault::Pin`].
    pub signal_pin: u32,
    /// [`SignalFault::Crc`].
    pub signal_crc: u32,
    /// [`SignalFault::NotReady`].
    pub signal_not_ready: u32,
    /// [`SignalFault::BadStatus`].
    pub signal_bad_status: u32,
    /// [`SignalFault::Protocol`].
    pub signal_protocol: u32,
    /// [`SignalFault::Uninitialised`].
    pub signal_uninitialised: u32,
    /// [`TempFault::Bus`].
    pub temp_bus: u32,
    /// [`TempFault::WrongDevice`].
    pub temp_wrong_device: u32,
    /// [`TempFault::Stale`].
    pub temp_stale: u32,
    /// [`TempFault::Uninitialised`].
    pub temp_uninitialised: u32,
    /// [`TempFault::ConfigLost`].
    pub temp_config_lost: u32,
}

impl FaultCounts {
    /// Counts one signal fault.
    pub fn record_signal(&mut self, f: SignalFault) {
        let c = match f {
            SignalFault::Bus => &mut self.signal_bus,
            SignalFault::Pin => &mut self.signal_pin,
            SignalFault::Crc => &mut self.signal_crc,
            SignalFault::NotReady => &mut self.signal_not_ready,
            SignalFault::BadStatus => &mut self.signal_bad_status,
            SignalFault::Protocol => &mut self.signal_protocol,
            SignalFault::Uninitialised => &mut self.signal_uninitialised,
        };
        *c = c.saturating_add(1);
    }

    /// Counts one temperature fault.
    pub fn record_temp(&mut self, f: TempFault) {
        let c = match f {
            TempFault::Bus => &mut self.temp_bus,
            TempFault::WrongDevice => &mut self.temp_wrong_device,
            TempFault::Stale => &mut self.temp_stale,
            TempFault::Uninitialised => &mut self.temp_uninitialised,
            TempFault::ConfigLost => &mut self.temp_config_lost,
        };
        *c = c.saturating_add(1);
    }

    /// All signal faults.
    pub fn signal_total(&self) -> u32 {
        [
            self.signal_bus,
            self.signal_pin,
            self.signal_crc,
            self.signal_not_ready,
            self.signal_bad_status,
            self.signal_protocol,
            self.signal_uninitialised,
        ]
        .iter()
        .fold(0u32, |a, &b| a.saturating_add(b))
    }

    /// All temperature faults.
    pub fn temp_total(&self) -> u32 {
        [self.temp_bus, self.temp_wrong_device, self.temp_stale, self.temp_uninitialised, self.temp_config_lost]
            .iter()
            .fold(0u32, |a, &b| a.saturating_add(b))
    }
}

/// Timing of the fault policy, in samples (ADC data periods).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SourceConfig {
    /// Poll the temperature sensor every this many samples (0 is taken as 1). Each poll is
    /// one or two I²C register reads (≈ 0.1 ms each at 400 kHz), so it should not run every
    /// sample at kSPS rates.
    pub temp_poll_interval: u32,
    /// Consecutive failed samples that get the last good signals before NaN is delivered.
    pub max_signal_hold: u32,
    /// Oldest temperature still delivered, in samples since it was read.
    pub max_temp_age: u32,
    /// Samples between attempts to initialise a sensor whose initialisation failed (0: never
    /// try again).
    pub reinit_interval: u32,
}

impl Default for SourceConfig {
    /// For the ADC at 4 kSPS (OSR 1024, 8.192 MHz) and the TMP117 converting every 125 ms
    /// (CONV = 000b, AVG = 8): a poll every 16 ms, one held sample, temperature at most 2 s
    /// (16 conversion cycles) old, a failed sensor tried again every second.
    fn default() -> Self {
        SourceConfig { temp_poll_interval: 64, max_signal_hold: 1, max_temp_age: 8000, reinit_interval: 4000 }
    }
}

/// One sample's inputs for the compensation, and what happened reading them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reading {
    /// x, y, z accelerometer signals \[V\]: fresh, held, or NaN (see [`signal_fault`](Self::signal_fault)).
    pub signals_v: [f32; 3],
    /// Temperature of the unit [°C], or NaN when stale.
    pub temp_c: f32,
    /// Why the signals are not fresh, if they are not.
    pub signal_fault: Option<SignalFault>,
    /// Why this sample's temperature poll failed or the temperature is stale, if so.
    pub temp_fault: Option<TempFault>,
    /// [`Status::SENSOR_FAULT`] when either fault is set, else [`Status::OK`].
    pub status: Status,
}

/// The sample source of the firmware's sampling interrupt: the ADC and the temperature sensor,
/// and the state of the fault policy (see the [module documentation](self)).
pub struct SampleSource<SPI, DRDY, I2C> {
    adc: Ads131m04<SPI, DRDY>,
    temp: Tmp117<I2C>,
    config: SourceConfig,
    /// What the TMP117 is (re)initialised with.
    temp_config: temp::Config,
    adc_ready: bool,
    temp_ready: bool,
    /// Samples until the next initialisation attempt of a sensor that is not ready.
    until_reinit: u32,
    reinit_attempts: u32,
    last_signals_v: Option<[f32; 3]>,
    held: u32,
    last_temp_c: Option<f32>,
    temp_age: u32,
    until_poll: u32,
    counts: FaultCounts,
}

impl<SPI, DRDY, I2C> SampleSource<SPI, DRDY, I2C>
where
    SPI: SpiDevice<u8>,
    DRDY: InputPin,
    I2C: I2c,
{
    /// Takes the two drivers, already initialised (the TMP117 with the default
    /// [`temp::Config`]); the first [`read`](Self::read) polls the temperature.
    pub fn new(adc: Ads131m04<SPI, DRDY>, temp: Tmp117<I2C>, config: SourceConfig) -> Self {
        SampleSource {
            adc,
            temp,
            config,
            temp_config: temp::Config::default(),
            adc_ready: true,
            temp_ready: true,
            until_reinit: 0,
            reinit_attempts: 0,
            last_signals_v: None,
            held: 0,
            last_temp_c: None,
            temp_age: 0,
            until_poll: 0,
            counts: FaultCounts::default(),
        }
    }

    /// Initialises both sensors and takes them. A sensor that fails is not read, and its
    /// initialisation is tried again every [`SourceConfig::reinit_interval`] samples (see the
    /// [module documentation](self)); [`adc_ready`](Self::adc_ready) and
    /// [`temp_ready`](Self::temp_ready) tell how the boot went.
    pub fn init(
        mut adc: Ads131m04<SPI, DRDY>,
        mut temp: Tmp117<I2C>,
        temp_config: temp::Config,
        config: SourceConfig,
    ) -> Self {
        let adc_ready = adc.init().is_ok();
        let temp_ready = temp.init(temp_config).is_ok();
        SampleSource {
            temp_config,
            adc_ready,
            temp_ready,
            until_reinit: config.reinit_interval.saturating_sub(1),
            ..SampleSource::new(adc, temp, config)
        }
    }

    /// True while the ADC is initialised and read.
    pub fn adc_ready(&self) -> bool {
        self.adc_ready
    }

    /// True while the TMP117 is initialised and polled.
    pub fn temp_ready(&self) -> bool {
        self.temp_ready
    }

    /// Initialisation attempts after boot (each of one sensor).
    pub fn reinit_attempts(&self) -> u32 {
        self.reinit_attempts
    }

    /// Gives the drivers back.
    pub fn destroy(self) -> (Ads131m04<SPI, DRDY>, Tmp117<I2C>) {
        (self.adc, self.temp)
    }

    /// Fault counters since [`new`](Self::new) or [`init`](Self::init).
    pub fn fault_counts(&self) -> &FaultCounts {
        &self.counts
    }

    /// Reads one sample: the signals from the ADC and, on a poll sample, the temperature.
    /// Never fails: a driver error yields the fallback of the module documentation, the fault
    /// kind, and [`Status::SENSOR_FAULT`].
    pub fn read(&mut self) -> Reading {
        if !(self.adc_ready && self.temp_ready) {
            self.reinit_when_due();
        }
        let (signals_v, signal_fault) = self.read_signals();
        let (temp_c, temp_fault) = self.read_temp();
        let status = if signal_fault.is_some() || temp_fault.is_some() { Status::SENSOR_FAULT } else { Status::OK };
        Reading { signals_v, temp_c, signal_fault, temp_fault, status }
    }

    /// One initialisation attempt of a sensor that is not ready, when one is due: the ADC
    /// first, the TMP117 once the ADC is ready. Off the normal path: out of line, optimised
    /// for size.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    fn reinit_when_due(&mut self) {
        if self.config.reinit_interval == 0 {
            return;
        }
        if self.until_reinit > 0 {
            self.until_reinit -= 1;
            return;
        }
        self.until_reinit = self.config.reinit_interval - 1;
        self.reinit_attempts = self.reinit_attempts.saturating_add(1);
        if !self.adc_ready {
            self.adc_ready = self.adc.init().is_ok();
        } else {
            self.temp_ready = self.temp.init(self.temp_config).is_ok();
        }
    }

    fn read_signals(&mut self) -> ([f32; 3], Option<SignalFault>) {
        let fault = if !self.adc_ready {
            SignalFault::Uninitialised
        } else {
            match self.adc.read_signals_v() {
                Ok(s) => {
                    self.last_signals_v = Some(s);
                    self.held = 0;
                    return (s, None);
                }
                Err(e) => {
                    if matches!(e, adc::Error::BadStatus(st) if st & adc::status::RESET != 0) {
                        // The ADC has reset (a brown-out, say) to its register defaults: it is
                        // initialised again from the next sample on.
                        self.adc_ready = false;
                        self.until_reinit = 0;
                    }
                    SignalFault::from(&e)
                }
            }
        };
        self.counts.record_signal(fault);
        match self.last_signals_v {
            Some(s) if self.held < self.config.max_signal_hold => {
                self.held += 1;
                (s, Some(fault))
            }
            _ => ([f32::NAN; 3], Some(fault)),
        }
    }

    fn read_temp(&mut self) -> (f32, Option<TempFault>) {
        self.temp_age = self.temp_age.saturating_add(1);
        let mut fault = None;
        if self.until_poll == 0 {
            self.until_poll = self.config.temp_poll_interval.saturating_sub(1);
            let polled = if self.temp_ready {
                self.temp.read_temp_c().map_err(|e| TempFault::from_error(&e))
            } else {
                Err(Some(TempFault::Uninitialised))
            };
            match polled {
                Ok(t) => {
                    self.last_temp_c = Some(t);
                    self.temp_age = 0;
                }
                Err(f) => {
                    fault = f;
                    if let Some(f) = f {
                        self.counts.record_temp(f);
                    }
                    if f == Some(TempFault::ConfigLost) {
                        // Reset to its defaults: initialised again from the next sample on.
                        self.temp_ready = false;
                        self.until_reinit = 0;
                    }
                }
            }
        } else {
            self.until_poll -= 1;
        }
        match self.last_temp_c {
            Some(t) if self.temp_age <= self.config.max_temp_age => (t, fault),
            _ => {
                self.counts.record_temp(TempFault::Stale);
                (f32::NAN, fault.or(Some(TempFault::Stale)))
            }
        }
    }
}
