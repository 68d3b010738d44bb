//! Recording format v1: the real recording reads completely and gives the independent
//! reference's constants, every error names file, line and column, write → read is exact.

use bins_cal::recording::{Columns, ErrorKind, Reader, Row, VibKind, Writer, read_all};
use bins_comp::ident::six_position;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::io::Cursor;
use std::path::{Path, PathBuf};

fn real() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/real/imucal-session.csv")
}

#[test]
fn real_recording_reads_completely() {
    let path = real();
    let text = std::fs::read_to_string(&path).unwrap();
    let lines = text.lines().count();
    let comment_lines = text.lines().take_while(|l| l.starts_with('#')).count();
    let mut r = Reader::open(&path).unwrap();
    assert_eq!(r.comments().len(), comment_lines);
    assert!(r.comments()[0].starts_with("recording format v1"));
    assert!(r.has_reference());
    assert_eq!(r.extra_columns(), ["src_part"]);
    let mut row = Row::default();
    let (mut n, mut known, mut last_t) = (0usize, 0usize, -1.0);
    let mut sums = [[0.0f64; 3]; 6];
    let mut counts = [0usize; 6];
    while r.read_row(&mut row).unwrap() {
        n += 1;
        assert!(row.t_s > last_t);
        last_t = row.t_s;
        assert_eq!(row.temp_c, 20.0);
        match (row.reference_f_g(), &row.pos) {
            (Some(f), Some(p)) => {
                known += 1;
                assert_eq!(row.vib_kind, Some(VibKind::None));
                assert!(!row.extra[0].is_empty());
                let k: usize = p.strip_prefix("TP").unwrap().parse().unwrap();
                assert_eq!(f, bins_comp::ident::TILTER_POSITIONS_G[k - 1]);
                for i in 0..3 {
                    sums[k - 1][i] += row.u_v[i];
                }
                counts[k - 1] += 1;
            }
            (None, None) => {
                assert_eq!(row.vib_kind, None);
                assert!(row.extra[0].is_empty());
            }
            other => panic!("line {}: reference and pos disagree: {other:?}", row.line),
        }
    }
    // Every data line is a row: nothing skipped, nothing left.
    assert_eq!(n, lines - comment_lines - 1);
    assert_eq!(row.line as usize, lines);
    assert_eq!(known, 3428);
    assert!((last_t - (n - 1) as f64 / 102.4).abs() < 1e-9);
    // The data README's independent reference (imucal's Ferraris calibration): K from the
    // six-position formulas equals it to its printed 6 digits.
    let means: [[f64; 3]; 6] = std::array::from_fn(|k| sums[k].map(|s| s / counts[k] as f64));
    let c = six_position(&means);
    let k_ref = [[0.996608, -0.014782, -0.007457], [0.008598, 1.002399, 0.001848], [0.013643, 0.002050, 1.023302]];
    for i in 0..3 {
        for j in 0..3 {
            assert!((c.k_v_per_g[i][j] - k_ref[i][j]).abs() < 0.6e-6, "K[{i}][{j}] = {}", c.k_v_per_g[i][j]);
        }
    }
    // The bias depends on the estimator by up to 2 mg (README).
    let u0_ref = [0.054752, -0.062814, 0.040659];
    for i in 0..3 {
        assert!((c.u0_v[i] - u0_ref[i]).abs() < 2.5e-3, "U0[{i}] = {}", c.u0_v[i]);
    }
}

/// Reads `text` as file `bad.csv` to its end; the first error.
fn first_error(text: &str) -> bins_cal::recording::Error {
    match Reader::new(Cursor::new(text.as_bytes().to_vec()), "bad.csv") {
        Err(e) => e,
        Ok(r) => {
            for row in r {
                if let Err(e) = row {
                    return e;
                }
            }
            panic!("no error in {text:?}")
        }
    }
}

const HEAD: &str = "# a comment\n# another\nt_s,ux_V,uy_V,uz_V,temp_C,pos\n";

#[test]
fn missing_required_column_names_file_line_and_column() {
    let e = first_error("# c\nt_s,ux_V,uy_V,temp_C\n0,1,2,3\n");
    assert_eq!(e.kind, ErrorKind::MissingColumn("uz_V"));
    assert_eq!(e.line, 2);
    let msg = e.to_string();
    assert!(msg.starts_with("bad.csv:2: ") && msg.contains("`uz_V`"), "{msg}");
    let e = first_error("# only comments\n");
    assert_eq!(e.kind, ErrorKind::NoHeader);
}

#[test]
fn non_numeric_cell_names_file_line_and_column() {
    let e = first_error(&format!("{HEAD}0,1,2,3,20,TP1\n0.01,1,2,x3,20,TP1\n"));
    assert_eq!(e.kind, ErrorKind::NotANumber("x3".into()));
    assert_eq!((e.line, e.column.clone()), (5, Some((4, "uz_V".to_string()))));
    assert_eq!(e.to_string(), "bad.csv:5: column 4 `uz_V`: `x3` is not a finite number");
    // NaN and infinities are not numbers of a recording; an empty required cell is an error.
    let e = first_error(&format!("{HEAD}0,1,NaN,3,20,\n"));
    assert_eq!((e.line, e.column.unwrap().1), (4, "uy_V".to_string()));
    let e = first_error(&format!("{HEAD}0,1,2,3,,\n"));
    assert_eq!((e.kind, e.line, e.column.unwrap().1), (ErrorKind::EmptyRequired, 4, "temp_C".to_string()));
    let e = first_error("t_s,ux_V,uy_V,uz_V,temp_C,vib_kind\n0,1,2,3,4,shake\n");
    assert_eq!((e.kind, e.line, e.column.unwrap().0), (ErrorKind::BadVibKind("shake".into()), 2, 6));
}

#[test]
fn non_increasing_time_names_file_line_and_column() {
    let e = first_error(&format!("{HEAD}0,1,2,3,20,\n0.01,1,2,3,20,\n0.01,1,2,3,20,\n"));
    assert_eq!(e.kind, ErrorKind::TimeNotIncreasing { previous: 0.01, this: 0.01 });
    assert_eq!((e.line, e.column.clone()), (6, Some((1, "t_s".to_string()))));
    assert!(e.to_string().starts_with("bad.csv:6: column 1 `t_s`: "), "{e}");
}

#[test]
fn wrong_cell_count_names_file_line() {
    let e = first_error(&format!("{HEAD}0,1,2,3,20,TP1\n0.01,1,2,20\n"));
    assert_eq!(e.kind, ErrorKind::CellCount { expected: 6, got: 4 });
    assert_eq!(e.line, 5);
    assert!(e.to_string().starts_with("bad.csv:5: 4 cells, the header has 6"), "{e}");
    // Trailing optional cells may be left out (the real recording does); required ones not.
    let r = Reader::new(Cursor::new(format!("{HEAD}0,1,2,3,20\n").into_bytes()), "ok.csv").unwrap();
    let rows: Vec<Row> = r.collect::<Result<_, _>>().unwrap();
    assert_eq!((rows[0].temp_c, rows[0].pos.clone()), (20.0, None));
    let e = first_error(&format!("{HEAD}0,1,2,3\n"));
    assert_eq!((e.kind, e.line), (ErrorKind::CellCount { expected: 6, got: 4 }, 4));
    let e = first_error(&format!("{HEAD}0,1,2,3,20,TP1,extra\n"));
    assert_eq!((e.kind, e.line), (ErrorKind::CellCount { expected: 6, got: 7 }, 4));
    let e = first_error(&format!("{HEAD}0,1,2,3,20,\"TP1\n"));
    assert_eq!((e.kind, e.line), (ErrorKind::UnterminatedQuote, 4));
}

/// The format's own rules where a plain CSV reader (the `csv` crate by itself) reads otherwise:
/// spaces around an unquoted cell are not part of it, inside quotes they are; a quoted cell
/// ends on its line; a blank data line is a row (of one cell); a byte order mark not at the
/// start of the file is part of the header name; a row longer than any read buffer keeps the
/// line numbers of the rows after it.
#[test]
fn cells_quotes_blank_lines_and_long_rows_as_the_format_says() {
    let head = "t_s,ux_V,uy_V,uz_V,temp_C,pos,note\n";
    let text = format!("{head} 0 ,\t1, 2 ,3 ,20,\" TP 1 \",  \"a \"\"b\"\"\" \n");
    let rows: Vec<Row> = Reader::new(Cursor::new(text), "f.csv").unwrap().collect::<Result<_, _>>().unwrap();
    assert_eq!((rows[0].t_s, rows[0].u_v, rows[0].temp_c), (0.0, [1.0, 2.0, 3.0], 20.0));
    assert_eq!((rows[0].pos.as_deref(), rows[0].extra[0].as_str()), (Some(" TP 1 "), "a \"b\""));
    // A quote opened and not closed on its line is refused there, even when a later line
    // would close it.
    let e = first_error(&format!("{head}0,1,2,3,20,\"TP1\n1,1,2,3,20,x\",y\n"));
    assert_eq!((e.kind, e.line), (ErrorKind::UnterminatedQuote, 2));
    let e = first_error(&format!("{head}0,1,2,3,20,TP1,\n\n1,1,2,3,20,TP1,\n"));
    assert_eq!((e.kind, e.line), (ErrorKind::CellCount { expected: 7, got: 1 }, 3));
    let e = first_error(&format!("# unit 7\n\u{feff}{head}"));
    assert_eq!((e.kind, e.line), (ErrorKind::MissingColumn("t_s"), 2));
    let long = "n".repeat(300_000);
    let e = first_error(&format!("{head}0,1,2,3,20,TP1,{long}\n1,1,2,3,20,TP1,{long}\n1,1,2,3,20,TP1,x\n"));
    assert_eq!((e.kind, e.line), (ErrorKind::TimeNotIncreasing { previous: 1.0, this: 1.0 }, 4));
}

#[test]
fn reader_stops_after_an_error() {
    let text = format!("{HEAD}0,1,2,3,20,\nx,1,2,3,20,\n1,1,2,3,20,\n");
    let r = Reader::new(Cursor::new(text.into_bytes()), "bad.csv").unwrap();
    let items: Vec<_> = r.collect();
    assert_eq!(items.len(), 2);
    assert!(items[0].is_ok() && items[1].is_err());
}

#[test]
fn open_names_a_missing_file() {
    let e = Reader::open(Path::new("/nonexistent/rec.csv")).err().unwrap();
    assert!(e.to_string().starts_with("/nonexistent/rec.csv: "), "{e}");
}

fn random_row(rng: &mut ChaCha8Rng, t: f64) -> Row {
    // Values across magnitudes, signs, and with the last bits set: the exactness test.
    // Columns with a physical range (signals and temperatures below 100, forces below 1000)
    // up to their limits, the others up to 1e30.
    let mut x = |top: i32| {
        let m: f64 = rng.random_range(-1.0..1.0);
        let e: i32 = rng.random_range(-30..top);
        m * 10f64.powi(e)
    };
    let mut row = Row {
        line: 0,
        t_s: t,
        u_v: [x(2), x(2), x(2)],
        temp_c: x(2),
        f_g: [Some(x(3)), None, Some(x(3))],
        vib_kind: Some(VibKind::Random),
        vib_g: [Some(x(3)), Some(x(3)), Some(0.0)],
        vib_hz: Some(x(30)),
        vib_bw_hz: None,
        chamber_c: Some(x(2)),
        pos: Some("CP3".into()),
        power_s: Some(t + 1e-7),
        extra: vec!["a, \"quoted\" cell".into(), String::new()],
    };
    if rng.random_bool(0.3) {
        row.clear_reference();
        row.pos = None;
    }
    row
}

#[test]
fn write_then_read_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rt.csv");
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut columns = Columns::all();
    columns.extra = vec!["note".into(), "src".into()];
    let mut rows = Vec::new();
    let mut t = 0.0;
    for _ in 0..5000 {
        t += rng.random_range(1e-9..1.0);
        rows.push(random_row(&mut rng, t));
    }
    {
        let f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut w = Writer::new(f, &path, columns, &["unit: SN 0042", "second comment"]).unwrap();
        for r in &rows {
            w.write_row(r).unwrap();
        }
        assert_eq!(w.rows(), 5000);
        w.finish().unwrap();
    }
    let (comments, back) = read_all(&path).unwrap();
    assert_eq!(comments, ["unit: SN 0042", "second comment"]);
    assert_eq!(back.len(), rows.len());
    for (i, (a, b)) in rows.iter().zip(&back).enumerate() {
        assert_eq!(b.line as usize, i + 4);
        let mut b = b.clone();
        b.line = 0;
        assert_eq!(*a, b, "row {i}");
    }
}

#[test]
fn real_recording_copies_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("copy.csv");
    let mut r = Reader::open(&real()).unwrap();
    let comments: Vec<String> = r.comments().to_vec();
    let c: Vec<&str> = comments.iter().map(String::as_str).collect();
    let mut w = Writer::new(Vec::new(), &out, Columns::of_reader(&r), &c).unwrap();
    let mut row = Row::default();
    let mut original = Vec::new();
    while r.read_row(&mut row).unwrap() {
        w.write_row(&row).unwrap();
        original.push(row.clone());
    }
    std::fs::write(&out, w.finish().unwrap()).unwrap();
    let (c2, back) = read_all(&out).unwrap();
    assert_eq!(c2, comments);
    assert_eq!(back.len(), original.len());
    for (a, b) in original.iter().zip(&back) {
        assert_eq!(
            (a.t_s, a.u_v, a.f_g, a.vib_kind, &a.pos, &a.extra),
            (b.t_s, b.u_v, b.f_g, b.vib_kind, &b.pos, &b.extra)
        );
    }
}

#[test]
fn writer_refuses_what_the_reader_would_reject() {
    let mut w = Writer::new(Vec::new(), "w.csv", Columns::default(), &[]).unwrap();
    let mut row = Row { t_s: 1.0, ..Row::default() };
    w.write_row(&row).unwrap();
    let e = w.write_row(&row).err().unwrap();
    assert!(matches!(e.kind, ErrorKind::TimeNotIncreasing { .. }));
    assert_eq!((e.line, e.column.clone().unwrap().1), (3, "t_s".to_string()));
    row.t_s = 2.0;
    row.u_v[1] = f64::NAN;
    let e = w.write_row(&row).err().unwrap();
    assert_eq!(e.column.unwrap(), (3, "uy_V".to_string()));
    assert!(Writer::new(Vec::new(), "w.csv", Columns::default(), &["two\nlines"]).is_err());
    let cols = Columns { extra: vec!["t_s".into()], ..Columns::default() };
    assert!(Writer::new(Vec::new(), "w.csv", cols, &[]).is_err());
    // Nor a value outside its column's physical range.
    row.u_v[1] = 0.5;
    row.temp_c = 250.0;
    let e = w.write_row(&row).err().unwrap();
    assert!(matches!(e.kind, ErrorKind::OutOfRange { .. }), "{e}");
    assert_eq!(e.column.unwrap(), (5, "temp_C".to_string()));
}

#[test]
fn values_outside_the_physical_range_name_file_line_and_column() {
    let e = first_error(&format!("{HEAD}0,1,2,3,20,\n1,1,2,3,1e308,\n"));
    assert_eq!((e.line, e.column.clone()), (5, Some((5, "temp_C".to_string()))));
    assert_eq!(
        e.to_string(),
        "bad.csv:5: column 5 `temp_C`: `1e308` is outside the physical range -100 … 200 °C (a logger fault or a bad edit)"
    );
    let e = first_error(&format!("{HEAD}0,1,-100.01,3,20,\n"));
    assert_eq!(e.column.unwrap().1, "uy_V");
    let e = first_error("t_s,ux_V,uy_V,uz_V,temp_C,fz_g,chamber_C\n0,1,2,3,20,1,-101\n");
    assert_eq!(e.column.unwrap().1, "chamber_C");
    let e = first_error("t_s,ux_V,uy_V,uz_V,temp_C,fz_g\n0,1,2,3,20,-1000.5\n");
    assert_eq!(e.column.unwrap().1, "fz_g");
    // The limits themselves are values.
    let r =
        Reader::new(Cursor::new(format!("{HEAD}0,100,-100,0,200,\n1,0,0,0,-100,\n").into_bytes()), "ok.csv").unwrap();
    assert_eq!(r.count(), 2);
}

#[test]
fn a_cut_off_last_line_is_an_error_a_byte_order_mark_is_skipped() {
    // No line break at the end and fewer cells than the header: cut off.
    let e = first_error(&format!("{HEAD}0,1,2,3,20,TP1\n1,1,2,3"));
    assert_eq!((e.kind.clone(), e.line), (ErrorKind::CutOff { expected: 6, got: 4 }, 5));
    assert!(e.to_string().starts_with("bad.csv:5: last line cut off: 4 cells, the header has 6"), "{e}");
    // Also when only optional cells are missing (a complete short row has its line break).
    let e = first_error(&format!("{HEAD}0,1,2,3,20"));
    assert_eq!(e.kind, ErrorKind::CutOff { expected: 6, got: 5 });
    // A complete last row without a line break is a row.
    let r = Reader::new(Cursor::new(format!("{HEAD}0,1,2,3,20,TP1").into_bytes()), "ok.csv").unwrap();
    assert_eq!(r.count(), 1);
    // The byte order mark of a spreadsheet export, before a comment or before the header.
    for text in [format!("\u{feff}{HEAD}0,1,2,3,20,TP1\n"), "\u{feff}t_s,ux_V,uy_V,uz_V,temp_C\n0,1,2,3,20\n".into()] {
        let mut r = Reader::new(Cursor::new(text.into_bytes()), "bom.csv").unwrap();
        assert_eq!(r.header()[0], "t_s");
        let mut row = Row::default();
        assert!(r.read_row(&mut row).unwrap());
        assert_eq!(row.temp_c, 20.0);
    }
}

#[test]
fn require_rows_refuses_a_header_only_recording() {
    let mut r = Reader::new(Cursor::new(HEAD.as_bytes().to_vec()), "head.csv").unwrap();
    assert!(r.next().is_none());
    let e = r.require_rows().err().unwrap();
    assert_eq!(e.to_string(), "head.csv: no data row after the header");
    let mut r = Reader::new(Cursor::new(format!("{HEAD}0,1,2,3,20,\n").into_bytes()), "one.csv").unwrap();
    assert_eq!(r.by_ref().count(), 1);
    assert_eq!(r.rows_read(), 1);
    r.require_rows().unwrap();
}

#[test]
fn vibration_cells_map_to_the_core_type() {
    use bins_comp::vibration::Vibration;
    let mut row = Row::default();
    for v in [
        Vibration::None,
        Vibration::Harmonic { amp_g: [0.42, 1.5, -1.5], freq_hz: 16.0 },
        Vibration::Random { sigma_g: [0.5, 0.5, 0.25], band_hz: (20.0, 40.0) },
    ] {
        row.set_vibration(&v);
        assert_eq!(row.vibration(), Some(v));
    }
    row.vib_hz = None;
    assert_eq!(row.vibration(), None);
}
