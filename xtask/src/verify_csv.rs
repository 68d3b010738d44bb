//! `bins-cal verify`'s `verify.csv`, read by the `csv` crate and its header: the columns are
//! found by name, so a column added or moved by `verify` does not shift what the demo reads.

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
    let mut csv = csv::ReaderBuilder::new().trim(csv::Trim::All).from_reader(text.as_bytes());
    let header = csv.headers().map_err(|e| format!("line 1: {e}"))?.clone();
    let mut at = [0usize; COLUMNS.len()];
    for (slot, name) in at.iter_mut().zip(COLUMNS) {
        *slot = header.iter().position(|h| h == name).ok_or(format!("line 1: no column `{name}` in the header"))?;
    }
    let [t, p, m, d, ph] = at;
    let mut rows = Vec::new();
    for record in csv.records() {
        let f = record.map_err(|e| match e.position() {
            Some(pos) => format!("line {}: {e}", pos.line()),
            None => e.to_string(),
        })?;
        let line = f.position().map_or(0, csv::Position::line);
        let number = |i: usize| -> Result<f64> {
            let s = &f[i];
            s.parse().map_err(|_| format!("line {line}: `{}` = `{s}` is not a number", &header[i]))
        };
        rows.push(Row {
            temp_c: number(t)?,
            pos: f[p].to_string(),
            method: f[m].to_string(),
            dg_mg: number(d)?,
            phase: f[ph].to_string(),
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
        // A quoted label with a comma is one field.
        let c = parse("temp_C,pos,method,dg_mg,phase\n-9.6,CP1,\"poly:2, method 1\",0.034,hold\n").unwrap();
        assert_eq!((c[0].method.as_str(), c[0].dg_mg), ("poly:2, method 1", 0.034));
    }

    #[test]
    fn a_missing_column_or_a_bad_number_is_named() {
        let e = parse("temp_C,pos,method,phase\n").unwrap_err();
        assert!(e.contains("line 1") && e.contains("`dg_mg`"), "{e}");
        let e = parse("temp_C,pos,method,dg_mg,phase\n20,CP1,method 1,abc,hold\n").unwrap_err();
        assert!(e.contains("line 2") && e.contains("dg_mg") && e.contains("abc"), "{e}");
        let e = parse("temp_C,pos,method,dg_mg,phase\n20,CP1,method 1,0.1,hold\n20,CP2,method 1\n").unwrap_err();
        assert!(e.contains("line 3"), "{e}");
    }
}
