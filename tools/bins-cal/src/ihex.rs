//! Intel HEX output (I32HEX): extended-linear-address records (type 04) for the upper 16
//! address bits, 16-byte data records (type 00), an end-of-file record (type 01).

use std::fmt::Write;

/// Bytes per data record.
pub const RECORD_BYTES: usize = 16;

fn record(out: &mut String, kind: u8, addr16: u16, data: &[u8]) {
    let mut sum = data.len() as u8;
    sum = sum.wrapping_add((addr16 >> 8) as u8).wrapping_add(addr16 as u8).wrapping_add(kind);
    let _ = write!(out, ":{:02X}{:04X}{:02X}", data.len(), addr16, kind);
    for &b in data {
        let _ = write!(out, "{b:02X}");
        sum = sum.wrapping_add(b);
    }
    let _ = writeln!(out, "{:02X}", sum.wrapping_neg());
}

/// `data` placed at `base` as Intel HEX text. Fails if the data would run past 4 GiB.
pub fn encode(base: u32, data: &[u8]) -> Result<String, String> {
    if (base as u64) + (data.len() as u64) > 1 << 32 {
        return Err(format!("{} bytes at 0x{base:08X} run past the 32-bit address space", data.len()));
    }
    let mut out = String::new();
    let mut upper: Option<u16> = None;
    let mut addr = base as u64;
    let mut rest = data;
    while !rest.is_empty() {
        let hi = (addr >> 16) as u16;
        if upper != Some(hi) {
            record(&mut out, 0x04, 0, &hi.to_be_bytes());
            upper = Some(hi);
        }
        // A record never crosses a 64 KiB boundary.
        let to_boundary = 0x1_0000 - (addr & 0xffff) as usize;
        let n = rest.len().min(RECORD_BYTES).min(to_boundary);
        record(&mut out, 0x00, addr as u16, &rest[..n]);
        addr += n as u64;
        rest = &rest[n..];
    }
    record(&mut out, 0x01, 0, &[]);
    Ok(out)
}
