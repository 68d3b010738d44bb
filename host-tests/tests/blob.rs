//! The calibration blob (`bins_comp::blob`) against `docs/calibration-blob.md`: a blob built
//! here byte by byte from the spec equals the encoder's, round trips are lossless, every
//! single-bit flip and every truncation of a typical blob is rejected with the error its
//! position implies, and physically impossible values under a valid CRC are rejected naming
//! the field and its byte offset. The same holds for blobs with the optional vibration
//! sections (0x0005 coefficients, 0x0006 flight-phase profiles) and the thermal-dynamics
//! section (0x0007); a blob without them gives no vibration-error model and no dynamics.

use bins_comp::blob::{self, BlobError, CalDate, Field, Meta, section};
use bins_comp::dynamics::{DynamicsError, ThermalDynamics};
use bins_comp::temperature::{MAX_KNOTS, MAX_POLY_ORDER};
use bins_comp::vibration::{MAX_PROFILES, tables};
use bins_comp::{
    Calibration, CalibrationParams, CoefDelta, Constants, ConversionFunction, Form, Method, TempModel, Variant,
    Vibration, VibrationConfig, VibrationParams, paper,
};
use proptest::prelude::*;

// ---- independent references -------------------------------------------------------------

/// Bit-at-a-time CRC-32 (reflected, 0xEDB88320), written from the definition.
fn crc32_bitwise(data: &[u8]) -> u32 {
    let mut crc = 0xffff_ffffu32;
    for &byte in data {
        crc ^= byte as u32;
        for _ in 0..8 {
            let lsb = crc & 1;
            crc >>= 1;
            if lsb == 1 {
                crc ^= 0xedb8_8320;
            }
        }
    }
    !crc
}

/// A section to build: id, flags, payload.
type Sec = (u16, u16, Vec<u8>);

/// Assembles a blob from sections exactly as the spec lays it out: header, table, payloads in
/// table order at 8-byte-aligned offsets with zero padding, total length = aligned end + CRC.
fn build(sections: &[Sec]) -> Vec<u8> {
    let n = sections.len();
    let align = |x: usize| x.div_ceil(8) * 8;
    let mut offsets = Vec::new();
    let mut at = align(16 + 12 * n);
    for (_, _, p) in sections {
        offsets.push(at);
        at = align(at + p.len());
    }
    let total = at + 4;
    let mut b = vec![0u8; total];
    b[0..4].copy_from_slice(b"BCAL");
    b[4..6].copy_from_slice(&1u16.to_le_bytes());
    b[6..8].copy_from_slice(&(n as u16).to_le_bytes());
    b[8..12].copy_from_slice(&(total as u32).to_le_bytes());
    for (k, ((id, flags, p), off)) in sections.iter().zip(&offsets).enumerate() {
        let t = 16 + 12 * k;
        b[t..t + 2].copy_from_slice(&id.to_le_bytes());
        b[t + 2..t + 4].copy_from_slice(&flags.to_le_bytes());
        b[t + 4..t + 8].copy_from_slice(&(*off as u32).to_le_bytes());
        b[t + 8..t + 12].copy_from_slice(&(p.len() as u32).to_le_bytes());
        b[*off..off + p.len()].copy_from_slice(p);
    }
    seal(&mut b);
    b
}

/// Writes the CRC of `b[..len-4]` into the last four bytes (independently of `blob::reseal`).
fn seal(b: &mut [u8]) {
    let n = b.len();
    let crc = crc32_bitwise(&b[..n - 4]);
    b[n - 4..].copy_from_slice(&crc.to_le_bytes());
}

fn f64s(xs: &[f64]) -> Vec<u8> {
    xs.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// The 12 values of a coefficient set in the spec's order: ΔU0 x,y,z then ΔK/K row-major.
fn coef_values(c: &CoefDelta<f64>) -> Vec<f64> {
    let mut v = c.du0_v.to_vec();
    for row in &c.rel_k {
        v.extend_from_slice(row);
    }
    v
}

/// The payloads of the spec's sections for `p` and `meta`, in id order.
fn spec_sections(p: &CalibrationParams, serial: &str, date: Option<(u16, u8, u8)>, tool: &str) -> Vec<Sec> {
    spec_sections_vib(p, None, serial, date, tool)
}

/// The vibration sections as the spec lays them out: 0x0005 = variant (1 paper, 2 exact), 7
/// zero bytes, then per accelerometer a0, δ_1A, k2…k5, m1, m2, m31, m32; 0x0006 = count, 7
/// zero bytes, then per profile kind (0 none, 1 sine, 2 random), 7 zero bytes and five f64
/// (sine: amplitudes x, y, z, frequency, 0; random: σ x, y, z, band low, band high).
fn spec_vibration(v: &VibrationParams) -> Vec<Sec> {
    let mut vib = vec![if v.variant == Variant::Paper { 1u8 } else { 2 }, 0, 0, 0, 0, 0, 0, 0];
    for cf in &v.cf {
        vib.extend(f64s(&[
            cf.a0_g,
            cf.delta_1a,
            cf.k2_g_per_g2,
            cf.k3_g_per_g3,
            cf.k4_g_per_g4,
            cf.k5_g_per_g5,
            cf.m1_g_per_g,
            cf.m2_g_per_g,
            cf.m31_g_per_g2,
            cf.m32_g_per_g2,
        ]));
    }
    let mut out = vec![(0x0005, 1, vib)];
    let n = v.n_profiles as usize;
    if n > 0 {
        let mut prof = vec![n as u8, 0, 0, 0, 0, 0, 0, 0];
        for p in &v.profiles[..n] {
            let (kind, vals) = match *p {
                Vibration::None => (0u8, [0.0; 5]),
                Vibration::Harmonic { amp_g: a, freq_hz } => (1, [a[0], a[1], a[2], freq_hz, 0.0]),
                Vibration::Random { sigma_g: s, band_hz } => (2, [s[0], s[1], s[2], band_hz.0, band_hz.1]),
            };
            prof.extend([kind, 0, 0, 0, 0, 0, 0, 0]);
            prof.extend(f64s(&vals));
        }
        out.push((0x0006, 1, prof));
    }
    out
}

/// [`spec_sections`] with the vibration sections.
fn spec_sections_vib(
    p: &CalibrationParams,
    vib: Option<&VibrationParams>,
    serial: &str,
    date: Option<(u16, u8, u8)>,
    tool: &str,
) -> Vec<Sec> {
    let mut constants = vec![p.t0_c];
    for row in &p.constants.k_v_per_g {
        constants.extend_from_slice(row);
    }
    constants.extend_from_slice(&p.constants.u0_v);
    let model = match &p.model {
        TempModel::Poly { order, coef } => {
            let mut m = vec![1u8, *order, 0, 0, 0, 0, 0, 0];
            for c in coef.iter().take(*order as usize) {
                m.extend(f64s(&coef_values(c)));
            }
            m
        }
        TempModel::Pwl { n_knots, knots_c, at_knot } => {
            let n = *n_knots as usize;
            let mut m = vec![2u8, *n_knots, 0, 0, 0, 0, 0, 0];
            m.extend(f64s(&knots_c[..n]));
            for c in &at_knot[..n] {
                m.extend(f64s(&coef_values(c)));
            }
            m
        }
    };
    let method = match p.method {
        Method::Uncorrected => [0u8, 0],
        Method::CoefficientCorrection => [1, 0],
        Method::OutputCorrection(Form::Full) => [2, 1],
        Method::OutputCorrection(Form::Simplified) => [2, 2],
        Method::OutputCorrection(Form::Linearized) => [2, 3],
    };
    let mut out: Vec<Sec> = vec![
        (0x0001, 1, f64s(&constants)),
        (0x0002, 1, model),
        (0x0003, 1, [method[0], method[1], 0, 0, 0, 0, 0, 0].to_vec()),
        (0x0004, 1, f64s(&[p.temp_range_c.0, p.temp_range_c.1])),
    ];
    if let Some(v) = vib {
        out.extend(spec_vibration(v));
    }
    if !serial.is_empty() {
        out.push((0x0101, 0, serial.as_bytes().to_vec()));
    }
    if let Some((y, m, d)) = date {
        let mut v = y.to_le_bytes().to_vec();
        v.extend([m, d]);
        out.push((0x0102, 0, v));
    }
    if !tool.is_empty() {
        out.push((0x0103, 0, tool.as_bytes().to_vec()));
    }
    out
}

// ---- fixtures -----------------------------------------------------------------------------

const SERIAL: &str = "PAPER-T1T2-0001";
const TOOL: &str = "bins-cal 0.1.0";
const DATE: CalDate = CalDate { year: 2024, month: 2, day: 29 };

fn paper_params() -> CalibrationParams {
    paper::params(paper::two_range_model().expect("two-range model"), Method::OutputCorrection(Form::Simplified))
}

fn meta() -> Meta<'static> {
    Meta { serial: SERIAL, date: Some(DATE), tool_version: TOOL }
}

/// The typical blob: the paper's unit, two-range model, method 2 simplified, all metadata.
fn typical() -> Vec<u8> {
    let mut buf = [0u8; blob::MAX_BLOB_BYTES];
    let n = blob::encode(&paper_params(), &meta(), &mut buf).expect("encode");
    buf[..n].to_vec()
}

/// The AL-15 on every axis (exact variant) with the seven flight profiles of Tables V2/V3
/// and a quiet phase: every profile kind.
fn vib_params() -> VibrationParams {
    let mut v = VibrationParams::new([tables::AL15; 3], Variant::Exact);
    let (profiles, n) = tables::flight_profiles();
    for p in &profiles[..n as usize] {
        v.push_profile(*p).unwrap();
    }
    v.push_profile(Vibration::None).unwrap();
    v
}

/// The typical blob with the vibration sections.
fn typical_vib() -> Vec<u8> {
    let mut buf = [0u8; blob::MAX_BLOB_BYTES];
    let n = blob::encode_with_vibration(&paper_params(), Some(&vib_params()), &meta(), &mut buf).expect("encode");
    buf[..n].to_vec()
}

/// (id, flags, offset, len) of each table entry, read directly from the bytes.
fn table(b: &[u8]) -> Vec<(u16, u16, usize, usize)> {
    let n = u16::from_le_bytes([b[6], b[7]]) as usize;
    (0..n)
        .map(|k| {
            let t = 16 + 12 * k;
            let u32_at = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap()) as usize;
            (
                u16::from_le_bytes([b[t], b[t + 1]]),
                u16::from_le_bytes([b[t + 2], b[t + 3]]),
                u32_at(t + 4),
                u32_at(t + 8),
            )
        })
        .collect()
}

fn entry_index(b: &[u8], id: u16) -> usize {
    table(b).iter().position(|e| e.0 == id).expect("section present")
}

fn payload_offset(b: &[u8], id: u16) -> usize {
    table(b)[entry_index(b, id)].2
}

fn put_f64(b: &mut [u8], off: usize, x: f64) {
    b[off..off + 8].copy_from_slice(&x.to_le_bytes());
}

fn get_f64(b: &[u8], off: usize) -> f64 {
    f64::from_le_bytes(b[off..off + 8].try_into().unwrap())
}

/// Applies `edit` to a copy of the typical blob, re-seals it and parses it.
fn parse_edited(edit: impl FnOnce(&mut Vec<u8>)) -> Result<(), BlobError> {
    let mut b = typical();
    edit(&mut b);
    seal(&mut b);
    blob::parse(&b).map(|_| ())
}

/// [`parse_edited`] on the typical blob with the vibration sections.
fn parse_edited_vib(edit: impl FnOnce(&mut Vec<u8>)) -> Result<(), BlobError> {
    let mut b = typical_vib();
    edit(&mut b);
    seal(&mut b);
    blob::parse(&b).map(|_| ())
}

/// Every f64 of the parameters as bits (lossless comparison, -0.0 ≠ 0.0).
fn param_bits(p: &CalibrationParams) -> Vec<u64> {
    let mut v: Vec<f64> = vec![p.t0_c, p.temp_range_c.0, p.temp_range_c.1];
    v.extend(p.constants.k_v_per_g.iter().flatten());
    v.extend(p.constants.u0_v);
    match &p.model {
        TempModel::Poly { order, coef } => {
            v.push(*order as f64);
            coef.iter().for_each(|c| v.extend(coef_values(c)));
        }
        TempModel::Pwl { n_knots, knots_c, at_knot } => {
            v.push(100.0 + *n_knots as f64);
            v.extend(knots_c);
            at_knot.iter().for_each(|c| v.extend(coef_values(c)));
        }
    }
    v.iter().map(|x| x.to_bits()).collect()
}

// ---- CRC and layout -----------------------------------------------------------------------

#[test]
fn crc32_check_value_and_bitwise_reference() {
    assert_eq!(blob::crc32(b"123456789"), 0xcbf4_3926);
    assert_eq!(blob::crc32(b""), 0);
    assert_eq!(crc32_bitwise(b"123456789"), 0xcbf4_3926);
    let data: Vec<u8> = (0..5000u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8).collect();
    for n in [1, 2, 3, 7, 64, 255, 256, 4095, 5000] {
        assert_eq!(blob::crc32(&data[..n]), crc32_bitwise(&data[..n]), "length {n}");
    }
}

#[test]
fn encoder_output_equals_blob_built_from_the_spec() {
    let p = paper_params();
    let spec = build(&spec_sections(&p, SERIAL, Some((2024, 2, 29)), TOOL));
    assert_eq!(typical(), spec);
    // And for a polynomial model with every method.
    let quad = paper::quadratic_truth().unwrap();
    for method in all_methods() {
        let p = paper::params(quad, method);
        let mut buf = [0u8; 4096];
        let n = blob::encode(&p, &Meta::default(), &mut buf).unwrap();
        assert_eq!(buf[..n], build(&spec_sections(&p, "", None, ""))[..], "{method:?}");
    }
}

fn all_methods() -> [Method; 5] {
    [
        Method::Uncorrected,
        Method::CoefficientCorrection,
        Method::OutputCorrection(Form::Full),
        Method::OutputCorrection(Form::Simplified),
        Method::OutputCorrection(Form::Linearized),
    ]
}

#[test]
fn typical_blob_parses_to_its_parameters_and_metadata() {
    let b = typical();
    assert!(b.len() <= blob::MAX_BLOB_BYTES);
    let parsed = blob::parse(&b).expect("valid");
    assert_eq!(param_bits(&parsed.params), param_bits(&paper_params()));
    assert_eq!(parsed.params, paper_params());
    assert_eq!(parsed.meta, meta());
    // The f32 calibration from the blob compensates exactly like one built from the params.
    let from_blob = parsed.calibration::<f32>().unwrap();
    let direct = Calibration::<f32>::new(&paper_params()).unwrap();
    for (u, t) in [([0.1f32, -0.2, 0.55], -10.0f32), ([-0.3, 0.0, 0.2], 45.0), ([5.0, -5.0, 1.0], 20.0)] {
        let (a, b) = (from_blob.compensate(u, t), direct.compensate(u, t));
        assert_eq!(a.status, b.status);
        assert_eq!(a.accel_g.map(f32::to_bits), b.accel_g.map(f32::to_bits));
    }
}

#[test]
fn parse_region_ignores_erased_flash_after_the_blob() {
    let b = typical();
    let mut region = [0xffu8; blob::MAX_BLOB_BYTES];
    region[..b.len()].copy_from_slice(&b);
    let parsed = blob::parse_region(&region).expect("valid");
    assert_eq!(parsed.params, paper_params());
    assert_eq!(blob::parse_region(&[0xffu8; 4096]), Err(BlobError::BadMagic));
    assert_eq!(blob::parse_region(&[0u8; 4096]), Err(BlobError::BadMagic));
    // The exact-length parser refuses the trailing bytes.
    assert_eq!(blob::parse(&region), Err(BlobError::LengthMismatch { declared: b.len(), actual: 4096 }));
    // A region shorter than the declared length.
    assert_eq!(blob::parse_region(&b[..b.len() - 1]), Err(BlobError::Truncated { needed: b.len(), got: b.len() - 1 }));
}

// ---- corruption: exhaustive ---------------------------------------------------------------

#[test]
fn every_single_bit_flip_is_rejected_with_the_error_of_its_region() {
    assert_every_bit_flip_rejected(&typical());
    assert_every_bit_flip_rejected(&typical_vib());
}

fn assert_every_bit_flip_rejected(b: &[u8]) {
    let len = b.len();
    let stored = u32::from_le_bytes(b[len - 4..].try_into().unwrap());
    let mut checked = 0;
    for byte in 0..len {
        for bit in 0..8 {
            let mut c = b.to_vec();
            c[byte] ^= 1 << bit;
            let got = blob::parse(&c);
            let expected = match byte {
                0..4 => BlobError::BadMagic,
                4..6 => BlobError::UnsupportedVersion(u16::from_le_bytes([c[4], c[5]])),
                8..12 => {
                    let declared = u32::from_le_bytes(c[8..12].try_into().unwrap());
                    let d = declared as usize;
                    if !(20..=4096).contains(&d) {
                        BlobError::BadLength(declared)
                    } else if d > len {
                        BlobError::Truncated { needed: d, got: len }
                    } else {
                        BlobError::LengthMismatch { declared: d, actual: len }
                    }
                }
                // Section count, reserved word, table, payloads, padding and the CRC itself
                // are all covered by the CRC, which is checked before any of them is read.
                _ => BlobError::CrcMismatch {
                    stored: u32::from_le_bytes(c[len - 4..].try_into().unwrap()),
                    computed: crc32_bitwise(&c[..len - 4]),
                },
            };
            assert_eq!(got.map(|_| ()), Err(expected), "bit {bit} of byte {byte}");
            if byte >= len - 4 {
                assert_ne!(u32::from_le_bytes(c[len - 4..].try_into().unwrap()), stored);
            }
            checked += 1;
        }
    }
    assert_eq!(checked, 8 * len);
}

#[test]
fn every_truncation_is_rejected() {
    assert_every_truncation_rejected(&typical());
    assert_every_truncation_rejected(&typical_vib());
}

fn assert_every_truncation_rejected(b: &[u8]) {
    let len = b.len();
    for k in 0..len {
        let needed = if k < 16 { 16 } else { len };
        assert_eq!(blob::parse(&b[..k]).map(|_| ()), Err(BlobError::Truncated { needed, got: k }), "prefix {k}");
    }
    let mut longer = b.to_vec();
    longer.push(0);
    assert_eq!(blob::parse(&longer).map(|_| ()), Err(BlobError::LengthMismatch { declared: len, actual: len + 1 }));
}

// ---- impossible values under a valid CRC ----------------------------------------------------

fn constants_value(b: &[u8], index: usize) -> usize {
    payload_offset(b, section::CONSTANTS) + 8 * index
}

#[test]
fn out_of_range_constants_are_rejected_naming_the_field() {
    let b = typical();
    let k00 = get_f64(&b, constants_value(&b, 1));
    // Scale factors.
    for bad in [0.0, 5e-4, -5e-4, 2e3, -1.5e3, f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        for (i, idx) in [(0u8, 1usize), (1, 5), (2, 9)] {
            let off = constants_value(&b, idx);
            assert_eq!(
                parse_edited(|b| put_f64(b, off, bad)),
                Err(BlobError::OutOfRange { field: Field::K { row: i, col: i }, offset: off }),
                "K[{i}][{i}] = {bad}"
            );
        }
    }
    // Cross-sensitivity beyond half the row's scale factor (and just inside is accepted).
    let off = constants_value(&b, 2); // K[0][1]
    assert_eq!(
        parse_edited(|b| put_f64(b, off, 0.5001 * k00.abs())),
        Err(BlobError::OutOfRange { field: Field::K { row: 0, col: 1 }, offset: off })
    );
    assert_eq!(parse_edited(|b| put_f64(b, off, -0.1 * k00.abs())), Ok(()));
    let off = constants_value(&b, 8); // K[2][1]
    assert_eq!(
        parse_edited(|b| put_f64(b, off, f64::NAN)),
        Err(BlobError::OutOfRange { field: Field::K { row: 2, col: 1 }, offset: off })
    );
    // Offsets.
    let off = constants_value(&b, 12); // U0[2]
    assert_eq!(
        parse_edited(|b| put_f64(b, off, -100.5)),
        Err(BlobError::OutOfRange { field: Field::U0 { axis: 2 }, offset: off })
    );
    // T0 outside the physical limits, and inside them but outside the calibrated range.
    let off = constants_value(&b, 0);
    assert_eq!(parse_edited(|b| put_f64(b, off, 250.0)), Err(BlobError::OutOfRange { field: Field::T0, offset: off }));
    let range = payload_offset(&b, section::TEMP_RANGE);
    assert_eq!(parse_edited(|b| put_f64(b, off, 80.0)), Err(BlobError::BadRange { offset: range }));
}

#[test]
fn bad_ranges_knots_and_codes_are_rejected_naming_the_field() {
    let b = typical();
    let range = payload_offset(&b, section::TEMP_RANGE);
    assert_eq!(
        parse_edited(|b| put_f64(b, range + 8, 300.0)),
        Err(BlobError::OutOfRange { field: Field::TempRange { end: 1 }, offset: range + 8 })
    );
    assert_eq!(
        parse_edited(|b| put_f64(b, range, -101.0)),
        Err(BlobError::OutOfRange { field: Field::TempRange { end: 0 }, offset: range })
    );
    assert_eq!(parse_edited(|b| put_f64(b, range, 75.0)), Err(BlobError::BadRange { offset: range }));

    // The two-range model: kind 2, 3 knots (−40, 20, 70), then 3 coefficient sets.
    let m = payload_offset(&b, section::TEMP_MODEL);
    assert_eq!((b[m], b[m + 1]), (2, 3));
    let knot = |i: usize| m + 8 + 8 * i;
    assert_eq!(
        parse_edited(|b| put_f64(b, knot(2), 20.0)),
        Err(BlobError::KnotsNotIncreasing { knot: 2, offset: knot(2) })
    );
    assert_eq!(
        parse_edited(|b| put_f64(b, knot(0), -150.0)),
        Err(BlobError::OutOfRange { field: Field::Knot { knot: 0 }, offset: knot(0) })
    );
    let set = |i: usize, v: usize| m + 8 + 8 * 3 + 96 * i + 8 * v;
    assert_eq!(
        parse_edited(|b| put_f64(b, set(2, 1), 101.0)),
        Err(BlobError::OutOfRange { field: Field::KnotDu0 { knot: 2, axis: 1 }, offset: set(2, 1) })
    );
    // rel_k[1][1] of knot 0 (value 3 + 4 = 7): a scale factor more than doubled.
    assert_eq!(
        parse_edited(|b| put_f64(b, set(0, 7), 1.5)),
        Err(BlobError::OutOfRange { field: Field::KnotRelK { knot: 0, row: 1, col: 1 }, offset: set(0, 7) })
    );
    // rel_k[0][2] of knot 2 (value 5): K_xz grows past half of K_xx.
    assert_eq!(
        parse_edited(|b| put_f64(b, set(2, 5), 40.0)),
        Err(BlobError::OutOfRange { field: Field::KnotRelK { knot: 2, row: 0, col: 2 }, offset: set(2, 5) })
    );
    // Within the per-value limit, but the scale factor falls below half its T0 value at a knot
    // inside the range: Calibration::new's check.
    assert_eq!(parse_edited(|b| put_f64(b, set(0, 3), -0.9)), Err(BlobError::SingularInRange));

    // Codes and counts.
    assert_eq!(parse_edited(|b| b[m] = 3), Err(BlobError::BadCode { field: Field::ModelKind, offset: m, code: 3 }));
    assert_eq!(parse_edited(|b| b[m + 1] = 9), Err(BlobError::KnotCount { count: 9, offset: m + 1 }));
    assert_eq!(parse_edited(|b| b[m + 1] = 1), Err(BlobError::KnotCount { count: 1, offset: m + 1 }));
    assert_eq!(
        parse_edited(|b| b[m + 1] = 2),
        Err(BlobError::SectionLength { id: section::TEMP_MODEL, offset: m, len: 8 + 3 * 104 })
    );
    assert_eq!(parse_edited(|b| b[m + 5] = 1), Err(BlobError::ReservedNotZero { offset: m + 5 }));
    let me = payload_offset(&b, section::METHOD);
    assert_eq!(parse_edited(|b| b[me] = 3), Err(BlobError::BadCode { field: Field::Method, offset: me, code: 3 }));
    assert_eq!(
        parse_edited(|b| b[me + 1] = 4),
        Err(BlobError::BadCode { field: Field::Form, offset: me + 1, code: 4 })
    );
    assert_eq!(
        parse_edited(|b| b[me..me + 2].copy_from_slice(&[1, 2])),
        Err(BlobError::BadCode { field: Field::Form, offset: me + 1, code: 2 })
    );
    assert_eq!(
        parse_edited(|b| b[me + 1] = 0),
        Err(BlobError::BadCode { field: Field::Form, offset: me + 1, code: 0 })
    );
    assert_eq!(parse_edited(|b| b[me + 7] = 0x80), Err(BlobError::ReservedNotZero { offset: me + 7 }));
}

#[test]
fn polynomial_order_and_term_limits() {
    let quad = paper::quadratic_truth().unwrap();
    let p = paper::params(quad, Method::CoefficientCorrection);
    let mut buf = [0u8; 4096];
    let n = blob::encode(&p, &Meta::default(), &mut buf).unwrap();
    let b = buf[..n].to_vec();
    let m = payload_offset(&b, section::TEMP_MODEL);
    assert_eq!((b[m], b[m + 1]), (1, 2));
    let edited = |edit: &dyn Fn(&mut Vec<u8>)| {
        let mut c = b.clone();
        edit(&mut c);
        seal(&mut c);
        blob::parse(&c).map(|_| ())
    };
    for order in [0u8, 5, 255] {
        assert_eq!(edited(&|c| c[m + 1] = order), Err(BlobError::UnsupportedOrder { order, offset: m + 1 }));
    }
    assert_eq!(
        edited(&|c| c[m + 1] = 3),
        Err(BlobError::SectionLength { id: section::TEMP_MODEL, offset: m, len: 8 + 2 * 96 })
    );
    // Term 2 (ΔT²) α_y: |α|·ΔT_max² must stay within 100 V; ΔT_max = 60 °C here (T0 = 20,
    // range −40…70), so the limit is 100/3600 ≈ 0.0278 V/°C².
    let off = m + 8 + 96 + 8;
    assert_eq!(edited(&|c| put_f64(c, off, 0.027)), Ok(()));
    assert_eq!(
        edited(&|c| put_f64(c, off, 0.028)),
        Err(BlobError::OutOfRange { field: Field::TermAlpha { term: 1, axis: 1 }, offset: off })
    );
    // β_zz of term 1 (ΔT¹, value 3 + 8 = 11): |β|·60 ≤ 1.
    let off = m + 8 + 8 * 11;
    assert_eq!(
        edited(&|c| put_f64(c, off, 0.017)),
        Err(BlobError::OutOfRange { field: Field::TermRelK { term: 0, row: 2, col: 2 }, offset: off })
    );
    // 0.015·60 = 0.9: within the per-term limit, but K_zz(−40 °C) falls to about 0.1× its T0
    // value.
    assert_eq!(edited(&|c| put_f64(c, off, 0.015)), Err(BlobError::SingularInRange));
}

#[test]
fn container_errors_are_rejected() {
    let b = typical();
    let entry = |id: u16| 16 + 12 * entry_index(&b, id);
    // Reserved header word and flag bits.
    assert_eq!(parse_edited(|b| b[13] = 1), Err(BlobError::ReservedNotZero { offset: 12 }));
    let e = entry(section::METHOD);
    assert_eq!(parse_edited(|b| b[e + 2] |= 2), Err(BlobError::ReservedNotZero { offset: e + 2 }));
    // An unknown section flagged required is refused; the same one optional is skipped.
    let e = entry(section::SERIAL);
    assert_eq!(
        parse_edited(|b| b[e..e + 4].copy_from_slice(&[0x00, 0x02, 1, 0])),
        Err(BlobError::UnknownRequiredSection { id: 0x0200, offset: e })
    );
    let mut c = b.clone();
    c[e..e + 4].copy_from_slice(&[0x00, 0x02, 0, 0]);
    seal(&mut c);
    let parsed = blob::parse(&c).expect("unknown optional section skipped");
    assert_eq!(parsed.meta.serial, "");
    assert_eq!(parsed.blob.section(0x0200), Some(SERIAL.as_bytes()));
    // Missing mandatory section (renamed to an unknown optional id).
    let e = entry(section::METHOD);
    assert_eq!(
        parse_edited(|b| b[e..e + 4].copy_from_slice(&[0x77, 0x00, 0, 0])),
        Err(BlobError::MissingSection(section::METHOD))
    );
    // Duplicate id.
    let e = entry(section::TOOL_VERSION);
    assert_eq!(
        parse_edited(|b| b[e..e + 2].copy_from_slice(&section::SERIAL.to_le_bytes())),
        Err(BlobError::DuplicateSection { id: section::SERIAL, offset: e })
    );
    // Overlap: the method section moved onto the last 8 bytes of the model section.
    let (e, m_end) = (entry(section::METHOD), {
        let t = table(&b)[entry_index(&b, section::TEMP_MODEL)];
        t.2 + t.3
    });
    assert_eq!(
        parse_edited(|b| b[e + 4..e + 8].copy_from_slice(&((m_end - 8) as u32).to_le_bytes())),
        Err(BlobError::OverlappingSections { first: section::TEMP_MODEL, second: section::METHOD })
    );
    // Out of bounds: into the CRC, into the table, and a length that wraps.
    let len = b.len();
    assert_eq!(
        parse_edited(|b| b[e + 4..e + 8].copy_from_slice(&((len - 6) as u32).to_le_bytes())),
        Err(BlobError::SectionOutOfBounds { id: section::METHOD, offset: e })
    );
    assert_eq!(
        parse_edited(|b| b[e + 4..e + 8].copy_from_slice(&20u32.to_le_bytes())),
        Err(BlobError::SectionOutOfBounds { id: section::METHOD, offset: e })
    );
    assert_eq!(
        parse_edited(|b| b[e + 8..e + 12].copy_from_slice(&u32::MAX.to_le_bytes())),
        Err(BlobError::SectionOutOfBounds { id: section::METHOD, offset: e })
    );
    // Section count: beyond the maximum, and a table that would run into the CRC.
    assert_eq!(parse_edited(|b| b[6] = 17), Err(BlobError::BadSectionCount(17)));
    let mut tiny = vec![0u8; 28];
    tiny[..4].copy_from_slice(b"BCAL");
    tiny[4] = 1;
    tiny[6] = 1;
    tiny[8] = 28;
    seal(&mut tiny);
    assert_eq!(blob::parse(&tiny).map(|_| ()), Err(BlobError::BadSectionCount(1)));
    // Wrong section length of a fixed-size section.
    let e = entry(section::CONSTANTS);
    let off = payload_offset(&b, section::CONSTANTS);
    assert_eq!(
        parse_edited(|b| b[e + 8..e + 12].copy_from_slice(&96u32.to_le_bytes())),
        Err(BlobError::SectionLength { id: section::CONSTANTS, offset: off, len: 96 })
    );
}

#[test]
fn metadata_is_checked() {
    let b = typical();
    let s = payload_offset(&b, section::SERIAL);
    assert_eq!(parse_edited(|b| b[s + 3] = 0x07), Err(BlobError::OutOfRange { field: Field::Serial, offset: s }));
    assert_eq!(parse_edited(|b| b[s] = 0xc3), Err(BlobError::OutOfRange { field: Field::Serial, offset: s }));
    let d = payload_offset(&b, section::CAL_DATE);
    for (y, m, day) in [(2023u16, 2u8, 29u8), (2024, 13, 1), (2024, 4, 31), (1969, 12, 31), (2024, 1, 0)] {
        let mut v = y.to_le_bytes().to_vec();
        v.extend([m, day]);
        assert_eq!(
            parse_edited(|b| b[d..d + 4].copy_from_slice(&v)),
            Err(BlobError::OutOfRange { field: Field::CalDate, offset: d }),
            "{y}-{m}-{day}"
        );
    }
    let t = payload_offset(&b, section::TOOL_VERSION);
    assert_eq!(parse_edited(|b| b[t] = 0x7f), Err(BlobError::OutOfRange { field: Field::ToolVersion, offset: t }));
}

#[test]
fn singular_k_is_rejected_by_parser_and_encoder() {
    // Every |K_ij| is half of |K_ii| (the limit), yet (1, 1, 1) is in the null space.
    let mut p = paper_params();
    p.constants.k_v_per_g = [[1.0, -0.5, -0.5], [-0.5, 1.0, -0.5], [-0.5, -0.5, 1.0]];
    p.model = TempModel::Poly { order: 1, coef: [CoefDelta::zero(); 4] };
    let mut buf = [0u8; 4096];
    assert_eq!(blob::encode(&p, &Meta::default(), &mut buf), Err(BlobError::SingularK));
    // Built from the spec (the parser alone).
    let b = build(&spec_sections(&p, "", None, ""));
    assert_eq!(blob::parse(&b).map(|_| ()), Err(BlobError::SingularK));
}

#[test]
fn encoder_refuses_what_it_cannot_write() {
    let p = paper_params();
    let mut small = [0u8; 100];
    let n = typical().len();
    assert_eq!(blob::encode(&p, &meta(), &mut small), Err(BlobError::BufferTooSmall { needed: n }));
    let mut buf = [0u8; 4096];
    let long = "X".repeat(33);
    assert!(matches!(
        blob::encode(&p, &Meta { serial: &long, ..meta() }, &mut buf),
        Err(BlobError::OutOfRange { field: Field::Serial, .. })
    ));
    let bad =
        paper::params(TempModel::Poly { order: 5, coef: [CoefDelta::zero(); 4] }, Method::OutputCorrection(Form::Full));
    assert!(matches!(blob::encode(&bad, &meta(), &mut buf), Err(BlobError::UnsupportedOrder { order: 5, .. })));
    let mut wrong = p;
    wrong.constants.u0_v[1] = 1e3;
    assert!(matches!(
        blob::encode(&wrong, &meta(), &mut buf),
        Err(BlobError::OutOfRange { field: Field::U0 { axis: 1 }, .. })
    ));
}

#[test]
fn error_messages_name_field_and_offset() {
    let e = BlobError::OutOfRange { field: Field::K { row: 0, col: 1 }, offset: 0x68 };
    let s = e.to_string();
    assert!(s.starts_with("k_V_per_g[0][1] at byte 0x0068 out of range"), "{s}");
    let e = BlobError::OutOfRange { field: Field::KnotRelK { knot: 2, row: 1, col: 0 }, offset: 0x1f0 };
    assert!(e.to_string().starts_with("temperature_model.knot[2].rel_k[1][0] at byte 0x01f0"), "{e}");
    assert!(!BlobError::CrcMismatch { stored: 1, computed: 2 }.to_string().contains('\n'));
}

// ---- vibration sections ---------------------------------------------------------------------

#[test]
fn vibration_sections_equal_the_spec_and_parse_to_their_configuration() {
    let v = vib_params();
    let b = typical_vib();
    assert_eq!((typical().len(), b.len()), (596, 1260), "sizes quoted in docs/measurements.md");
    assert_eq!(b, build(&spec_sections_vib(&paper_params(), Some(&v), SERIAL, Some((2024, 2, 29)), TOOL)));
    // Both sections written REQUIRED, in id order between the range and the serial.
    let ids: Vec<(u16, u16)> = table(&b).iter().map(|e| (e.0, e.1)).collect();
    assert_eq!(&ids[3..6], &[(0x0004, 1), (0x0005, 1), (0x0006, 1)]);
    assert_eq!(table(&b)[entry_index(&b, section::VIBRATION)].3, 8 + 3 * 80);
    assert_eq!(table(&b)[entry_index(&b, section::FLIGHT_PHASES)].3, 8 + 8 * 48);
    let parsed = blob::parse(&b).expect("valid");
    assert_eq!(parsed.params, paper_params());
    assert_eq!(parsed.vibration, Some(v));
    assert_eq!(parsed.meta, meta());
    // The pair the firmware builds equals the configurations built directly.
    let (cal, vib) = parsed.configs::<f32>().unwrap();
    assert_eq!(cal, Calibration::<f32>::new(&paper_params()).unwrap());
    assert_eq!(vib, VibrationConfig::<f32>::new(&v).unwrap());
    let mut region = [0xffu8; blob::MAX_BLOB_BYTES];
    region[..b.len()].copy_from_slice(&b);
    assert_eq!(blob::load_region::<f32>(&region), Ok((cal, vib)));
    // Without the sections (every blob written before them): no VE model.
    let plain = typical();
    let old = blob::parse(&plain).unwrap();
    assert_eq!(old.vibration, None);
    assert_eq!(old.vibration_config::<f32>(), Ok(VibrationConfig::none()));
    let mut region = [0xffu8; blob::MAX_BLOB_BYTES];
    region[..typical().len()].copy_from_slice(&typical());
    assert_eq!(blob::load_region::<f64>(&region).map(|p| p.1), Ok(VibrationConfig::none()));
    assert_eq!(blob::load_region::<f32>(&[0xffu8; 64]), Err(BlobError::BadMagic));
    // Coefficients without profiles: no 0x0006 section.
    let mut buf = [0u8; 4096];
    let bare = VibrationParams::new([tables::AL15; 3], Variant::Paper);
    let n = blob::encode_with_vibration(&paper_params(), Some(&bare), &Meta::default(), &mut buf).unwrap();
    assert!(table(&buf[..n]).iter().all(|e| e.0 != section::FLIGHT_PHASES));
    assert_eq!(blob::parse(&buf[..n]).unwrap().vibration, Some(bare));
}

#[test]
fn largest_blob_fits_the_region() {
    let mut p = paper_params();
    let mut knots_c = [0.0; MAX_KNOTS];
    for (i, k) in knots_c.iter_mut().enumerate() {
        *k = -40.0 + 110.0 * i as f64 / (MAX_KNOTS - 1) as f64;
    }
    p.model = TempModel::Pwl { n_knots: MAX_KNOTS as u8, knots_c, at_knot: [CoefDelta::zero(); MAX_KNOTS] };
    let mut v = VibrationParams::new([tables::AL15; 3], Variant::Exact);
    for _ in 0..MAX_PROFILES {
        v.push_profile(Vibration::Random { sigma_g: [1.0; 3], band_hz: (20.0, 2000.0) }).unwrap();
    }
    let long = "X".repeat(32);
    let m = Meta { serial: &long, date: Some(DATE), tool_version: &long };
    let mut buf = [0u8; 4096];
    let n = blob::encode_with_vibration(&p, Some(&v), &m, &mut buf).unwrap();
    assert!(n <= 2048, "{n} bytes");
    let too_many = VibrationParams { n_profiles: 9, ..v };
    assert_eq!(
        blob::encode_with_vibration(&p, Some(&too_many), &m, &mut buf),
        Err(BlobError::ProfileCount { count: 9, offset: 0 })
    );
}

#[test]
fn bad_vibration_sections_are_rejected_naming_the_field() {
    let b = typical_vib();
    let v = payload_offset(&b, section::VIBRATION);
    let coef = |axis: usize, n: usize| v + 8 + 80 * axis + 8 * n;
    // Codes and reserved bytes.
    for code in [0u8, 3, 255] {
        assert_eq!(
            parse_edited_vib(|b| b[v] = code),
            Err(BlobError::BadCode { field: Field::VibVariant, offset: v, code })
        );
    }
    assert_eq!(parse_edited_vib(|b| b[v] = 1), Ok(()));
    assert_eq!(parse_edited_vib(|b| b[v + 7] = 1), Err(BlobError::ReservedNotZero { offset: v + 7 }));
    // Coefficients: non-finite, and each beyond its limit (just inside is accepted).
    for (n, lim) in
        [(0usize, 1.0), (1, 0.1), (2, 1e-2), (3, 1e-3), (4, 1e-4), (5, 1e-5), (6, 0.5), (7, 0.5), (8, 1e-2), (9, 1e-2)]
    {
        let axis = n % 3;
        let off = coef(axis, n);
        let field = Field::VibCoef { axis: axis as u8, coef: n as u8 };
        assert_eq!(blob::coefficient_limit(n as u8), lim);
        assert_eq!(parse_edited_vib(|b| put_f64(b, off, -lim)), Ok(()), "{field}");
        assert_eq!(
            parse_edited_vib(|b| put_f64(b, off, lim * 1.001)),
            Err(BlobError::OutOfRange { field, offset: off })
        );
        for bad in [f64::NAN, f64::INFINITY] {
            assert_eq!(parse_edited_vib(|b| put_f64(b, off, bad)), Err(BlobError::OutOfRange { field, offset: off }));
        }
    }
    let ve = table_entry(&b, section::VIBRATION);
    assert_eq!(
        parse_edited_vib(|b| b[ve + 8] = 240),
        Err(BlobError::SectionLength { id: section::VIBRATION, offset: v, len: 240 })
    );
    // Profiles: count, kinds, levels, bands.
    let f = payload_offset(&b, section::FLIGHT_PHASES);
    let prof = |i: usize| f + 8 + 48 * i;
    assert_eq!(b[f], 8);
    assert_eq!(parse_edited_vib(|b| b[f] = 0), Err(BlobError::ProfileCount { count: 0, offset: f }));
    assert_eq!(parse_edited_vib(|b| b[f] = 9), Err(BlobError::ProfileCount { count: 9, offset: f }));
    assert_eq!(
        parse_edited_vib(|b| b[f] = 7),
        Err(BlobError::SectionLength { id: section::FLIGHT_PHASES, offset: f, len: 8 + 8 * 48 })
    );
    assert_eq!(parse_edited_vib(|b| b[f + 3] = 1), Err(BlobError::ReservedNotZero { offset: f + 3 }));
    assert_eq!(
        parse_edited_vib(|b| b[prof(3)] = 3),
        Err(BlobError::BadCode { field: Field::ProfileKind { profile: 3 }, offset: prof(3), code: 3 })
    );
    assert_eq!(parse_edited_vib(|b| b[prof(3) + 1] = 1), Err(BlobError::ReservedNotZero { offset: prof(3) + 1 }));
    // Profile 0 is a sine: amplitudes signed within 10 g, the fifth value reserved.
    assert_eq!(b[prof(0)], 1);
    assert_eq!(parse_edited_vib(|b| put_f64(b, prof(0) + 16, -10.0)), Ok(()));
    assert_eq!(
        parse_edited_vib(|b| put_f64(b, prof(0) + 16, 10.5)),
        Err(BlobError::OutOfRange { field: Field::ProfileAmp { profile: 0, axis: 1 }, offset: prof(0) + 16 })
    );
    assert_eq!(
        parse_edited_vib(|b| put_f64(b, prof(0) + 32, -1.0)),
        Err(BlobError::OutOfRange { field: Field::ProfileFreq { profile: 0 }, offset: prof(0) + 32 })
    );
    assert_eq!(parse_edited_vib(|b| b[prof(0) + 40] = 1), Err(BlobError::ReservedNotZero { offset: prof(0) + 40 }));
    // Profile 2 is random: σ ≥ 0, band ordered.
    assert_eq!(b[prof(2)], 2);
    assert_eq!(
        parse_edited_vib(|b| put_f64(b, prof(2) + 8, -0.1)),
        Err(BlobError::OutOfRange { field: Field::ProfileSigma { profile: 2, axis: 0 }, offset: prof(2) + 8 })
    );
    assert_eq!(
        parse_edited_vib(|b| put_f64(b, prof(2) + 40, 10.0)),
        Err(BlobError::OutOfRange { field: Field::ProfileBand { profile: 2, end: 1 }, offset: prof(2) + 40 })
    );
    assert_eq!(
        parse_edited_vib(|b| put_f64(b, prof(2) + 32, f64::NAN)),
        Err(BlobError::OutOfRange { field: Field::ProfileBand { profile: 2, end: 0 }, offset: prof(2) + 32 })
    );
    // Profile 7 is "none": its values must be zero.
    assert_eq!(b[prof(7)], 0);
    assert_eq!(parse_edited_vib(|b| b[prof(7) + 20] = 1), Err(BlobError::ReservedNotZero { offset: prof(7) + 20 }));
    // Profiles without the coefficients (0x0005 renamed to an unknown optional id).
    let e = 16 + 12 * entry_index(&b, section::VIBRATION);
    assert_eq!(
        parse_edited_vib(|b| b[e..e + 4].copy_from_slice(&[0x77, 0x00, 0, 0])),
        Err(BlobError::MissingSection(section::VIBRATION))
    );
    // A parser that did not know the sections would refuse the blob (they are REQUIRED): here
    // the flags are checked as written.
    assert!(table(&b).iter().filter(|e| e.0 == 0x0005 || e.0 == 0x0006).all(|e| e.1 == 1));
}

fn table_entry(b: &[u8], id: u16) -> usize {
    16 + 12 * entry_index(b, id)
}

#[test]
fn vibration_error_messages_name_the_key() {
    let e = BlobError::OutOfRange { field: Field::VibCoef { axis: 1, coef: 3 }, offset: 0x1a0 };
    assert!(e.to_string().starts_with("vibration.y.k3_g_per_g3 at byte 0x01a0 out of range"), "{e}");
    let e = BlobError::OutOfRange { field: Field::ProfileBand { profile: 4, end: 1 }, offset: 0x300 };
    assert!(e.to_string().starts_with("vibration.profile[4].band_Hz[1] at byte 0x0300"), "{e}");
    let e = BlobError::ProfileCount { count: 9, offset: 0x2f0 };
    assert!(e.to_string().contains("vibration.profile") && e.to_string().contains("9 profiles"), "{e}");
}

// ---- round trip over random valid calibrations -------------------------------------------------

prop_compose! {
    fn arb_constants()(
        diag in prop::array::uniform3(prop_oneof![0.05f64..5.0, -5.0f64..-0.05]),
        cross in prop::array::uniform6(-0.02f64..0.02),
        u0 in prop::array::uniform3(-0.5f64..0.5),
    ) -> Constants<f64> {
        let mut k = [[0.0; 3]; 3];
        let mut c = cross.iter();
        for i in 0..3 {
            for j in 0..3 {
                k[i][j] = if i == j { diag[i] } else { c.next().unwrap() * diag[i].abs() };
            }
        }
        Constants { k_v_per_g: k, u0_v: u0 }
    }
}

/// A coefficient set whose effect at |ΔT| ≤ 100 °C is small: |ΔU0| ≲ 0.05 V, |ΔK/K| ≲ 0.05.
fn arb_coef(power: i32) -> impl Strategy<Value = CoefDelta<f64>> {
    let s = 100f64.powi(power);
    prop::array::uniform12(-1.0f64..1.0).prop_map(move |a| {
        let mut d = CoefDelta::from_array(&a);
        d.du0_v.iter_mut().for_each(|x| *x *= 0.05 / s);
        d.rel_k.iter_mut().flatten().for_each(|x| *x *= 0.05 / s);
        d
    })
}

/// A model whose changes stay small over `range`: polynomial coefficients scaled for
/// |ΔT| ≤ 100 °C, or knots spread over the range (jittered, strictly increasing) so that no
/// end interval is extrapolated far.
fn arb_model(range: (f64, f64)) -> impl Strategy<Value = TempModel<f64>> {
    let poly = (1..=MAX_POLY_ORDER).prop_flat_map(|order| {
        (arb_coef(1), arb_coef(2), arb_coef(3), arb_coef(4)).prop_map(move |(a, b, c, d)| {
            let mut coef = [a, b, c, d];
            coef.iter_mut().skip(order).for_each(|x| *x = CoefDelta::zero());
            TempModel::Poly { order: order as u8, coef }
        })
    });
    let pwl = (2..=MAX_KNOTS).prop_flat_map(move |n| {
        (prop::collection::vec(-0.3f64..0.3, n), prop::collection::vec(arb_coef(0), n)).prop_map(move |(jit, sets)| {
            let mut knots_c = [0.0; MAX_KNOTS];
            let mut at_knot = [CoefDelta::zero(); MAX_KNOTS];
            let step = (range.1 - range.0) / (n - 1) as f64;
            for i in 0..n {
                // Within the format's knot limits ([-100, 200] °C): a range reaching −80 °C with
                // a jittered first knot would otherwise fall below −100 °C.
                knots_c[i] = (range.0 + step * (i as f64 + jit[i])).max(-100.0);
                at_knot[i] = sets[i];
            }
            TempModel::Pwl { n_knots: n as u8, knots_c, at_knot }
        })
    });
    prop_oneof![poly, pwl]
}

fn arb_profile() -> impl Strategy<Value = Vibration<f64>> {
    prop_oneof![
        Just(Vibration::None),
        (prop::array::uniform3(-10.0f64..=10.0), 0.0f64..1e5)
            .prop_map(|(amp_g, freq_hz)| Vibration::Harmonic { amp_g, freq_hz }),
        (prop::array::uniform3(0.0f64..=10.0), 0.0f64..5e4, 1.0f64..5e4)
            .prop_map(|(sigma_g, lo, w)| Vibration::Random { sigma_g, band_hz: (lo, lo + w) }),
    ]
}

fn arb_method() -> impl Strategy<Value = Method> {
    prop::sample::select(all_methods().to_vec())
}

fn arb_params() -> impl Strategy<Value = CalibrationParams> {
    (-20.0f64..40.0, 1.0f64..60.0, 1.0f64..60.0).prop_flat_map(|(t0_c, below, above)| {
        let range = (t0_c - below, t0_c + above);
        (arb_constants(), arb_model(range), arb_method()).prop_map(move |(constants, model, method)| {
            CalibrationParams { constants, t0_c, model, method, temp_range_c: range }
        })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// Encode → parse gives back every value bit for bit, and the bytes are the spec's.
    #[test]
    fn round_trip_is_lossless(p in arb_params(), serial in "[ -~]{0,32}", tool in "[ -~]{0,32}",
                              date in prop::option::of((1970u16..=9999, 1u8..=12, 1u8..=28))) {
        let meta = Meta {
            serial: &serial,
            date: date.map(|(year, month, day)| CalDate { year, month, day }),
            tool_version: &tool,
        };
        let mut buf = [0u8; blob::MAX_BLOB_BYTES];
        let n = blob::encode(&p, &meta, &mut buf).expect("valid calibration encodes");
        prop_assert_eq!(&buf[..n], &build(&spec_sections(&p, &serial, date, &tool))[..]);
        let parsed = blob::parse(&buf[..n]).expect("parses");
        prop_assert_eq!(param_bits(&parsed.params), param_bits(&p));
        prop_assert_eq!(parsed.meta, meta);
    }

    /// The same with the vibration sections: coefficients within their limits, profiles of
    /// every kind.
    #[test]
    fn round_trip_with_vibration_is_lossless(
        p in arb_params(),
        cf in prop::array::uniform3(prop::array::uniform10(-1.0f64..1.0)),
        paper_variant in any::<bool>(),
        profiles in prop::collection::vec(arb_profile(), 0..=MAX_PROFILES),
    ) {
        let cf = cf.map(|a| {
            let mut out = [0.0; 10];
            for (n, x) in a.iter().enumerate() {
                out[n] = x * blob::coefficient_limit(n as u8);
            }
            ConversionFunction::from_array(&out)
        });
        let mut v = VibrationParams::new(cf, if paper_variant { Variant::Paper } else { Variant::Exact });
        for prof in &profiles {
            v.push_profile(*prof).unwrap();
        }
        let mut buf = [0u8; blob::MAX_BLOB_BYTES];
        let n = blob::encode_with_vibration(&p, Some(&v), &Meta::default(), &mut buf).expect("encodes");
        prop_assert_eq!(&buf[..n], &build(&spec_sections_vib(&p, Some(&v), "", None, ""))[..]);
        let parsed = blob::parse(&buf[..n]).expect("parses");
        prop_assert_eq!(param_bits(&parsed.params), param_bits(&p));
        let back = parsed.vibration.expect("vibration section");
        let bits = |v: &VibrationParams| -> Vec<u64> {
            let mut out: Vec<u64> = v.cf.iter().flat_map(|c| c.to_array()).map(f64::to_bits).collect();
            out.push(v.n_profiles as u64);
            out
        };
        prop_assert_eq!(bits(&back), bits(&v));
        prop_assert_eq!(back, v);
        prop_assert!(parsed.configs::<f32>().is_ok());
    }

    /// Arbitrary bytes are rejected without a panic (random bytes never carry the magic, a
    /// valid length and a matching CRC together).
    #[test]
    fn arbitrary_bytes_are_rejected(bytes in prop::collection::vec(any::<u8>(), 0..700)) {
        prop_assert!(blob::parse(&bytes).is_err());
    }

    /// A valid header around random contents: the parser gets past the CRC and must still
    /// never panic.
    #[test]
    fn sealed_random_contents_are_handled(mut bytes in prop::collection::vec(any::<u8>(), 20..700), n in 0u16..20) {
        let len = bytes.len();
        bytes[..4].copy_from_slice(b"BCAL");
        bytes[4..6].copy_from_slice(&1u16.to_le_bytes());
        bytes[6..8].copy_from_slice(&n.to_le_bytes());
        bytes[8..12].copy_from_slice(&(len as u32).to_le_bytes());
        seal(&mut bytes);
        let _ = blob::parse(&bytes);
    }
}

/// A value written over one of the vibration sections' numbers: often within the limits,
/// sometimes just outside, negative, zero of either sign or not finite.
fn arb_vib_value() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -10.0f64..=10.0,
        1 => 0.0f64..=2e5,
        1 => prop::sample::select(vec![0.0, -0.0, 10.0, -10.0, 10.000001, 1e5, 1.00000001e5, 1e-3, 1.1e-2]),
        1 => prop::sample::select(vec![f64::NAN, f64::INFINITY, f64::NEG_INFINITY, f64::MIN_POSITIVE / 2.0]),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]
    /// The parser checks the vibration sections value by value and does not run
    /// `VibrationParams::validate` again: whatever the sections hold, a blob it accepts
    /// passes `validate`, and its configuration is `VibrationConfig::new`'s.
    #[test]
    fn vibration_parser_accepts_only_what_validate_accepts(
        coefs in prop::collection::vec(prop::option::weighted(0.03, arb_vib_value()), 30),
        values in prop::collection::vec(prop::option::weighted(0.4, arb_vib_value()), 5 * 8),
    ) {
        let mut b = typical_vib();
        let at = payload_offset(&b, section::VIBRATION);
        for (n, x) in coefs.iter().enumerate() {
            if let Some(x) = x {
                put_f64(&mut b, at + 8 + 8 * n, *x);
            }
        }
        let at = payload_offset(&b, section::FLIGHT_PHASES);
        for (n, x) in values.iter().enumerate() {
            // Profile n / 5, its value n % 5 (after the kind's 8 bytes).
            if let Some(x) = x {
                put_f64(&mut b, at + 8 + 48 * (n / 5) + 8 + 8 * (n % 5), *x);
            }
        }
        seal(&mut b);
        if let Ok(parsed) = blob::parse(&b) {
            let v = parsed.vibration.expect("vibration section");
            prop_assert_eq!(v.validate(), Ok(()));
            prop_assert_eq!(parsed.vibration_config::<f32>(), Ok(VibrationConfig::new(&v).unwrap()));
        }
    }
}

// ---- thermal dynamics (section 0x0007) -----------------------------------------------------

/// A unit with every stage of the thermal dynamics on.
fn dyn_params() -> ThermalDynamics<f64> {
    ThermalDynamics {
        lag_tau_s: 150.0,
        hysteresis_width_c: 0.3,
        self_heating_c: 1.2,
        self_heating_tau_s: 600.0,
        bias_play_width_c: 0.5,
        bias_play_g: [20e-6, -15e-6, 0.0],
    }
}

/// The typical blob with the vibration sections and the thermal-dynamics section.
fn typical_dyn() -> Vec<u8> {
    let mut buf = [0u8; blob::MAX_BLOB_BYTES];
    let n = blob::encode_with_dynamics(&paper_params(), Some(&vib_params()), Some(&dyn_params()), &meta(), &mut buf)
        .expect("encode");
    buf[..n].to_vec()
}

/// The section as the spec lays it out: layout version 1, 7 zero bytes, 8 f64.
fn spec_dynamics(d: &ThermalDynamics<f64>) -> Sec {
    let mut p = vec![1u8, 0, 0, 0, 0, 0, 0, 0];
    let b = d.bias_play_g;
    p.extend(f64s(&[
        d.lag_tau_s,
        d.hysteresis_width_c,
        d.self_heating_c,
        d.self_heating_tau_s,
        d.bias_play_width_c,
        b[0],
        b[1],
        b[2],
    ]));
    (0x0007, 1, p)
}

#[test]
fn dynamics_section_equals_the_spec_and_parses_to_its_parameters() {
    let b = typical_dyn();
    let mut spec = spec_sections_vib(&paper_params(), Some(&vib_params()), SERIAL, Some((2024, 2, 29)), TOOL);
    spec.insert(6, spec_dynamics(&dyn_params()));
    assert_eq!(b, build(&spec));
    assert_eq!(b.len(), 1340, "size quoted in docs/calibration-blob.md");
    assert_eq!(table(&b)[entry_index(&b, section::THERMAL_DYNAMICS)].3, blob::DYNAMICS_BYTES);
    let parsed = blob::parse(&b).expect("valid");
    assert_eq!(parsed.dynamics, Some(dyn_params()));
    assert_eq!(parsed.vibration, Some(vib_params()));
    assert_eq!(parsed.params, paper_params());
    let fixed = parsed.dynamics_at_rate(1e-3f32).unwrap().unwrap();
    assert_eq!(*fixed.params(), dyn_params().cast::<f32>());
    // Without the section (every blob written before it): no dynamics.
    for old in [typical(), typical_vib()] {
        let p = blob::parse(&old).unwrap();
        assert_eq!(p.dynamics, None);
        assert_eq!(p.dynamics_at_rate(1e-3f32), Ok(None));
    }
    // Dynamics alone, without the vibration sections.
    let mut buf = [0u8; 4096];
    let n = blob::encode_with_dynamics(&paper_params(), None, Some(&dyn_params()), &Meta::default(), &mut buf).unwrap();
    let p = blob::parse(&buf[..n]).unwrap();
    assert_eq!((p.vibration, p.dynamics), (None, Some(dyn_params())));
    // A period that is not finite and positive is refused by name.
    assert_eq!(parsed.dynamics_at_rate(0.0f32), Err(BlobError::Dynamics(DynamicsError::SamplePeriod)));
}

#[test]
fn every_single_bit_flip_and_truncation_of_a_dynamics_blob_is_rejected() {
    let b = typical_dyn();
    assert_every_bit_flip_rejected(&b);
    assert_every_truncation_rejected(&b);
}

#[test]
fn bad_dynamics_sections_are_rejected_naming_the_field() {
    let b = typical_dyn();
    let at = payload_offset(&b, section::THERMAL_DYNAMICS);
    let edited = |edit: &dyn Fn(&mut Vec<u8>)| {
        let mut c = b.clone();
        edit(&mut c);
        seal(&mut c);
        blob::parse(&c).map(|_| ())
    };
    // Each value just outside its range, and NaN, names its key and offset.
    let outside = [-1e-9, 50.0 + 1e-9, -50.0 - 1e-9, 1e5 + 1e-6, -1e-12, 0.1 + 1e-12, -0.1 - 1e-12, f64::INFINITY];
    for (param, bad) in outside.iter().enumerate() {
        let off = at + 8 + 8 * param;
        for x in [*bad, f64::NAN] {
            let got = edited(&|c| put_f64(c, off, x));
            let want = BlobError::OutOfRange { field: Field::Dynamics { param: param as u8 }, offset: off };
            // Parameter 1 at 50 + 1e-9 is outside; param 2 at −50 − 1e-9 too; the list above
            // pairs each parameter with a value outside its own range.
            assert_eq!(got, Err(want), "param {param} = {x}");
        }
    }
    // Limits themselves are accepted.
    for (param, ok) in [(0usize, 1e5), (1, 50.0), (2, -50.0), (3, 0.0), (4, 50.0), (5, 0.1), (6, -0.1)] {
        assert_eq!(edited(&|c| put_f64(c, at + 8 + 8 * param, ok)), Ok(()), "param {param} = {ok}");
    }
    // Layout version, reserved bytes, length.
    assert_eq!(edited(&|c| c[at] = 2), Err(BlobError::BadCode { field: Field::DynamicsLayout, offset: at, code: 2 }));
    assert_eq!(edited(&|c| c[at + 7] = 1), Err(BlobError::ReservedNotZero { offset: at + 7 }));
    let e = entry_index(&b, section::THERMAL_DYNAMICS);
    assert_eq!(
        edited(&|c| c[16 + 12 * e + 8] = 64),
        Err(BlobError::SectionLength { id: section::THERMAL_DYNAMICS, offset: at, len: 64 })
    );
    // A bias play without a width names the first nonzero gain.
    let got = edited(&|c| put_f64(c, at + 8 + 8 * 4, 0.0));
    assert_eq!(got, Err(BlobError::OutOfRange { field: Field::Dynamics { param: 5 }, offset: at + 8 + 40 }));
    let msg = got.unwrap_err().to_string();
    assert!(msg.starts_with("thermal_dynamics.bias_play_mg[0] at byte"), "{msg}");
    let msg = edited(&|c| put_f64(c, at + 8, -1.0)).unwrap_err().to_string();
    assert!(msg.starts_with("thermal_dynamics.lag_tau_s at byte"), "{msg}");
    // The section is REQUIRED: a parser that did not know it would refuse the blob.
    assert_eq!(table(&b)[e].1, blob::FLAG_REQUIRED);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]
    /// Whatever the section holds, the parser accepts exactly what
    /// `ThermalDynamics::validate` accepts, and the encoder round-trips it bit for bit.
    #[test]
    fn dynamics_parser_accepts_exactly_what_validate_accepts(
        a in proptest::array::uniform8(prop_oneof![
            Just(0.0), -0.2f64..0.2, -60.0f64..60.0, 0.0f64..2e5, Just(f64::NAN), Just(-0.0)
        ])
    ) {
        let d = ThermalDynamics::from_array(&a);
        let mut b = typical_dyn();
        let at = payload_offset(&b, section::THERMAL_DYNAMICS);
        for (n, x) in a.iter().enumerate() {
            put_f64(&mut b, at + 8 + 8 * n, *x);
        }
        seal(&mut b);
        let parsed = blob::parse(&b);
        prop_assert_eq!(parsed.is_ok(), d.validate().is_ok(), "{:?}: {:?}", d, parsed.map(|_| ()));
        if let Ok(p) = parsed {
            let got = p.dynamics.unwrap().to_array().map(f64::to_bits);
            prop_assert_eq!(got, a.map(f64::to_bits));
        }
    }
}
