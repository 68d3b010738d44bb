//! Property: whatever rows the writer accepts, the reader gives back exactly (numbers to the
//! bit, text cells with commas, quotes, spaces and any Unicode, empty optional cells, any
//! choice of optional and extra columns, comments).

use bins_cal::recording::{Columns, Reader, Row, VibKind, Writer};
use proptest::prelude::*;
use std::io::Cursor;

/// Text a cell or comment may hold: anything but a line break.
fn text() -> impl Strategy<Value = String> {
    prop_oneof![
        "[^\r\n]{0,12}",
        Just(String::new()),
        Just(" leading and trailing ".to_string()),
        Just("a, \"quoted\" b".to_string()),
        Just("\"".to_string()),
        Just("\t#,".to_string()),
    ]
}

fn opt(range: std::ops::RangeInclusive<f64>) -> impl Strategy<Value = Option<f64>> {
    prop::option::of(prop_oneof![range, Just(0.0), Just(-0.0)])
}

/// A finite number spread over many decades within `±max`.
fn decades(max: f64) -> impl Strategy<Value = f64> {
    (-1.0f64..=1.0, -12i32..=0).prop_map(move |(m, e)| m * max * 10f64.powi(e))
}

fn row(extra: usize) -> impl Strategy<Value = Row> {
    (
        [decades(100.0), decades(100.0), decades(100.0)],
        -100.0f64..=200.0,
        [opt(-1000.0..=1000.0), opt(-1000.0..=1000.0), opt(-1000.0..=1000.0)],
        prop::option::of(prop_oneof![Just(VibKind::None), Just(VibKind::Sine), Just(VibKind::Random)]),
        [opt(-1000.0..=1000.0), opt(-1000.0..=1000.0), opt(-1000.0..=1000.0)],
        (opt(0.0..=1e4), opt(0.0..=1e4), opt(-100.0..=200.0), opt(0.0..=1e7)),
        prop::option::of(text().prop_filter("a non-empty label", |s| !s.trim().is_empty())),
        prop::collection::vec(text(), extra),
    )
        .prop_map(|(u_v, temp_c, f_g, vib_kind, vib_g, (vib_hz, vib_bw_hz, chamber_c, power_s), pos, extra)| Row {
            line: 0,
            t_s: 0.0,
            u_v,
            temp_c,
            f_g,
            vib_kind,
            vib_g,
            vib_hz,
            vib_bw_hz,
            chamber_c,
            pos,
            power_s,
            extra,
        })
}

fn recording() -> impl Strategy<Value = (Columns, Vec<String>, Vec<Row>)> {
    (
        any::<[bool; 4]>(),
        prop::collection::btree_set("x_[a-z0-9 ]{0,6}[a-z]", 0..4),
        prop::collection::vec(text(), 0..3),
    )
        .prop_flat_map(|(on, extra, comments)| {
            let columns = Columns {
                reference: on[0],
                chamber: on[1],
                pos: on[2],
                power: on[3],
                extra: extra.into_iter().collect(),
            };
            let n = columns.extra.len();
            let rows = prop::collection::vec((row(n), 1e-3f64..1e3), 0..20);
            (Just(columns), Just(comments), rows, -1e6f64..1e6)
        })
        .prop_map(|(columns, comments, rows, t0)| {
            let mut t = t0;
            let rows = rows
                .into_iter()
                .map(|(mut r, dt)| {
                    t += dt;
                    r.t_s = t;
                    r
                })
                .collect();
            (columns, comments, rows)
        })
}

/// What the reader must give for `r` written with `columns`: the cells of absent columns are
/// not known, and the line is the row's.
fn expected(columns: &Columns, r: &Row, line: u64) -> Row {
    let mut e = r.clone();
    e.line = line;
    if !columns.reference {
        e.clear_reference();
    }
    if !columns.chamber {
        e.chamber_c = None;
    }
    if !columns.pos {
        e.pos = None;
    }
    if !columns.power {
        e.power_s = None;
    }
    e
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn write_then_read_gives_every_row_back((columns, comments, rows) in recording()) {
        let refs: Vec<&str> = comments.iter().map(String::as_str).collect();
        let mut w = Writer::new(Vec::new(), "prop.csv", columns.clone(), &refs).unwrap();
        for r in &rows {
            w.write_row(r).unwrap();
        }
        let bytes = w.finish().unwrap();
        let mut reader = Reader::new(Cursor::new(&bytes), "prop.csv").unwrap();
        prop_assert_eq!(reader.comments(), &comments[..]);
        prop_assert_eq!(reader.extra_columns(), &columns.extra[..]);
        prop_assert_eq!(Columns::of_reader(&reader), columns.clone());
        let back: Vec<Row> = reader.by_ref().collect::<Result<_, _>>().unwrap();
        prop_assert_eq!(back.len(), rows.len());
        let first = comments.len() as u64 + 2;
        for (k, (b, r)) in back.iter().zip(&rows).enumerate() {
            prop_assert_eq!(b, &expected(&columns, r, first + k as u64));
            // Bit for bit, which `==` on floats does not say for ±0.
            prop_assert_eq!(b.u_v.map(f64::to_bits), r.u_v.map(f64::to_bits));
        }
    }
}
