//! The sampling interrupt's body, shared by the flight image, the replay firmware and the link
//! check (`mod isr;` in each), so the link check proves exactly this code panic-free. Each image
//! names the VE source of its steps as a constant, `crate::VE_SOURCE`.
//!
//! Deadline: one tick period (1 ms at the default 1 kHz). The body takes one sample, runs one
//! [`Tick::step`] (bounded: the instructions it takes are in `docs/measurements.md`, benchmarks)
//! and pushes the result into the consumer's queue without waiting. Whatever cannot be done in the slot
//! is counted and flagged ([`Status::OVERRUN`](bins_comp::Status::OVERRUN)), never waited for.

use bins_comp::replay::{Input, Tick, WINDOW};
use bins_comp::{Pipeline, Sample};
use heapless::spsc::Producer;

/// What a sample source has for this tick.
pub enum Take {
    /// The sample of this slot.
    Sample(Input<f32>),
    /// No sample is ready: the slot is missed (an overrun).
    NotReady,
    /// The source has ended (a replayed recording is exhausted): nothing to do.
    End,
}

/// A source of one sample per tick.
pub trait SampleIn {
    /// The sample of the current slot. Must not block.
    fn take(&mut self) -> Take;
}

/// Everything the interrupt owns: the per-tick state, the source and the output queue.
pub struct Isr<S: 'static, const Q: usize> {
    /// Pipeline and its running state.
    pub tick: Tick<f32, WINDOW>,
    /// Where the samples come from.
    pub source: S,
    /// The consumer's queue (drained by `main`).
    pub output: Producer<'static, Sample<f32>, Q>,
}

impl<S: SampleIn, const Q: usize> Isr<S, Q> {
    /// The interrupt's state at boot.
    pub fn new(pipeline: Pipeline<f32>, source: S, output: Producer<'static, Sample<f32>, Q>) -> Self {
        Isr { tick: Tick::new(pipeline), source, output }
    }

    /// One tick: take a sample, step, push. Returns false once the source has ended.
    #[inline]
    pub fn on_tick(&mut self) -> bool {
        match self.source.take() {
            Take::Sample(input) => {
                let s = self.tick.step(&input, crate::VE_SOURCE);
                if self.output.enqueue(s).is_err() {
                    self.tick.overrun();
                }
                true
            }
            Take::NotReady => {
                self.tick.overrun();
                true
            }
            Take::End => false,
        }
    }
}

/// The flight sample source: the ADC and the temperature sensor through
/// [`SampleSource`](bins_comp::drivers::SampleSource), whose fault policy never fails a slot
/// (a driver fault gives held or NaN signals, or a stale temperature, flagged
/// `SENSOR_FAULT` and counted).
impl<SPI, DRDY, I2C> SampleIn for bins_comp::drivers::SampleSource<SPI, DRDY, I2C>
where
    SPI: embedded_hal::spi::SpiDevice<u8>,
    DRDY: embedded_hal::digital::InputPin,
    I2C: embedded_hal::i2c::I2c,
{
    fn take(&mut self) -> Take {
        let r = self.read();
        Take::Sample(Input { u_v: r.signals_v, temp_c: r.temp_c, status: r.status })
    }
}
