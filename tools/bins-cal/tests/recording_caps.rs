//! The recording reader's caps: a file without line breaks (`/dev/zero`) or a line with tens
//! of thousands of cells is refused within a second, in bounded memory, with one line naming
//! the file and the line.

use bins_cal::recording::{ErrorKind, MAX_COLUMNS, MAX_LINE_BYTES, Reader, Row};
use std::io::{BufReader, Cursor, Read};
use std::path::Path;
use std::time::{Duration, Instant};

const HEADER: &str = "t_s,ux_V,uy_V,uz_V,temp_C\n";

/// The error of reading `src` to its end (header and rows).
fn error_of(src: impl std::io::BufRead, name: &str) -> bins_cal::recording::Error {
    let mut r = match Reader::new(src, name) {
        Ok(r) => r,
        Err(e) => return e,
    };
    let mut row = Row::default();
    loop {
        match r.read_row(&mut row) {
            Ok(true) => continue,
            Ok(false) => panic!("{name}: read to the end without an error"),
            Err(e) => return e,
        }
    }
}

#[test]
fn a_file_without_line_breaks_is_refused_within_the_line_cap() {
    let t = Instant::now();
    let e = error_of(BufReader::new(std::fs::File::open("/dev/zero").unwrap()), "/dev/zero");
    assert!(t.elapsed() < Duration::from_secs(1), "{:?}", t.elapsed());
    assert_eq!((e.kind.clone(), e.line), (ErrorKind::LineTooLong, 1), "{e}");
    assert!(e.to_string().starts_with("/dev/zero:1: line longer than"), "{e}");
    // The same after a valid header and row: the line number is the long line's.
    let long = Cursor::new(format!("{HEADER}0,0,0,0,20\n")).chain(std::io::repeat(b'7').take(5 << 20));
    let e = error_of(BufReader::new(long), "rec.csv");
    assert_eq!((e.kind.clone(), e.line), (ErrorKind::LineTooLong, 3), "{e}");
}

#[test]
fn a_line_at_the_cap_is_read_and_one_byte_more_is_not() {
    // A row whose extra cell fills the line to exactly the cap.
    let head = "t_s,ux_V,uy_V,uz_V,temp_C,note\n";
    let prefix = "0,0,0,0,20,";
    let at_cap = format!("{head}{prefix}{}\n", "a".repeat(MAX_LINE_BYTES - prefix.len()));
    let mut r = Reader::new(Cursor::new(at_cap.as_bytes()), "cap.csv").unwrap();
    let mut row = Row::default();
    assert!(r.read_row(&mut row).unwrap());
    assert_eq!(row.extra[0].len(), MAX_LINE_BYTES - prefix.len());
    let over = format!("{head}{prefix}{}\n", "a".repeat(MAX_LINE_BYTES + 3 - prefix.len()));
    assert_eq!(error_of(Cursor::new(over.as_bytes()), "cap.csv").kind, ErrorKind::LineTooLong);
}

#[test]
fn a_header_or_row_with_too_many_cells_is_refused() {
    // 50 000 empty column names.
    let t = Instant::now();
    let header = format!("{}\n", ",".repeat(50_000));
    let e = error_of(Cursor::new(header.as_bytes()), "wide.csv");
    assert!(t.elapsed() < Duration::from_secs(1), "{:?}", t.elapsed());
    assert_eq!((e.kind.clone(), e.line), (ErrorKind::TooManyCells, 1), "{e}");
    assert!(e.to_string().starts_with("wide.csv:1: more than"), "{e}");
    // 50 000 distinct names after the required ones, and a row of 50 000 cells under a valid
    // header.
    let names: Vec<String> = (0..50_000).map(|i| format!("c{i}")).collect();
    let header = format!("{},{}\n", HEADER.trim_end(), names[..MAX_COLUMNS].join(","));
    let e = error_of(Cursor::new(header.as_bytes()), "wide.csv");
    assert_eq!((e.kind.clone(), e.line), (ErrorKind::TooManyCells, 1), "{e}");
    let row = format!("{HEADER}0,0,0,0,20{}\n", ",1".repeat(50_000));
    let e = error_of(Cursor::new(row.as_bytes()), "wide.csv");
    assert_eq!((e.kind.clone(), e.line), (ErrorKind::TooManyCells, 2), "{e}");
}

/// Exactly [`MAX_COLUMNS`] cells are read, one more is refused, with or without padding (the
/// reader's two ways through a line).
#[test]
fn the_cell_cap_is_exact() {
    let names: Vec<String> = (0..MAX_COLUMNS - 5).map(|i| format!("c{i}")).collect();
    for pad in ["", " "] {
        let header = format!("{},{}\n", HEADER.trim_end(), names.join(&format!("{pad},")));
        let row = format!("0,0,0,0,20{}\n", format!(",{pad}1").repeat(MAX_COLUMNS - 5));
        let mut r = Reader::new(Cursor::new(format!("{header}{row}")), "cap.csv").unwrap();
        let mut got = Row::default();
        assert!(r.read_row(&mut got).unwrap());
        assert_eq!(got.extra.len(), MAX_COLUMNS - 5);
        let over = format!("{header}{}\n", row.trim_end().to_string() + ",1");
        let e = error_of(Cursor::new(over), "cap.csv");
        assert_eq!((e.kind, e.line), (ErrorKind::TooManyCells, 2), "padding {pad:?}");
    }
}

/// The command reading `/dev/zero` as a recording, its address space limited to 100 MiB:
/// one line naming the file and line 1, in under a second.
#[test]
fn the_command_refuses_dev_zero_in_bounded_memory() {
    if !Path::new("/dev/zero").exists() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let bin = env!("CARGO_BIN_EXE_bins-cal");
    let cal = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../calibrations/paper-two-range.toml");
    let script = format!(
        "ulimit -v 102400 && exec '{bin}' verify --check /dev/zero --calib '{}' -o '{}'",
        cal.display(),
        dir.path().join("out").display()
    );
    let t = Instant::now();
    let o = std::process::Command::new("sh").args(["-c", &script]).output().unwrap();
    let elapsed = t.elapsed();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(elapsed < Duration::from_secs(1), "{elapsed:?}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.starts_with("bins-cal: error: /dev/zero:1: line longer than"), "{err}");
}

/// Tables that are not recordings (constants, coefficients) go through the same line reader,
/// tokenizer and caps.
#[test]
fn a_table_is_read_by_header_name_with_the_same_tokenizer_and_caps() {
    use bins_cal::recording::Table;
    let text = "\u{feff}# comment\n\nb , a,\"c, d\"\n1, 2 ,\"x \"\"y\"\"\"\n# between\n3,4,5\n";
    let t = Table::from_reader(Cursor::new(text.as_bytes()), "t.csv").unwrap();
    assert_eq!(t.header, ["b", "a", "c, d"]);
    assert_eq!(
        t.rows,
        [(4, vec!["1".into(), "2".into(), "x \"y\"".into()]), (6, vec!["3".into(), "4".into(), "5".into()])]
    );
    let a = t.column("a").unwrap();
    assert_eq!(t.number(t.rows[1].0, &t.rows[1].1, a).unwrap(), 4.0);
    let e = t.number(t.rows[0].0, &t.rows[0].1, 2).unwrap_err();
    assert_eq!(e.to_string(), "t.csv:4: column 3 `c, d`: `x \"y\"` is not a finite number");
    assert_eq!(t.column("z").unwrap_err().to_string(), "t.csv: missing column `z` in the header");
    let e = Table::from_reader(Cursor::new("a,b\n1,2,3\n".as_bytes()), "t.csv").unwrap_err();
    assert_eq!(e.to_string(), "t.csv:2: 3 cells, the header has 2");
    let t0 = Instant::now();
    let e = Table::read(Path::new("/dev/zero")).unwrap_err();
    assert!(t0.elapsed() < Duration::from_secs(1));
    assert_eq!((e.kind, e.line), (ErrorKind::LineTooLong, 1));
}
