//! CSV files in the tests, read and rewritten through one path, the `csv` crate (the crate that
//! splits the cells of recordings and tables in `recording`): the `#` lines before the header
//! are comments, cells are trimmed, columns are found by header name, and a row may be shorter
//! than the header (trailing optional cells left out, as in `data/real/imucal-session.csv`).
//! Tests that plant bad input edit the cells and write the file back with the `csv` writer.
//! Not every test uses every function.

#![allow(dead_code)]

use std::path::Path;

/// A CSV file's comment lines, header and rows.
#[derive(Clone, Debug, PartialEq)]
pub struct Csv {
    /// The lines before the header that start with `#`, as they are.
    pub comments: Vec<String>,
    /// The header names.
    pub header: Vec<String>,
    /// The rows' cells.
    pub rows: Vec<Vec<String>>,
}

impl Csv {
    /// The CSV in `text`.
    pub fn parse(text: &str) -> Csv {
        let comments = text.lines().take_while(|l| l.starts_with('#')).map(String::from).collect();
        let mut r = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .comment(Some(b'#'))
            .trim(csv::Trim::All)
            .from_reader(text.as_bytes());
        let mut records = r.records().map(|rec| rec.expect("a CSV row").iter().map(String::from).collect());
        let header = records.next().expect("a header row");
        Csv { comments, header, rows: records.collect() }
    }

    /// The CSV in the file at `path`.
    pub fn read(path: &Path) -> Csv {
        Csv::parse(&std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())))
    }

    /// The position of column `name`.
    pub fn col(&self, name: &str) -> usize {
        self.header.iter().position(|h| h == name).unwrap_or_else(|| panic!("no column `{name}` in {:?}", self.header))
    }

    /// The cell of column `name` in `row` (empty where the row is short).
    pub fn cell<'a>(&self, row: &'a [String], name: &str) -> &'a str {
        row.get(self.col(name)).map_or("", String::as_str)
    }

    /// The number in column `name` of `row`.
    pub fn num(&self, row: &[String], name: &str) -> f64 {
        let c = self.cell(row, name);
        c.parse().unwrap_or_else(|_| panic!("`{name}` = `{c}` is not a number"))
    }

    /// The numbers of column `name`, row by row.
    pub fn column(&self, name: &str) -> Vec<f64> {
        self.rows.iter().map(|r| self.num(r, name)).collect()
    }

    /// Removes column `name` from the header and every row.
    pub fn remove_column(&mut self, name: &str) {
        let k = self.col(name);
        self.header.remove(k);
        for r in &mut self.rows {
            if k < r.len() {
                r.remove(k);
            }
        }
    }

    /// The file's text: the comment lines, then the header and the rows written by the `csv`
    /// writer (cells quoted where they need it).
    pub fn to_text(&self) -> String {
        let mut w = csv::WriterBuilder::new().flexible(true).from_writer(Vec::new());
        w.write_record(&self.header).expect("the header");
        for r in &self.rows {
            w.write_record(r).expect("a row");
        }
        let body = String::from_utf8(w.into_inner().expect("written")).expect("UTF-8");
        self.comments.iter().map(|c| format!("{c}\n")).collect::<String>() + &body
    }

    /// Writes the file's text to `path`.
    pub fn write(&self, path: &Path) {
        std::fs::write(path, self.to_text()).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    }
}
