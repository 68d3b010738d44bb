//! `bins-cal verify`'s `verify.csv`, read by its header: the columns are found by name, so a
//! column added or moved by `verify` does not shift what the demo reads.

use std::path::Path;

use crate::task::Result;

/// The columns the demo reads, by their header names.
const COLUMNS: [&str; 5] = ["temp_C", "pos", "method", "dg_mg", "phase"];

/// One check dwell's |g| error under one method.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Row {
    /// The dwell's temperature [°C].
    pub(crate) temp_c: f64,
    /// The check position (`CP1` … `CP6`).
    pub(crate) pos: String,
    /// The method's label (`method 1`, `T0 constants`, `replayed`, …).
    pub(crate) method: String,
    /// Δg = |a| − 1 g \[mg\].
    pub(crate) dg_mg: f64,
    /// `hold`, `heating` or `cooling`.
    pub(crate) phase: String,
}

/// The rows of the `verify.csv` at `path`; an error names the file and the missing column or
/// the line and field that is not a number.
pub(crate) fn read(path: &Path) -> Result<Vec<Row>> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    parse(&text).map_err(|e| format!("{}: {e}", path.display()))
}

fn parse(text: &str) -> Result<Vec<Row>> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').map(str::trim).collect();
    let mut at = [0usize; COLUMNS.len()];
    for (slot, name) in at.iter_mut().zip(COLUMNS) {
        *slot = header.iter().position(|h| *h == name).ok_or(format!("line 1: no column `{name}` in the header"))?;
    }
    let [t, p, m, d, ph] = at;
    let mut rows = Vec::new();
    for (n, line) in lines.enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let f: Vec<&str> = line.split(',').collect();
        let field = |i: usize| f.get(i).copied().ok_or(format!("line {}: only {} fields", n + 2, f.len()));
        let number = |i: usize| -> Result<f64> {
            let s = field(i)?;
            s.trim().parse().map_err(|_| format!("line {}: `{}` = `{s}` is not a number", n + 2, header[i]))
        };
        rows.push(Row {
            temp_c: number(t)?,
            pos: field(p)?.to_string(),
            method: field(m)?.to_string(),
            dg_mg: number(d)?,
            phase: field(ph)?.to_string(),
        });
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_are_found_by_name_in_any_order() {
        let a = parse("temp_C,pos,method,dg_mg,phase\n-9.6,CP1,method 1,0.034,hold\n").unwrap();
        let b = parse("phase,dg_mg,extra,method,pos,temp_C\nhold,0.034,x,method 1,CP1,-9.6\n").unwrap();
        assert_eq!(a, b);
        assert_eq!(
            a[0],
            Row { temp_c: -9.6, pos: "CP1".into(), method: "method 1".into(), dg_mg: 0.034, phase: "hold".into() }
        );
    }

    #[test]
    fn a_missing_column_or_a_bad_number_is_named() {
        let e = parse("temp_C,pos,method,phase\n").unwrap_err();
        assert!(e.contains("line 1") && e.contains("`dg_mg`"), "{e}");
        let e = parse("temp_C,pos,method,dg_mg,phase\n20,CP1,method 1,abc,hold\n").unwrap_err();
        assert!(e.contains("line 2") && e.contains("dg_mg") && e.contains("abc"), "{e}");
    }
}
