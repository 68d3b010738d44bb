//! The value parsers of the numeric command-line options: every number given on the command
//! line is finite and in its range, or the option is refused by name before anything runs
//! (clap names the option: `invalid value 'nan' for '--t0 <T0>': not a finite number`).

/// The longest duration an option takes \[s\] (about 116 days, longer than any recording).
pub const MAX_DURATION_S: f64 = 1.0e7;

/// The shortest duration a window or block option takes \[s\] (one sample at 1 kHz).
pub const MIN_DURATION_S: f64 = 1.0e-3;

fn number(s: &str) -> Result<f64, String> {
    let x: f64 = s.trim().parse().map_err(|_| format!("`{s}` is not a number"))?;
    if !x.is_finite() { Err(format!("`{s}` is not a finite number")) } else { Ok(x) }
}

/// A finite number.
pub fn finite(s: &str) -> Result<f64, String> {
    number(s)
}

/// A temperature [°C] within −273.15 … 1000 (the core's calibrated ranges are far inside).
pub fn temp_c(s: &str) -> Result<f64, String> {
    let x = number(s)?;
    if !(-273.15..=1000.0).contains(&x) {
        return Err(format!("{x} °C is outside −273.15 … 1000 °C"));
    }
    Ok(x)
}

/// A finite number greater than 0 and at most `1e9`.
pub fn positive(s: &str) -> Result<f64, String> {
    let x = number(s)?;
    if !(x > 0.0 && x <= 1.0e9) {
        return Err(format!("{x}: must be greater than 0 and at most 1e9"));
    }
    Ok(x)
}

/// A duration \[s\] from 0 to [`MAX_DURATION_S`].
pub fn duration_or_zero_s(s: &str) -> Result<f64, String> {
    let x = number(s)?;
    if !(0.0..=MAX_DURATION_S).contains(&x) {
        return Err(format!("{x} s: must be from 0 to {MAX_DURATION_S:e} s"));
    }
    Ok(x)
}

/// A duration \[s\] from [`MIN_DURATION_S`] to [`MAX_DURATION_S`].
pub fn duration_s(s: &str) -> Result<f64, String> {
    let x = number(s)?;
    if !(MIN_DURATION_S..=MAX_DURATION_S).contains(&x) {
        return Err(format!("{x} s: must be from {MIN_DURATION_S} to {MAX_DURATION_S:e} s"));
    }
    Ok(x)
}
