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
/// Smallest |K_ii| \[V/g\]: a row whose scale factor is below it (an all-zero row) has no
/// accelerometer in it.
pub const MIN_K_DIAG_V_PER_G: f64 = 1.0e-6;
/// Largest |K_ij| \[V/g\] and |U0_i| \[V\].
pub const MAX_ABS_V: f64 = 1.0e3;

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
            if !(c.k_v_per_g[i][i].abs() >= MIN_K_DIAG_V_PER_G) {
                bail!(
                    "{file}:{line}, column `{}`: {} V/g: the scale factor of an accelerometer must be at least {MIN_K_DIAG_V_PER_G} V/g in magnitude",
                    K_NAMES[i][i],
                    c.k_v_per_g[i][i]
                );
            }
            for (j, k) in c.k_v_per_g[i].iter().enumerate() {
                if k.abs() > MAX_ABS_V {
                    bail!("{file}:{line}, column `{}`: {k} V/g is beyond ±{MAX_ABS_V}", K_NAMES[i][j]);
                }
            }
            if c.u0_v[i].abs() > MAX_ABS_V {
                bail!("{file}:{line}, column `{}`: {} V is beyond ±{MAX_ABS_V}", U0_NAMES[i], c.u0_v[i]);
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
