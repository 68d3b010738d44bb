//! The CALIB flash region's address: `ORIGIN` of the `CALIB` line of the firmware's
//! `memory.x`, so the Intel HEX output lands where the firmware reads its calibration.

use std::path::{Path, PathBuf};

/// The address used when no `memory.x` with a CALIB region is found: the last 4 KiB of the
/// MPS2-AN386's 4 MiB of code memory.
pub const DEFAULT_CALIB_ORIGIN: u32 = 0x003F_F000;

/// `ORIGIN` of the `CALIB` region in a linker script's `MEMORY` block, if there is one whose
/// expression this understands: numbers (decimal or `0x` hex, optional `K`/`M` suffix)
/// joined by `+` and `-`.
pub fn calib_origin(memory_x: &str) -> Option<u32> {
    let text = strip_comments(memory_x);
    for line in text.lines() {
        let line = line.trim();
        let Some(rest) = line.strip_prefix("CALIB") else { continue };
        let rest = rest.trim_start();
        if !rest.starts_with(':') && !rest.starts_with('(') {
            continue;
        }
        let origin = rest.split_once("ORIGIN")?.1;
        let expr = origin.trim_start().strip_prefix('=')?;
        let expr = expr.split(',').next()?;
        return eval(expr);
    }
    None
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

/// The CALIB origin and where it came from (for the tool's message).
pub fn resolve_calib_origin(explicit: Option<&Path>) -> anyhow::Result<(u32, String)> {
    match find_memory_x(explicit) {
        Some(p) => {
            let text = std::fs::read_to_string(&p).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?;
            match calib_origin(&text) {
                Some(a) => Ok((a, format!("CALIB ORIGIN in {}", p.display()))),
                None if explicit.is_some() => {
                    Err(anyhow::anyhow!("{}: no CALIB region with a readable ORIGIN", p.display()))
                }
                None => Ok((DEFAULT_CALIB_ORIGIN, format!("default (no CALIB region in {})", p.display()))),
            }
        }
        None => Ok((DEFAULT_CALIB_ORIGIN, "default (no memory.x found)".to_string())),
    }
}
