//! Fuzzes `bins_comp::blob::parse` and `parse_region` with arbitrary bytes. Besides "no panic,
//! no out-of-bounds access" (the sanitizer's job) it checks two properties on every input
//! the parser accepts:
//!
//! - the parsed calibration, vibration configuration and thermal dynamics build in `f32`
//!   (parse ran the same checks), and
//! - encoding the parsed contents and parsing that again gives the same contents.
//!
//! Inputs whose declared length is honoured and whose CRC matches are rare for random bytes,
//! so the target also re-seals every input (writes a matching length and CRC) and parses that
//! copy: the fuzzer then explores the section table and the sections themselves.
#![no_main]

use bins_comp::blob;
use libfuzzer_sys::fuzz_target;

fn check(bytes: &[u8]) {
    let _ = blob::parse_region(bytes);
    if let Ok(parsed) = blob::parse(bytes) {
        assert!(parsed.configs::<f32>().is_ok(), "parsed but does not build");
        assert!(parsed.dynamics.is_none_or(|d| d.validate().is_ok()), "dynamics parsed but invalid");
        assert!(parsed.dynamics_at_rate(1.0e-3f32).is_ok(), "dynamics parsed but do not build");
        let mut buf = [0u8; blob::MAX_BLOB_BYTES];
        let (vib, dynamics) = (parsed.vibration.as_ref(), parsed.dynamics.as_ref());
        let n = blob::encode_with_dynamics(&parsed.params, vib, dynamics, &parsed.meta, &mut buf)
            .expect("parsed contents re-encode");
        let again = blob::parse(&buf[..n]).expect("re-encoded blob parses");
        assert_eq!(again.params, parsed.params);
        assert_eq!(again.vibration, parsed.vibration);
        assert_eq!(again.dynamics.map(|d| d.to_array().map(f64::to_bits)), parsed.dynamics.map(|d| d.to_array().map(f64::to_bits)));
        assert_eq!(again.meta, parsed.meta);
    }
}

fuzz_target!(|data: &[u8]| {
    check(data);
    if (blob::MIN_BLOB_BYTES..=blob::MAX_BLOB_BYTES).contains(&data.len()) {
        let mut sealed = data.to_vec();
        sealed[..4].copy_from_slice(&blob::MAGIC);
        sealed[4..6].copy_from_slice(&blob::FORMAT_VERSION.to_le_bytes());
        sealed[8..12].copy_from_slice(&(data.len() as u32).to_le_bytes());
        assert!(blob::reseal(&mut sealed));
        check(&sealed);
    }
});
