//! Tables of the 12 constants measured at several temperatures (the form of
//! `data/paper-constants.csv`: `temp_C`, `Kxx` … `Kzz`, `U0x` … `U0z`, `#` comments), read
//! through [`Table`] (the recordings' tokenizer and caps) with errors that name the file, line
//! and column.

use crate::recording::Table;
use anyhow::bail;
use bins_comp::Constants;
use std::path::Path;

/// The K columns, row-major: `K_NAMES[i][j]` is the signal of accelerometer i per g along j.
pub const K_NAMES: [[&str; 3]; 3] = [["Kxx", "Kxy", "Kxz"], ["Kyx", "Kyy", "Kyz"], ["Kzx", "Kzy", "Kzz"]];
/// The zero-offset columns.
pub const U0_NAMES: [&str; 3] = ["U0x", "U0y", "U0z"];

/// The temperatures a table may hold [°C] (the simulator's range).
pub const MIN_TEMP_C: f64 = -150.0;
/// See [`MIN_TEMP_C`].
pub const MAX_TEMP_C: f64 = 250.0;
/// The physical limits of the constants: the firmware's ([`bins_comp::blob::limits`]), so that
/// a table is refused exactly where a calibration made from it could not be flashed: |K_ii|
/// within 1e-3 … 1e3 V/g, |K_ij| (i ≠ j) at most half |K_ii|, |U0_i| at most 100 V.
pub use bins_comp::blob::limits;

/// Reads a constants table: (temperature [°C], constants) per data row, in file order.
pub fn read(path: &Path) -> anyhow::Result<Vec<(f64, Constants<f64>)>> {
    from_table(&Table::read(path)?)
}

/// Parses the text of a constants table (errors name the line and column).
pub fn parse(text: &str) -> anyhow::Result<Vec<(f64, Constants<f64>)>> {
    from_table(&Table::from_reader(text.as_bytes(), "constants table")?)
}

fn from_table(table: &Table) -> anyhow::Result<Vec<(f64, Constants<f64>)>> {
    let t_col = table.column("temp_C")?;
    let mut k_cols = [[0usize; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            k_cols[i][j] = table.column(K_NAMES[i][j])?;
        }
    }
    let u0_cols = [table.column(U0_NAMES[0])?, table.column(U0_NAMES[1])?, table.column(U0_NAMES[2])?];
    let mut out: Vec<(f64, Constants<f64>)> = Vec::new();
    for (line, cells) in &table.rows {
        let num = |c: usize| table.number(*line, cells, c);
        let mut c = Constants { k_v_per_g: [[0.0; 3]; 3], u0_v: [0.0; 3] };
        for i in 0..3 {
            c.u0_v[i] = num(u0_cols[i])?;
            for j in 0..3 {
                c.k_v_per_g[i][j] = num(k_cols[i][j])?;
            }
        }
        let t = num(t_col)?;
        let file = table.file.display();
        if !(MIN_TEMP_C..=MAX_TEMP_C).contains(&t) {
            bail!("{file}:{line}, column `temp_C`: {t} °C is outside {MIN_TEMP_C} … {MAX_TEMP_C} °C");
        }
        for i in 0..3 {
            let k_ii = c.k_v_per_g[i][i];
            let (lo, hi) = (limits::SCALE_FACTOR_MIN_V_PER_G, limits::SCALE_FACTOR_MAX_V_PER_G);
            if !(lo..=hi).contains(&k_ii.abs()) {
                bail!(
                    "{file}:{line}, column `{}`: {k_ii} V/g: the scale factor of an accelerometer must be within {lo} … {hi} V/g in magnitude",
                    K_NAMES[i][i]
                );
            }
            for (j, k) in c.k_v_per_g[i].iter().enumerate() {
                let max = limits::CROSS_RATIO_MAX * k_ii.abs();
                if j != i && !(k.abs() <= max) {
                    bail!(
                        "{file}:{line}, column `{}`: {k} V/g is beyond ±{max} V/g ({} of the row's scale factor {k_ii}: a cross-axis sensitivity, not an axis)",
                        K_NAMES[i][j],
                        limits::CROSS_RATIO_MAX
                    );
                }
            }
            if !(c.u0_v[i].abs() <= limits::U0_MAX_V) {
                bail!("{file}:{line}, column `{}`: {} V is beyond ±{} V", U0_NAMES[i], c.u0_v[i], limits::U0_MAX_V);
            }
        }
        if out.iter().any(|(u, _)| *u == t) {
            bail!("{}:{line}: temperature {t} °C appears twice", table.file.display());
        }
        out.push((t, c));
    }
    if out.is_empty() {
        bail!("{}: no data rows", table.file.display());
    }
    Ok(out)
}
