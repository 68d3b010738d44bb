//! The CALIB flash region's address: `ORIGIN` of the `CALIB` line of the firmware's
//! `memory.x`, so the Intel HEX output lands where the firmware reads its calibration.

use std::path::{Path, PathBuf};

/// The address used when no `memory.x` with a CALIB region is found: the last 4 KiB of the
/// MPS2-AN386's 4 MiB of code memory.
pub const DEFAULT_CALIB_ORIGIN: u32 = 0x003F_F000;

/// The CALIB region of a linker script: where the blob goes and how many bytes it may take.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CalibRegion {
    /// `ORIGIN` (a multiple of [`ALIGN`]).
    pub origin: u32,
    /// `LENGTH` \[bytes\].
    pub length: u32,
}

/// The alignment `ORIGIN(CALIB)` must have: the firmware reads the blob by words, and the
/// linker script places `.calib` at `ALIGN(4)`.
pub const ALIGN: u32 = 4;

impl CalibRegion {
    /// `blob` as Intel HEX at the region's origin; refused when it is longer than the region.
    pub fn hex(&self, blob: &[u8]) -> Result<String, String> {
        if blob.len() as u64 > u64::from(self.length) {
            return Err(format!(
                "the {}-byte blob does not fit the CALIB region's LENGTH of {} bytes at 0x{:08X}",
                blob.len(),
                self.length,
                self.origin
            ));
        }
        crate::ihex::encode(self.origin, blob)
    }
}

/// The `CALIB` region of a linker script's `MEMORY` block: `Ok(None)` when there is none;
/// an error when its `ORIGIN` or `LENGTH` is not an expression this understands (numbers,
/// decimal or `0x` hex, optional `K`/`M` suffix, joined by `+` and `-`), the origin is not a
/// multiple of [`ALIGN`], the length is 0 or the region runs past 4 GiB, or there are two
/// CALIB regions.
pub fn calib_region(memory_x: &str) -> Result<Option<CalibRegion>, String> {
    let text = strip_comments(memory_x);
    let mut found: Option<(usize, CalibRegion)> = None;
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        let Some(rest) = line.strip_prefix("CALIB") else { continue };
        let rest = rest.trim_start();
        if !rest.starts_with(':') && !rest.starts_with('(') {
            continue;
        }
        if let Some((first, _)) = found {
            return Err(format!("line {}: a second CALIB region (the first is on line {})", n + 1, first + 1));
        }
        let value = |key: &str| -> Result<u32, String> {
            let expr = rest
                .split_once(key)
                .and_then(|(_, r)| r.trim_start().strip_prefix('='))
                .ok_or_else(|| format!("line {}: CALIB has no `{key} =`", n + 1))?;
            let expr = expr.split([',', '}']).next().unwrap_or_default();
            eval(expr)
                .ok_or_else(|| format!("line {}: CALIB {key} `{}` is not an expression read here", n + 1, expr.trim()))
        };
        let region = CalibRegion { origin: value("ORIGIN")?, length: value("LENGTH")? };
        if !region.origin.is_multiple_of(ALIGN) {
            return Err(format!("line {}: CALIB ORIGIN 0x{:08X} is not a multiple of {ALIGN}", n + 1, region.origin));
        }
        if region.length == 0 || u64::from(region.origin) + u64::from(region.length) > 1 << 32 {
            return Err(format!(
                "line {}: CALIB LENGTH {} at 0x{:08X} is empty or runs past 4 GiB",
                n + 1,
                region.length,
                region.origin
            ));
        }
        found = Some((n, region));
    }
    Ok(found.map(|f| f.1))
}

/// `ORIGIN` of the `CALIB` region (see [`calib_region`]), if there is one and it is valid.
pub fn calib_origin(memory_x: &str) -> Option<u32> {
    calib_region(memory_x).ok().flatten().map(|r| r.origin)
}

fn strip_comments(s: &str) -> String {
    let mut out = String::new();
    let mut rest = s;
    while let Some(start) = rest.find("/*") {
        out.push_str(&rest[..start]);
        match rest[start..].find("*/") {
            Some(end) => rest = &rest[start + end + 2..],
            None => return out,
        }
    }
    out.push_str(rest);
    out
}

fn eval(expr: &str) -> Option<u32> {
    let mut total: i64 = 0;
    let mut sign = 1i64;
    let mut seen_term = false;
    let mut token = String::new();
    let flush = |token: &mut String, total: &mut i64, sign: i64| -> Option<bool> {
        let t = token.trim();
        if t.is_empty() {
            return Some(false);
        }
        let (digits, mult) = match t.as_bytes().last()? {
            b'K' | b'k' => (&t[..t.len() - 1], 1024),
            b'M' | b'm' => (&t[..t.len() - 1], 1024 * 1024),
            _ => (t, 1),
        };
        let v = match digits.strip_prefix("0x").or_else(|| digits.strip_prefix("0X")) {
            Some(h) => i64::from_str_radix(h, 16).ok()?,
            None => digits.parse::<i64>().ok()?,
        };
        *total += sign * v * mult;
        token.clear();
        Some(true)
    };
    for c in expr.chars() {
        match c {
            '+' | '-' => {
                seen_term |= flush(&mut token, &mut total, sign)?;
                sign = if c == '+' { 1 } else { -1 };
            }
            c if c.is_whitespace() => {}
            c => token.push(c),
        }
    }
    seen_term |= flush(&mut token, &mut total, sign)?;
    if !seen_term {
        return None;
    }
    u32::try_from(total).ok()
}

/// The `memory.x` to read: `explicit` if given, else the first `memory.x` in the current
/// directory or its ancestors, else the one of the repository this tool was built from.
pub fn find_memory_x(explicit: Option<&Path>) -> Option<PathBuf> {
    if let Some(p) = explicit {
        return Some(p.to_path_buf());
    }
    if let Ok(cwd) = std::env::current_dir() {
        for dir in cwd.ancestors() {
            let p = dir.join("memory.x");
            if p.is_file() {
                return Some(p);
            }
        }
    }
    let built = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../memory.x");
    built.is_file().then_some(built)
}

/// The region used when no `memory.x` with a CALIB region is found.
pub const DEFAULT_CALIB_REGION: CalibRegion = CalibRegion { origin: DEFAULT_CALIB_ORIGIN, length: 4096 };

/// The CALIB region and where it came from (for the tool's message). Errors name the
/// linker script and its line.
pub fn resolve_calib_region(explicit: Option<&Path>) -> anyhow::Result<(CalibRegion, String)> {
    match find_memory_x(explicit) {
        Some(p) => {
            let text = crate::fsio::read_text(&p)?;
            match calib_region(&text).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))? {
                Some(r) => Ok((r, format!("CALIB ORIGIN in {}", p.display()))),
                None if explicit.is_some() => {
                    Err(anyhow::anyhow!("{}: no CALIB region with a readable ORIGIN", p.display()))
                }
                None => Ok((DEFAULT_CALIB_REGION, format!("default (no CALIB region in {})", p.display()))),
            }
        }
        None => Ok((DEFAULT_CALIB_REGION, "default (no memory.x found)".to_string())),
    }
}

/// The blob as Intel HEX placed in the CALIB region of `explicit` (or the `memory.x` found,
/// or the default); returns the text, the region and where it came from. Errors name the
/// linker script.
pub fn calib_hex(explicit: Option<&Path>, blob: &[u8]) -> anyhow::Result<(String, CalibRegion, String)> {
    let (region, from) = resolve_calib_region(explicit)?;
    let hex = region.hex(blob).map_err(|e| anyhow::anyhow!("{from}: {e}"))?;
    Ok((hex, region, from))
}
