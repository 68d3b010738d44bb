//! The CALIB flash region: its one accessor and the calibration it holds. Shared by the
//! firmware and the link check (`mod calib;` in each), so both images read the region the same
//! way and the link check proves the blob parser panic-free.
//!
//! The region is the last 4 KiB of code memory (`memory.x`, bounds `__scalib`/`__ecalib`). A
//! calibration blob is written there separately from the program image (by the programmer, or
//! by QEMU's generic loader: `-device loader,file=CAL.bin,addr=0x003ff000`). It is read once,
//! at boot, and checked completely (`bins_comp::blob::parse_region`) before anything uses it.

use bins_comp::Pipeline;
use bins_comp::blob::{self, BlobError, MAX_BLOB_BYTES, ParsedCalibration};

/// A copy of the CALIB region in RAM (at most [`MAX_BLOB_BYTES`]).
pub struct Region {
    bytes: [u8; MAX_BLOB_BYTES],
    len: usize,
}

impl Region {
    /// The region's bytes.
    pub fn bytes(&self) -> &[u8] {
        self.bytes.get(..self.len).unwrap_or(&[])
    }
}

/// The one accessor of the CALIB region: copies it into RAM with volatile byte reads.
pub fn read_region() -> Region {
    unsafe extern "C" {
        /// First byte of the CALIB region (defined in `memory.x`).
        static __scalib: u8;
        /// One past the last byte of the CALIB region (defined in `memory.x`).
        static __ecalib: u8;
    }
    let start = (&raw const __scalib).expose_provenance();
    let end = (&raw const __ecalib).expose_provenance();
    let len = end.saturating_sub(start).min(MAX_BLOB_BYTES);
    let mut region = Region { bytes: [0; MAX_BLOB_BYTES], len };
    for (i, b) in region.bytes.iter_mut().take(len).enumerate() {
        // SAFETY: [__scalib, __ecalib) is the CALIB region that memory.x reserves at the end of
        // code memory: mapped and readable at any time, written only before reset (programmer
        // or loader), never by this program, and holding no Rust object (the `.calib` section
        // is empty), so a read through a raw pointer aliases nothing. `start + i < end`: every
        // address read lies inside the region. Volatile, so the reads are not assumed to see
        // constant memory the compiler knows.
        *b = unsafe { core::ptr::read_volatile(core::ptr::with_exposed_provenance::<u8>(start + i)) };
    }
    region
}

/// The per-sample step the region's calibration defines, checked completely: the calibration,
/// the vibration-error configuration (sections 0x0005/0x0006; [`VibrationConfig::none`](bins_comp::VibrationConfig::none)
/// without them) and the thermal dynamics at the sampling period `dt_s` \[s\] (section
/// 0x0007; none without it), with the parsed blob (serial, date, tool version). An error
/// means: compensate with [`Calibration::uncalibrated`](bins_comp::Calibration::uncalibrated) and subtract nothing.
pub fn calibration(region: &Region, dt_s: f32) -> Result<(Pipeline<f32>, ParsedCalibration<'_>), BlobError> {
    let parsed = blob::parse_region(region.bytes())?;
    let (cal, vib) = parsed.configs::<f32>()?;
    let mut pipeline = Pipeline::new(cal, vib);
    if let Some(d) = parsed.dynamics_at_rate(dt_s)? {
        pipeline = pipeline.with_dynamics(d);
    }
    Ok((pipeline, parsed))
}
