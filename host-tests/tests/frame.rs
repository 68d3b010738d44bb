//! The flight image's output frames (`bins_comp::frame`) against the layout of its module
//! documentation: a frame built here byte by byte equals the encoder's, every kind round trips,
//! accelerations are rounded to 2⁻²⁴ g and saturated (flagged, never wrapped) outside
//! [−128, 128) g, every single- and double-bit error and a wrong sync or kind is rejected, and
//! the stream decoder finds the valid frames among garbage, corrupted and cut-off ones.

use bins_comp::frame::{
    BootFrame, FORMAT_VERSION, FRAME_BYTES, Frame, FrameError, Frames, HealthFrame, I8F24, Kind, SYNC, SampleFrame,
    accel_to_fixed,
};
use bins_comp::{Sample, Status};
use proptest::prelude::*;

// ---- independent reference ----------------------------------------------------------------

/// CRC-16-CCITT bit by bit from its definition: polynomial x¹⁶ + x¹² + x⁵ + 1, register preset
/// to 0xFFFF, MSB first, no reflection, no final XOR.
fn crc16_bit_serial(data: &[u8]) -> u16 {
    let mut reg = 0xFFFFu16;
    for &byte in data {
        for i in (0..8).rev() {
            let feedback = (reg & 0x8000 != 0) ^ ((byte >> i) & 1 == 1);
            reg <<= 1;
            if feedback {
                reg ^= 0x1021;
            }
        }
    }
    reg
}

/// A frame assembled from the layout table: sync, kind, flags, LE sequence, three LE words,
/// LE tail word, big-endian CRC of the 22 bytes before it.
fn layout(kind: u8, flags: u8, seq: u16, words: [u32; 3], tail: u32) -> Vec<u8> {
    let mut f = SYNC.to_vec();
    f.extend([kind, flags]);
    f.extend(seq.to_le_bytes());
    for w in words {
        f.extend(w.to_le_bytes());
    }
    f.extend(tail.to_le_bytes());
    let crc = crc16_bit_serial(&f);
    f.extend(crc.to_be_bytes());
    f
}

fn sample_frame(seq: u16, accel_g: [f32; 3], status: Status) -> SampleFrame {
    SampleFrame::from_sample(seq, &Sample { accel_g, status })
}

fn boot_frame() -> BootFrame {
    BootFrame {
        seq: 0,
        blob_accepted: true,
        adc_ready: false,
        temp_ready: true,
        tick_hz: 1000,
        vibration_profiles: 7,
        blob_crc32: 0x0164_975C,
        format_version: FORMAT_VERSION,
    }
}

fn health_frame() -> HealthFrame {
    HealthFrame {
        seq: 0xFFFF,
        signal_faults: 19_000,
        temp_faults: 19_594,
        overruns: 3,
        link_errors: u32::MAX,
        adc_ready: true,
        temp_ready: false,
    }
}

// ---- layout -------------------------------------------------------------------------------

#[test]
fn every_kind_is_laid_out_as_documented() {
    let s = sample_frame(0x1234, [1.0, -0.5, 9.81], Status::SENSOR_FAULT | Status::TEMP_CLAMPED);
    let words = [1 << 24, (-(1i32 << 23)).cast_unsigned(), (9.81f32 * 16_777_216.0).round() as u32];
    assert_eq!(Frame::Sample(s).encode().to_vec(), layout(1, 0, 0x1234, words, 0x101));
    let b = boot_frame();
    assert_eq!(Frame::Boot(b).encode().to_vec(), layout(2, 0b101, 0, [1000, 7, 0x0164_975C], FORMAT_VERSION));
    let h = health_frame();
    assert_eq!(Frame::Health(h).encode().to_vec(), layout(3, 0b010, 0xFFFF, [19_000, 19_594, 3], u32::MAX));
    let h = HealthFrame { adc_ready: false, temp_ready: true, ..h };
    assert_eq!(Frame::Health(h).encode().to_vec(), layout(3, 0b100, 0xFFFF, [19_000, 19_594, 3], u32::MAX));
}

#[test]
fn the_crc_over_a_whole_frame_is_zero() {
    for f in [Frame::Sample(sample_frame(7, [0.1, 0.2, 0.3], Status::OK)), Frame::Boot(boot_frame())] {
        assert_eq!(crc16_bit_serial(&f.encode()), 0);
    }
}

#[test]
fn every_kind_round_trips() {
    let frames = [
        Frame::Sample(sample_frame(0, [0.0, -0.0, 1e-9], Status::OK)),
        Frame::Sample(sample_frame(u16::MAX, [-127.5, 127.5, 3.25], Status(u32::MAX))),
        Frame::Sample(sample_frame(42, [f32::NAN, 1e6, -1e6], Status::NONFINITE_INPUT)),
        Frame::Boot(boot_frame()),
        Frame::Boot(BootFrame { blob_accepted: false, adc_ready: true, temp_ready: false, ..boot_frame() }),
        Frame::Health(health_frame()),
        Frame::Health(HealthFrame { adc_ready: false, temp_ready: true, ..health_frame() }),
    ];
    for f in frames {
        assert_eq!(Frame::decode(&f.encode()), Ok(f), "{f:?}");
    }
}

// ---- fixed-point accelerations ------------------------------------------------------------

#[test]
fn accelerations_are_rounded_to_2_pow_minus_24_g() {
    // Multiples of 2⁻²⁴ g are exact: every f32 of magnitude ≥ 0.5 g is one.
    for a in [1.0f32, -1.0, 0.5, 9.806_65, -9.999_999, 127.999_99, -128.0, 2f32.powi(-24)] {
        let (v, sat) = accel_to_fixed(a);
        assert!(!sat, "{a}");
        assert_eq!(v.to_num::<f64>(), f64::from(a), "{a}");
    }
    // Smaller values: to the nearest multiple, ties to even.
    let lsb = 2f64.powi(-24);
    for a in [1e-9f32, 0.123_456_79, -0.3, 3e-8] {
        let (v, sat) = accel_to_fixed(a);
        assert!(!sat);
        assert!((v.to_num::<f64>() - f64::from(a)).abs() <= lsb / 2.0, "{a}");
    }
    assert_eq!(accel_to_fixed(1.5 * 2f32.powi(-24)).0.to_bits(), 2);
    assert_eq!(accel_to_fixed(2.5 * 2f32.powi(-24)).0.to_bits(), 2);
}

#[test]
fn the_conversion_equals_the_fixed_crates_on_every_exponent() {
    // Every exponent, the mantissas' ends and a stride through them, both signs: the
    // hand-written rounding against `fixed`'s checked conversion (ties to even).
    let mut n = 0;
    for exp in 0u32..=255 {
        for m in (0u32..1 << 23).step_by(4099).chain([0, 1, 2, (1 << 22) - 1, 1 << 22, (1 << 22) + 1, (1 << 23) - 1]) {
            for sign in [0u32, 1 << 31] {
                let a = f32::from_bits(sign | exp << 23 | m);
                let want = match I8F24::checked_from_num(a) {
                    Some(v) => (v, false),
                    None if a > 0.0 => (I8F24::MAX, true),
                    None if a < 0.0 => (I8F24::MIN, true),
                    None => (I8F24::ZERO, true),
                };
                assert_eq!(accel_to_fixed(a), want, "{a:e} ({:#010x})", a.to_bits());
                n += 1;
            }
        }
    }
    assert!(n > 1_000_000);
}

#[test]
fn out_of_range_saturates_and_flags_instead_of_wrapping() {
    for (a, bits) in [
        (128.0f32, i32::MAX),
        (1e30, i32::MAX),
        (f32::INFINITY, i32::MAX),
        (-128.000_02, i32::MIN),
        (-1e30, i32::MIN),
        (f32::NEG_INFINITY, i32::MIN),
        (f32::NAN, 0),
    ] {
        let (v, sat) = accel_to_fixed(a);
        assert!(sat, "{a}");
        assert_eq!(v.to_bits(), bits, "{a}");
    }
    let f = sample_frame(1, [200.0, 0.25, -1e9], Status::OK);
    assert_eq!(f.saturated, [true, false, true]);
    assert_eq!(f.accel_g, [I8F24::MAX, I8F24::from_num(0.25), I8F24::MIN]);
    let bytes = Frame::Sample(f).encode();
    assert_eq!(bytes[3], 0b101, "flags byte: axes x and z saturated");
    assert_eq!(Frame::decode(&bytes), Ok(Frame::Sample(f)));
}

// ---- rejection ----------------------------------------------------------------------------

#[test]
fn every_single_and_double_bit_error_is_rejected() {
    let good = Frame::Sample(sample_frame(300, [0.3, -0.7, 1.1], Status::SENSOR_FAULT)).encode();
    let bits = FRAME_BYTES * 8;
    let flip = |b: &mut [u8; FRAME_BYTES], i: usize| b[i / 8] ^= 1 << (i % 8);
    for i in 0..bits {
        let mut b = good;
        flip(&mut b, i);
        let e = Frame::decode(&b).expect_err("single-bit error accepted");
        if i < 16 {
            assert_eq!(e, FrameError::Sync);
        } else {
            assert!(matches!(e, FrameError::Crc { .. }), "bit {i}: {e:?}");
        }
        for j in i + 1..bits {
            let mut b2 = b;
            flip(&mut b2, j);
            assert!(Frame::decode(&b2).is_err(), "bits {i} and {j} flipped: accepted");
        }
    }
}

#[test]
fn an_unknown_kind_under_a_valid_crc_is_rejected() {
    for kind in [0u8, 4, 0xFF] {
        let f: [u8; FRAME_BYTES] = layout(kind, 0, 5, [1, 2, 3], 4).try_into().unwrap();
        assert_eq!(Frame::decode(&f), Err(FrameError::UnknownKind(kind)));
    }
    assert_eq!(Kind::from_byte(1), Some(Kind::Sample));
}

// ---- stream -------------------------------------------------------------------------------

#[test]
fn the_stream_decoder_skips_garbage_corruption_and_a_cut_off_end() {
    let frames: Vec<Frame> =
        (0..5u16).map(|k| Frame::Sample(sample_frame(k, [f32::from(k), 0.0, -1.0], Status::OK))).collect();
    let mut bytes = vec![0x5A, 0xA5, 0x5A, 0x00, 0x13]; // a cut-off start, with a false sync
    for (k, f) in frames.iter().enumerate() {
        let mut b = f.encode();
        if k == 2 {
            b[10] ^= 0x40; // corrupted in transit
        }
        bytes.extend(b);
    }
    bytes.extend(&frames[0].encode()[..FRAME_BYTES - 1]); // cut off by the end of the capture
    let mut it = Frames::new(&bytes);
    let got: Vec<Frame> = it.by_ref().collect();
    assert_eq!(got, [frames[0], frames[1], frames[3], frames[4]]);
    assert_eq!(it.skipped(), 5 + FRAME_BYTES);
    assert_eq!(it.remainder(), FRAME_BYTES - 1);
}

proptest! {
    /// Any sample with |a| < 128 g: the decoded acceleration is the nearest multiple of
    /// 2⁻²⁴ g, the status and sequence are unchanged, nothing is flagged.
    #[test]
    fn samples_round_trip_within_half_an_lsb(
        ax in -127.9f32..127.9, ay in -1.0f32..1.0, az in -10.0f32..10.0, status in any::<u32>(), seq in any::<u16>(),
    ) {
        let f = sample_frame(seq, [ax, ay, az], Status(status));
        let Ok(Frame::Sample(d)) = Frame::decode(&Frame::Sample(f).encode()) else { panic!("not decoded") };
        prop_assert_eq!(d.seq, seq);
        prop_assert_eq!(d.status, Status(status));
        prop_assert_eq!(d.saturated, [false; 3]);
        for (v, a) in d.accel_g.iter().zip([ax, ay, az]) {
            prop_assert!((v.to_num::<f64>() - f64::from(a)).abs() <= 2f64.powi(-25));
        }
    }
}
