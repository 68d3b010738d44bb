//! The sampling interrupt's per-tick step, and the binary streams of a recording replay.
//!
//! The firmware's timer interrupt and the host's `bins-cal replay` run the same code here:
//! [`Tick::step`] takes one sample (or notes that none was ready), runs
//! [`Pipeline::step`] with a VE source (the flight image's is [`SOURCE`]; a replay's is chosen
//! per recording) and returns the result with the overrun bit ([`Status::OVERRUN`]) set if
//! data was lost since the previous result. With no overrun and the same source, the
//! firmware's results equal the host's bit for bit (same code, same `f32` operations, same
//! order of samples).
//!
//! # Streams
//!
//! A recording is replayed as a stream of [`INPUT_BYTES`]-byte records (`u_v` f32×3 \[V\],
//! `temp_c` f32 [°C], little-endian), and the results come back as [`OUTPUT_BYTES`]-byte
//! records (`accel_g` f32×3 \[g\], status u32, little-endian), one per input in input order.

use crate::compensate::{Sample, Status};
use crate::float::Float;
use crate::linalg::Vec3;
use crate::pipeline::{Pipeline, PipelineState, VibrationSource};

/// Bytes of one input record: `u_v` f32×3, `temp_c` f32.
pub const INPUT_BYTES: usize = 16;
/// Bytes of one output record: `accel_g` f32×3, status u32.
pub const OUTPUT_BYTES: usize = 16;
/// Samples in the online vibration window (at 1 kHz: 64 ms, four periods of a 62.5 Hz
/// vibration).
pub const WINDOW: usize = 64;
/// Where the flight image's VE comes from, and a replay's unless another source is chosen:
/// the online moment window.
pub const SOURCE: VibrationSource = VibrationSource::Online;

/// One sample's inputs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Input<F> {
    /// x, y, z accelerometer signals \[V\].
    pub u_v: Vec3<F>,
    /// Temperature of the unit [°C].
    pub temp_c: F,
    /// Status the source already knows (e.g. [`Status::SENSOR_FAULT`]), or'ed into the result.
    pub status: Status,
}

impl Input<f32> {
    /// Decodes one input record.
    pub fn decode(b: &[u8; INPUT_BYTES]) -> Self {
        let w = words(b);
        Input {
            u_v: [f32::from_bits(w[0]), f32::from_bits(w[1]), f32::from_bits(w[2])],
            temp_c: f32::from_bits(w[3]),
            status: Status::OK,
        }
    }

    /// Encodes one input record (the status is not part of the stream).
    pub fn encode(&self) -> [u8; INPUT_BYTES] {
        from_words([self.u_v[0].to_bits(), self.u_v[1].to_bits(), self.u_v[2].to_bits(), self.temp_c.to_bits()])
    }
}

/// Encodes one output record.
pub fn encode_output(s: &Sample<f32>) -> [u8; OUTPUT_BYTES] {
    from_words([s.accel_g[0].to_bits(), s.accel_g[1].to_bits(), s.accel_g[2].to_bits(), s.status.0])
}

/// Decodes one output record.
pub fn decode_output(b: &[u8; OUTPUT_BYTES]) -> Sample<f32> {
    let w = words(b);
    Sample { accel_g: [f32::from_bits(w[0]), f32::from_bits(w[1]), f32::from_bits(w[2])], status: Status(w[3]) }
}

fn words(b: &[u8; 16]) -> [u32; 4] {
    let mut w = [0u32; 4];
    for (i, c) in b.chunks_exact(4).enumerate() {
        if let (Some(slot), Ok(bytes)) = (w.get_mut(i), <[u8; 4]>::try_from(c)) {
            *slot = u32::from_le_bytes(bytes);
        }
    }
    w
}

fn from_words(w: [u32; 4]) -> [u8; 16] {
    let mut b = [0u8; 16];
    for (c, x) in b.chunks_exact_mut(4).zip(w) {
        c.copy_from_slice(&x.to_le_bytes());
    }
    b
}

/// The sampling interrupt's configuration and state: the pipeline (`&self` of the step, fixed
/// after boot), its running state and the loss flag carried to the next result.
#[derive(Clone, Copy, Debug)]
pub struct Tick<F, const W: usize> {
    /// The configuration: calibration and VE model.
    pub pipeline: Pipeline<F>,
    /// The pipeline's running state (online moment window).
    pub state: PipelineState<F, W>,
    /// Data was lost since the last result: the next one carries [`Status::OVERRUN`].
    pending_overrun: bool,
    /// Events of lost data since boot.
    overruns: u32,
}

impl<F: Float, const W: usize> Tick<F, W> {
    /// The state at boot.
    pub fn new(pipeline: Pipeline<F>) -> Self {
        Tick { pipeline, state: PipelineState::new(), pending_overrun: false, overruns: 0 }
    }

    /// Counts a loss of data (a missed slot, a dropped result); the next result is flagged.
    pub fn overrun(&mut self) {
        self.pending_overrun = true;
        self.overruns = self.overruns.saturating_add(1);
    }

    /// Losses counted since boot.
    pub fn overruns(&self) -> u32 {
        self.overruns
    }

    /// One sample through the pipeline with the VE of `source` subtracted, flagged
    /// [`Status::OVERRUN`] if data was lost since the previous result. Bounded time, no
    /// allocation, no panic.
    #[inline]
    pub fn step(&mut self, input: &Input<F>, source: VibrationSource) -> Sample<F> {
        let mut s = self.pipeline.step(&mut self.state, input.u_v, input.temp_c, source);
        s.status.insert(input.status);
        if self.pending_overrun {
            s.status.insert(Status::OVERRUN);
            self.pending_overrun = false;
        }
        s
    }
}
