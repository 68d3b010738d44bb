//! The flight image's output frames on its serial link: their byte layout, the fixed-point
//! format of the accelerations, the encoder the firmware runs and the decoder the host runs on
//! a capture (the same code, so the two cannot disagree on the format).
//!
//! # Layout
//!
//! Every frame is [`FRAME_BYTES`] = 24 bytes, integers little-endian except the CRC:
//!
//! | offset | bytes | field |
//! |---|---|---|
//! | 0 | 2 | sync word [`SYNC`] (`A5 5A`) |
//! | 2 | 1 | kind: [`Kind`] |
//! | 3 | 1 | flags, by kind (below) |
//! | 4 | 2 | sequence number, u16, +1 per frame of any kind, wrapping |
//! | 6 | 12 | three 32-bit words, by kind (below) |
//! | 18 | 4 | a 32-bit word, by kind (below) |
//! | 22 | 2 | CRC-16-CCITT of bytes 0..22, big-endian ([`crc16_ccitt`]: polynomial 0x1021, seed 0xFFFF, no reflection, no final XOR; the CRC over all 24 bytes is then zero) |
//!
//! | kind | flags | words 6..18 | word 18..22 |
//! |---|---|---|---|
//! | [`Kind::Sample`] (1), one per sample | bit i: axis i saturated ([`accel_to_fixed`]) | x, y, z acceleration \[g\], [`I8F24`] bits | [`Status`] bits |
//! | [`Kind::Boot`] (2), once, before the first sample | [`BootFrame`]: bit 0 blob accepted, bit 1 ADC initialised, bit 2 temperature sensor initialised | sampling rate \[Hz\], vibration profiles, the blob's stored CRC-32 (0 if rejected) | [`FORMAT_VERSION`] |
//! | [`Kind::Health`] (3), periodic | [`HealthFrame`]: bit 1 ADC ready, bit 2 temperature sensor ready (now: initialised, at boot or by a later attempt) | signal faults, temperature faults, sampling overruns (counts since boot) | frames the link could not send |
//!
//! # Acceleration format
//!
//! [`I8F24`]: signed, 8 integer and 24 fractional bits: range \[−128, 128 − 2⁻²⁴\] g, resolution
//! 2⁻²⁴ g ≈ 0.06 µg. The range is 12× the 10 g the compensation is specified for; the
//! resolution is the `f32` result's own spacing at 0.5–1 g, so every result of magnitude 0.5 g
//! or more is sent exactly and smaller ones to within 0.03 µg. A value outside the range is
//! saturated to its end (never wrapped) and flagged; a NaN (which the compensation does not
//! produce) is sent as 0, flagged.
//!
//! # Sizing
//!
//! At 1 kHz a sample frame per millisecond is 24 kB/s, 240 kbit/s with 8N1 framing: the link
//! needs a rate of at least that (the flight image runs its UART at 1 MBd).

use crate::compensate::{Sample, Status};
use crate::drivers::adc::crc16_ccitt;
/// The acceleration format (from the `fixed` crate), re-exported so that decoders can name it.
pub use fixed::types::I8F24;

/// Bytes of every frame.
pub const FRAME_BYTES: usize = 24;
/// First two bytes of every frame.
pub const SYNC: [u8; 2] = [0xA5, 0x5A];
/// The layout described here; sent in the boot frame. 2: health frames carry the sensors'
/// readiness in their flags (version 1 sent 0 there).
pub const FORMAT_VERSION: u32 = 2;

/// Bytes covered by the CRC (the CRC follows them).
const CRC_AT: usize = FRAME_BYTES - 2;

/// What a frame carries (byte 2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// One compensated sample.
    Sample = 1,
    /// What the image found at boot.
    Boot = 2,
    /// Fault and loss counters.
    Health = 3,
}

impl Kind {
    /// The kind a byte stands for.
    pub fn from_byte(b: u8) -> Option<Kind> {
        match b {
            1 => Some(Kind::Sample),
            2 => Some(Kind::Boot),
            3 => Some(Kind::Health),
            _ => None,
        }
    }
}

/// One compensated sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SampleFrame {
    /// Sequence number.
    pub seq: u16,
    /// x, y, z acceleration \[g\].
    pub accel_g: [I8F24; 3],
    /// Axis i's acceleration was outside [`I8F24`]'s range (or NaN) and is saturated (or 0).
    pub saturated: [bool; 3],
    /// The sample's status bits.
    pub status: Status,
}

impl SampleFrame {
    /// The frame of a compensated sample.
    pub fn from_sample(seq: u16, s: &Sample<f32>) -> Self {
        let [(x, sx), (y, sy), (z, sz)] = s.accel_g.map(accel_to_fixed);
        SampleFrame { seq, accel_g: [x, y, z], saturated: [sx, sy, sz], status: s.status }
    }
}

/// What the image found at boot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BootFrame {
    /// Sequence number.
    pub seq: u16,
    /// The CALIB region held a valid calibration blob, which is in use; otherwise every
    /// sample is flagged [`Status::INVALID_CALIBRATION`].
    pub blob_accepted: bool,
    /// The ADC answered its initialisation (ID and register writes acknowledged).
    pub adc_ready: bool,
    /// The temperature sensor answered its initialisation.
    pub temp_ready: bool,
    /// Sampling rate \[Hz\].
    pub tick_hz: u32,
    /// Vibration profiles of the blob (0 without a vibration section or blob).
    pub vibration_profiles: u32,
    /// The accepted blob's stored CRC-32 (its last four bytes), which identifies the
    /// calibration in use; 0 when the blob was rejected.
    pub blob_crc32: u32,
    /// The frame layout's version ([`FORMAT_VERSION`] from this encoder).
    pub format_version: u32,
}

/// Fault and loss counters since boot, each saturating at `u32::MAX`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HealthFrame {
    /// Sequence number.
    pub seq: u16,
    /// Failed ADC reads ([`FaultCounts::signal_total`](crate::drivers::FaultCounts::signal_total)).
    pub signal_faults: u32,
    /// Failed temperature polls and stale temperatures
    /// ([`FaultCounts::temp_total`](crate::drivers::FaultCounts::temp_total)).
    pub temp_faults: u32,
    /// Samples lost by the sampling interrupt ([`Tick::overruns`](crate::replay::Tick::overruns)).
    pub overruns: u32,
    /// Frames the serial link could not send (transmitter stuck).
    pub link_errors: u32,
    /// The ADC is initialised and read ([`SampleSource::adc_ready`](crate::drivers::SampleSource::adc_ready)).
    pub adc_ready: bool,
    /// The temperature sensor is initialised and polled
    /// ([`SampleSource::temp_ready`](crate::drivers::SampleSource::temp_ready)).
    pub temp_ready: bool,
}

/// One output frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Frame {
    /// [`Kind::Sample`].
    Sample(SampleFrame),
    /// [`Kind::Boot`].
    Boot(BootFrame),
    /// [`Kind::Health`].
    Health(HealthFrame),
}

/// Why a 24-byte block is not a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// The first two bytes are not [`SYNC`].
    Sync,
    /// The CRC does not match.
    Crc {
        /// CRC of bytes 0..22.
        expected: u16,
        /// CRC received.
        got: u16,
    },
    /// The CRC matches but the kind byte is none of [`Kind`].
    UnknownKind(u8),
}

/// Boot frame flag: blob accepted.
const BOOT_BLOB: u8 = 1 << 0;
/// Boot and health frame flag: ADC initialised.
const FLAG_ADC: u8 = 1 << 1;
/// Boot and health frame flag: temperature sensor initialised.
const FLAG_TEMP: u8 = 1 << 2;

/// The flags byte of the sensors' readiness.
fn sensor_flags(adc_ready: bool, temp_ready: bool) -> u8 {
    (if adc_ready { FLAG_ADC } else { 0 }) | if temp_ready { FLAG_TEMP } else { 0 }
}

/// An acceleration \[g\] in the frame's fixed-point format, and whether it had to be
/// saturated: rounded to the nearest multiple of 2⁻²⁴ g (ties to even) when in range, else
/// the range's end on its side; NaN gives 0, flagged.
///
/// By hand rather than by the `fixed` crate's generic conversion (the same results, checked
/// against it on every exponent in the host tests; 0.2 KB less flash): `a·2²⁴` is exact in
/// `f32`; its truncation differs from it by a fraction that is exact too, which decides the
/// rounding.
#[inline(never)]
#[cfg_attr(unstable_target, optimize(size))]
pub fn accel_to_fixed(a_g: f32) -> (I8F24, bool) {
    let v = a_g * 16_777_216.0;
    // The rounded value must lie in [−2³¹, 2³¹); f32 has no value in (2³¹ − 128, 2³¹) and
    // every f32 of magnitude ≥ 2²³ is an integer, so testing v itself is exact.
    if !(-2_147_483_648.0..2_147_483_648.0).contains(&v) {
        let end = if a_g > 0.0 {
            I8F24::MAX
        } else if a_g < 0.0 {
            I8F24::MIN
        } else {
            I8F24::ZERO
        };
        return (end, true);
    }
    let mut t = v as i32;
    let d = v - t as f32;
    let odd = t & 1 != 0;
    if d > 0.5 || (d == 0.5 && odd) {
        t += 1;
    } else if d < -0.5 || (d == -0.5 && odd) {
        t -= 1;
    }
    (I8F24::from_bits(t), false)
}

impl Frame {
    /// The frame's sequence number.
    pub fn seq(&self) -> u16 {
        match self {
            Frame::Sample(f) => f.seq,
            Frame::Boot(f) => f.seq,
            Frame::Health(f) => f.seq,
        }
    }

    /// The frame's kind.
    pub fn kind(&self) -> Kind {
        match self {
            Frame::Sample(_) => Kind::Sample,
            Frame::Boot(_) => Kind::Boot,
            Frame::Health(_) => Kind::Health,
        }
    }

    /// The frame's bytes.
    pub fn encode(&self) -> [u8; FRAME_BYTES] {
        let (flags, words, tail) = match self {
            Frame::Sample(f) => {
                let flags = f.saturated.iter().enumerate().fold(0u8, |a, (i, &s)| a | (u8::from(s) << i));
                (flags, f.accel_g.map(|a| a.to_bits().cast_unsigned()), f.status.0)
            }
            Frame::Boot(f) => {
                let flags = if f.blob_accepted { BOOT_BLOB } else { 0 } | sensor_flags(f.adc_ready, f.temp_ready);
                (flags, [f.tick_hz, f.vibration_profiles, f.blob_crc32], f.format_version)
            }
            Frame::Health(f) => {
                (sensor_flags(f.adc_ready, f.temp_ready), [f.signal_faults, f.temp_faults, f.overruns], f.link_errors)
            }
        };
        let [q0, q1] = self.seq().to_le_bytes();
        let [[a0, a1, a2, a3], [b0, b1, b2, b3], [d0, d1, d2, d3]] = words.map(u32::to_le_bytes);
        let [t0, t1, t2, t3] = tail.to_le_bytes();
        let [s0, s1] = SYNC;
        let kind = self.kind() as u8;
        let head = [s0, s1, kind, flags, q0, q1, a0, a1, a2, a3, b0, b1, b2, b3, d0, d1, d2, d3, t0, t1, t2, t3];
        let mut b = [0u8; FRAME_BYTES];
        if let Some((body, crc)) = b.split_last_chunk_mut::<2>() {
            for (d, s) in body.iter_mut().zip(head) {
                *d = s;
            }
            *crc = crc16_ccitt(body).to_be_bytes();
        }
        b
    }

    /// The frame in 24 bytes: sync, CRC and kind checked.
    ///
    /// # Example
    ///
    /// A compensated sample as the flight image sends it, and back.
    ///
    /// ```
    /// use bins_comp::compensate::{Sample, Status};
    /// use bins_comp::frame::{Frame, FrameError, SampleFrame};
    ///
    /// let sample = Sample { accel_g: [0.25, -1.0, 200.0], status: Status::TEMP_CLAMPED };
    /// let frame = Frame::Sample(SampleFrame::from_sample(7, &sample));
    /// let mut bytes = frame.encode();
    ///
    /// let Ok(Frame::Sample(back)) = Frame::decode(&bytes) else { panic!("not a sample frame") };
    /// assert_eq!((back.seq, back.status), (7, Status::TEMP_CLAMPED));
    /// assert_eq!(back.accel_g[0].to_num::<f32>(), 0.25);
    /// assert_eq!(back.saturated, [false, false, true]); // 200 g is beyond the frame's range
    ///
    /// bytes[10] ^= 1;
    /// assert!(matches!(Frame::decode(&bytes), Err(FrameError::Crc { .. })));
    /// ```
    pub fn decode(b: &[u8; FRAME_BYTES]) -> Result<Frame, FrameError> {
        let [s0, s1, kind, flags, q0, q1, w @ .., t0, t1, t2, t3, c0, c1] = *b;
        if [s0, s1] != SYNC {
            return Err(FrameError::Sync);
        }
        let expected = b.first_chunk::<CRC_AT>().map_or(0, |c| crc16_ccitt(c));
        let got = u16::from_be_bytes([c0, c1]);
        if expected != got {
            return Err(FrameError::Crc { expected, got });
        }
        let seq = u16::from_le_bytes([q0, q1]);
        let [a0, a1, a2, a3, b0, b1, b2, b3, d0, d1, d2, d3] = w;
        let words = [[a0, a1, a2, a3], [b0, b1, b2, b3], [d0, d1, d2, d3]].map(u32::from_le_bytes);
        let tail = u32::from_le_bytes([t0, t1, t2, t3]);
        let [w0, w1, w2] = words;
        match Kind::from_byte(kind) {
            Some(Kind::Sample) => Ok(Frame::Sample(SampleFrame {
                seq,
                accel_g: words.map(|w| I8F24::from_bits(w.cast_signed())),
                saturated: [0, 1, 2].map(|i| flags & (1 << i) != 0),
                status: Status(tail),
            })),
            Some(Kind::Boot) => Ok(Frame::Boot(BootFrame {
                seq,
                blob_accepted: flags & BOOT_BLOB != 0,
                adc_ready: flags & FLAG_ADC != 0,
                temp_ready: flags & FLAG_TEMP != 0,
                tick_hz: w0,
                vibration_profiles: w1,
                blob_crc32: w2,
                format_version: tail,
            })),
            Some(Kind::Health) => Ok(Frame::Health(HealthFrame {
                seq,
                signal_faults: w0,
                temp_faults: w1,
                overruns: w2,
                link_errors: tail,
                adc_ready: flags & FLAG_ADC != 0,
                temp_ready: flags & FLAG_TEMP != 0,
            })),
            None => Err(FrameError::UnknownKind(kind)),
        }
    }
}

/// The frames in a captured byte stream, in order. Where the bytes at the current position
/// are not a frame (a cut-off start, a corrupted frame), the decoder moves on by one byte until
/// the next valid frame and counts the bytes it skipped.
#[derive(Clone, Debug)]
pub struct Frames<'a> {
    rest: &'a [u8],
    skipped: usize,
}

impl<'a> Frames<'a> {
    /// The frames of `bytes`.
    pub fn new(bytes: &'a [u8]) -> Self {
        Frames { rest: bytes, skipped: 0 }
    }

    /// Bytes skipped so far (not part of any valid frame).
    pub fn skipped(&self) -> usize {
        self.skipped
    }

    /// Bytes left at the end that are too few for a frame (a capture cut mid-frame).
    pub fn remainder(&self) -> usize {
        self.rest.len()
    }
}

impl Iterator for Frames<'_> {
    type Item = Frame;

    fn next(&mut self) -> Option<Frame> {
        while let Some(block) = self.rest.first_chunk::<FRAME_BYTES>() {
            if let Ok(f) = Frame::decode(block) {
                self.rest = self.rest.get(FRAME_BYTES..).unwrap_or(&[]);
                return Some(f);
            }
            self.rest = self.rest.get(1..).unwrap_or(&[]);
            self.skipped += 1;
        }
        None
    }
}
